//! Chapter 5 experiments on the corner profile: `corners` (tracking through its corners) and
//! `fig5.3` (the preliminary correlation method on it).

use super::*;
use crate::config::SimConfig;
use crate::error::ExperimentError;
use crate::setups::on_corner_profile;
use crate::sim::Lockstep;
use crate::tuner::TunerConfig;
use serde::Serialize;

/// How one corner was handled.
#[derive(Debug, Clone, Serialize)]
pub struct CornerReport {
    /// Corner position (m, u).
    pub u_m: f64,
    /// Tangent turn at the corner (deg, + = valley/concave).
    pub turn_deg: f64,
    /// "valley" or "peak".
    pub kind: &'static str,
    /// Distance past the corner at which the first estimation started (m), if any.
    pub detected_after_m: Option<f64>,
    /// What started it.
    pub trigger: Option<String>,
    /// Distance past the corner after which |tangent error| stays below 0.5° (m), if it does
    /// before the next corner.
    pub tracked_after_m: Option<f64>,
    /// Worst |tangent error| between this corner and the next (deg).
    pub worst_angle_deg: f64,
    /// Worst |F_N − preload| / preload of the dither-period mean, same stretch.
    pub worst_force_deviation: f64,
    /// Smallest and largest instantaneous normal force, same stretch (N).
    pub force_range_n: [f64; 2],
}

/// Summary of `corners`.
#[derive(Debug, Clone, Serialize)]
pub struct CornersSummary {
    /// Profile vertices (u, h) in m.
    pub vertices: Vec<[f64; 2]>,
    /// Per corner.
    pub corners: Vec<CornerReport>,
    /// Corners detected and tracked through.
    pub tracked: usize,
    /// Worst tangent transient over all corners (deg).
    pub worst_angle_deg: f64,
    /// Worst period-mean force deviation over all corners.
    pub worst_force_deviation: f64,
    /// The run.
    pub run: TrackingRun,
}

/// Tracks the piecewise-linear profile through its four corners at 5 mm/s with the
/// friction-suppression dither at 5 ẋ_o; reports per corner how it was detected (force limit or
/// set-point drift), how far past it the tangent was re-acquired, and the worst transient.
pub fn corners(opts: &Options) -> Result<Outcome<CornersSummary>, ExperimentError> {
    let v = 0.005;
    let mut cfg = config(opts, TunerConfig::Fixed);
    let (vertices, end) = on_corner_profile(&mut cfg);
    let run = run_tracking(&cfg, v, end, 5.0 * v, 0.0, 600.0)?;
    let preload = cfg.servo.hybrid.preload_n;
    let mut reports = Vec::new();
    for j in 1..vertices.len() - 1 {
        let (a, c, b) = (vertices[j - 1], vertices[j], vertices[j + 1]);
        let s_in = ((c[1] - a[1]) / (c[0] - a[0])).atan();
        let s_out = ((b[1] - c[1]) / (b[0] - c[0])).atan();
        let turn = (s_out - s_in).to_degrees();
        let next = vertices[j + 1][0];
        // From just before this corner to 2 mm before the next (where the contact starts to
        // feel the next face).
        let stretch: Vec<&TrackSample> = run
            .samples
            .iter()
            .filter(|s| s.u_m >= c[0] - 0.001 && s.u_m < next - 0.002)
            .collect();
        let t_corner = stretch.first().map_or(f64::INFINITY, |s| s.t);
        let first = run.estimates.iter().find(|e| e.time_s >= t_corner);
        let start_u = first.and_then(|e| {
            run.samples
                .iter()
                .min_by(|x, y| (x.t - e.time_s).abs().total_cmp(&(y.t - e.time_s).abs()))
                .map(|s| s.u_m)
        });
        let err = |s: &TrackSample| {
            crate::math::wrap_angle(s.estimated_angle_rad - s.true_angle_rad)
                .to_degrees()
                .abs()
        };
        let tracked = stretch
            .iter()
            .rposition(|s| s.moving && err(s) >= 0.5)
            .map(|i| stretch.get(i + 1).map(|s| s.u_m - c[0]))
            .unwrap_or(Some(0.0));
        // The period mean of the recorded normal force (samples every 10 ms: 10 per dither period).
        let fm: Vec<f64> = stretch
            .windows(10)
            .map(|w| w.iter().map(|s| s.normal_n).sum::<f64>() / 10.0)
            .collect();
        reports.push(CornerReport {
            u_m: c[0],
            turn_deg: turn,
            kind: if turn > 0.0 { "valley" } else { "peak" },
            detected_after_m: start_u.map(|u| u - c[0]),
            trigger: first.map(|_| "estimation".to_string()),
            tracked_after_m: tracked,
            worst_angle_deg: stretch
                .iter()
                .filter(|s| s.moving)
                .map(|s| err(s))
                .fold(0.0, f64::max),
            worst_force_deviation: fm
                .iter()
                .map(|f| (f - preload).abs() / preload)
                .fold(0.0, f64::max),
            force_range_n: stretch
                .iter()
                .fold([f64::INFINITY, f64::NEG_INFINITY], |r, s| {
                    [r[0].min(s.normal_n), r[1].max(s.normal_n)]
                }),
        });
    }
    let tracked = reports
        .iter()
        .filter(|r| r.detected_after_m.is_some() && r.tracked_after_m.is_some())
        .count();
    let worst_angle = reports
        .iter()
        .map(|r| r.worst_angle_deg)
        .fold(0.0, f64::max);
    let worst_force = reports
        .iter()
        .map(|r| r.worst_force_deviation)
        .fold(0.0, f64::max);
    let checks = vec![
        Check::at_least(
            "corners_tracked",
            "corners detected and tracked through",
            tracked as f64,
            reports.len() as f64,
        ),
        Check::at_most(
            "ticks_without_contact",
            "servo ticks without contact",
            run.ticks_without_contact as f64,
            0.0,
        ),
        Check::at_least(
            "distance_tracked_m",
            "distance tracked (m)",
            run.travelled_m,
            0.99 * (end - cfg.start_u_m),
        ),
    ];
    let figure = tracking_figure(
        format!(
            "corners: tracking a piecewise-linear surface, {} estimations",
            run.estimations.estimates
        ),
        &[("dither method", &run)],
    );
    Ok(Outcome {
        simulated_s: run.duration_s,
        summary: CornersSummary {
            vertices,
            corners: reports,
            tracked,
            worst_angle_deg: worst_angle,
            worst_force_deviation: worst_force,
            run,
        },
        checks,
        figure,
    })
}

/// Runs the preliminary correlation method (§5.2) along the surface of `cfg` from its start to
/// `u_end`: force loop off, the normal set-point follows the polynomial model minus the preload
/// penetration, with the model's dither; tangent error = model slope against the truth.
pub(crate) fn run_correlation(
    cfg: &SimConfig,
    params: crate::correlation::CorrelationParams,
    initial: &[f64],
    velocity: f64,
    u_end: f64,
    a_omega: f64,
) -> Result<(TrackingRun, Vec<f64>), ExperimentError> {
    let preload = cfg.servo.hybrid.preload_n;
    let mut sim = Lockstep::new(cfg)?;
    let dt = sim.dt();
    let mut tracker = crate::correlation::CorrelationTracker::new(params, initial, dt);
    let depth0 = preload / cfg.plant.contact.stiffness();
    let origin_y = sim.truth().tip.y;
    let frame_origin = cfg.surface.frame.origin_m;
    sim.servo_mut().set_force_control(false);
    sim.servo_mut().set_a_omega(a_omega);
    sim.servo_mut().hybrid_mut().set_velocity(velocity);
    let u0 = sim.truth().surface_u_m;
    let mut samples = Vec::new();
    let (mut sq, mut n, mut max_err) = (0.0f64, 0.0f64, 0.0f64);
    let (mut worst, mut fmin, mut fmax, mut imin, mut imax, mut lost) = (
        0.0f64,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        0usize,
    );
    let mut worst_at = [0.0, 0.0];
    let (mut dev_sq, mut dev_n) = (0.0f64, 0.0f64);
    let mut period = crate::window::SlidingWindow::new(
        (1.0 / (cfg.servo.dither.frequency_hz * dt))
            .round()
            .max(1.0) as usize,
    );
    let mut dither = 0.0;
    for k in 0..(300.0 / dt) as usize {
        // Position along the profile from the encoders.
        let x = sim.world().arm().forward(sim.world().joints().0).x - frame_origin[0];
        let (h, slope) = tracker.model(x);
        // Desired tool height h − δ0 + dither, as depth below the frame origin.
        let depth = origin_y - (frame_origin[1] + h - depth0 + dither);
        sim.servo_mut().hybrid_mut().set_normal_setpoint(depth);
        sim.step();
        let f = sim.servo().diag().normal_force_n;
        dither = tracker.step(x, f, preload, dt);
        let tr = *sim.truth();
        if tr.contact_count == 0 || tr.normal_force_n <= 0.0 {
            lost += 1;
        }
        let est = slope.atan();
        let err = crate::math::wrap_angle(est - tr.tangent_angle_rad).to_degrees();
        sq += err * err;
        n += 1.0;
        max_err = max_err.max(err.abs());
        period.push(tr.normal_force_n);
        if sim.time() >= 0.5 {
            let mean = period.mean();
            let dev = (mean - preload).abs() / preload;
            dev_sq += dev * dev;
            dev_n += 1.0;
            if dev > worst {
                worst = dev;
                worst_at = [sim.time(), tr.surface_u_m];
            }
            fmin = fmin.min(mean);
            fmax = fmax.max(mean);
            imin = imin.min(tr.normal_force_n);
            imax = imax.max(tr.normal_force_n);
        }
        if k % 100 == 0 {
            samples.push(TrackSample {
                t: sim.time(),
                u_m: tr.surface_u_m,
                true_angle_rad: tr.tangent_angle_rad,
                estimated_angle_rad: est,
                normal_n: tr.normal_force_n,
                moving: true,
            });
        }
        if tr.surface_u_m >= u_end {
            break;
        }
    }
    let run = TrackingRun {
        tangent_error_rms_deg: (sq / n.max(1.0)).sqrt(),
        tangent_error_max_deg: max_err,
        worst_normal_deviation: worst,
        normal_range_n: [fmin, fmax],
        worst_normal_at: worst_at,
        normal_deviation_rms: (dev_sq / dev_n.max(1.0)).sqrt(),
        instantaneous_normal_range_n: [imin, imax],
        ticks_without_contact: lost,
        estimations: Default::default(),
        travelled_m: sim.truth().surface_u_m - u0,
        duration_s: sim.time(),
        estimates: Vec::new(),
        samples,
    };
    Ok((run, tracker.weights().to_vec()))
}

/// Summary of `fig5.3`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig53Summary {
    /// The profile (as `corners`).
    pub vertices: Vec<[f64; 2]>,
    /// Initial polynomial weights of the preliminary method (m): the least-squares quadratic of
    /// the true profile, 10 % off.
    pub initial_weights_m: Vec<f64>,
    /// Final weights (m).
    pub final_weights_m: Vec<f64>,
    /// The preliminary correlation method (§5.2).
    pub preliminary: TrackingRun,
    /// The dither method on the same profile.
    pub dither: TrackingRun,
}

/// The preliminary correlation method (eqs. 5.1–5.4) against the dither method on the corner
/// profile of `corners` (fig. 5.3: the thesis's preliminary method failed on discrete changes
/// of the tangent, even from an initial estimate within 10 %).
pub fn fig5_3(opts: &Options) -> Result<Outcome<Fig53Summary>, ExperimentError> {
    let v = 0.005;
    let mut cfg = config(opts, TunerConfig::Fixed);
    let (vertices, end) = on_corner_profile(&mut cfg);
    let params = crate::correlation::CorrelationParams::default();
    // Least-squares quadratic of the true profile in x̃ = x/L, then 10 % off.
    let fit = {
        use nalgebra::{Matrix3, Vector3};
        let (mut a, mut b) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
        for k in 0..=1000 {
            let x = vertices[0][0] + (end + 0.002 - vertices[0][0]) * k as f64 / 1000.0;
            let (h, _) = cfg.surface.height_slope(x);
            let xt = x / params.length_scale_m;
            let r = Vector3::new(1.0, xt, xt * xt);
            a += r * r.transpose();
            b += r * h;
        }
        a.cholesky()
            .map(|c| c.solve(&b))
            .unwrap_or_else(Vector3::zeros)
    };
    let initial: Vec<f64> = fit.iter().map(|w| 1.1 * w).collect();
    let (preliminary, final_weights) = run_correlation(&cfg, params, &initial, v, end, 5.0 * v)?;
    let dither = run_tracking(&cfg, v, end, 5.0 * v, 0.0, 600.0)?;
    let checks = vec![
        Check::at_most(
            "dither_over_preliminary_tangent_error",
            "dither method: tangent error RMS / preliminary's",
            dither.tangent_error_rms_deg / preliminary.tangent_error_rms_deg,
            1.0,
        ),
        Check::at_most(
            "dither_over_preliminary_force_deviation",
            "dither method: RMS period-mean force deviation / preliminary's",
            dither.normal_deviation_rms / preliminary.normal_deviation_rms.max(1e-9),
            1.0,
        ),
    ];
    let figure = tracking_figure("fig5.3: the preliminary correlation method (§5.2) vs the dither method on a profile with corners".into(), &[("preliminary", &preliminary), ("dither method", &dither)]);
    Ok(Outcome {
        simulated_s: preliminary.duration_s + dither.duration_s,
        summary: Fig53Summary {
            vertices,
            initial_weights_m: initial,
            final_weights_m: final_weights,
            preliminary,
            dither,
        },
        checks,
        figure,
    })
}
