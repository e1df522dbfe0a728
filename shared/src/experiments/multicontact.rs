//! Multiple-point contact (thesis §5.4, figs. 5.9–5.10): a box rotated into a corner about its
//! estimated instantaneous centre of rotation.

use super::*;
use crate::error::ExperimentError;
use crate::math::{Vec2, cross};
use crate::multicontact::{
    BoxParams, BoxPlant, Pose, estimate_rotation_centre, friction_filter, rotate_about,
};
use crate::sensor::{SensorModel, SensorParams, Wrench};
use crate::world::BoxWorld;
use serde::Serialize;

/// One estimate of the rotation centre.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct CentreEstimate {
    /// Time (s).
    pub t_s: f64,
    /// Box tilt when estimated (deg).
    pub tilt_deg: f64,
    /// True centre (m).
    pub truth_m: [f64; 2],
    /// Signed three-dither estimate (m).
    pub estimate_m: [f64; 2],
    /// Its error as a fraction of the box size.
    pub error_fraction: f64,
    /// The thesis's unsigned form with the third dither choosing the root (m).
    pub thesis_m: Option<[f64; 2]>,
    /// Its error as a fraction of the box size.
    pub thesis_error_fraction: Option<f64>,
    /// Friction filter (eqs. 5.11–5.18) on the mean wrench of the first dither, with the
    /// estimated centre: the friction resultant it attributes (N).
    pub friction_estimated_n: Option<[f64; 2]>,
    /// The true mean friction resultant over the same window (N).
    pub friction_true_n: [f64; 2],
    /// The fitted response matrix A = ∂g/∂c (rows: force x, y; N per m of centre shift per
    /// rad). The thesis's diagonal stiffness (eqs. 5.19–5.20) makes it `[[0, −k_x], [k_y, 0]]`.
    pub response_matrix: [[f64; 2]; 2],
    /// |diagonal| / |off-diagonal| of A: 0 under the thesis's assumption.
    pub coupling: f64,
}

/// Summary of `fig5.9`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig59Summary {
    /// Box size (m).
    pub size_m: [f64; 2],
    /// Initial tilt (deg).
    pub initial_tilt_deg: f64,
    /// Final tilt (deg).
    pub final_tilt_deg: f64,
    /// Dither amplitude (deg) and frequency (Hz).
    pub dither_deg: f64,
    /// Frequency (Hz).
    pub dither_hz: f64,
    /// Sensor noise (N).
    pub noise_n: f64,
    /// Largest error of the signed estimate, as a fraction of the box size.
    pub max_error_fraction: f64,
    /// Largest error of the thesis's form.
    pub thesis_max_error_fraction: f64,
    /// Per estimate.
    pub estimates: Vec<CentreEstimate>,
}

/// (time s, dither phase rad, force N, moment about the box centre N·m, box centre m).
type WrenchSample = (f64, f64, Vec2, f64, Vec2);

struct Rig {
    plant: BoxWorld,
    sensor: SensorModel,
    target: Pose,
    t: f64,
    dt: f64,
    sensor_period: f64,
    next_sample: f64,
    reading: Wrench,
    trace: Vec<[f64; 5]>,
}

impl Rig {
    fn step(&mut self, target: Pose, target_vel: [f64; 3]) {
        self.plant.step(target, target_vel);
        self.t += self.dt;
        while self.next_sample <= self.t {
            let tr = self.plant.truth();
            self.reading = self
                .sensor
                .sample(Wrench {
                    force: tr.force,
                    torque: tr.moment,
                })
                .wrench;
            self.next_sample += self.sensor_period;
        }
        if ((self.t / self.dt).round() as u64).is_multiple_of(200)
            && let Some(p) = self.plant.truth().rotation_centre
        {
            self.trace
                .push([self.t, p.x, p.y, self.plant.pose()[2], 0.0]);
        }
    }
}

/// Keeps both contacts loaded for 0.5 s: a slow force loop on the commanded position (grip in
/// series with the contact ≈ 3.3 kN/m, crossover ≈ 2 Hz), with the suppression dither on so
/// static friction does not hold part of the preload.
fn settle(rig: &mut Rig, p_hat: Vec2, tare: Vec2, target: Vec2, supp_amp: f64, supp_hz: f64) {
    for _ in 0..5000 {
        let f = rig.reading.force - tare;
        let gain = std::f64::consts::TAU * 2.0 / 3300.0 * rig.dt;
        rig.target[0] -= gain * (target.x - f.x);
        rig.target[1] -= gain * (target.y - f.y);
        let supp = supp_amp * (std::f64::consts::TAU * supp_hz * rig.t).sin();
        let t = rotate_about(rig.target, p_hat, supp);
        rig.step(t, [0.0; 3]);
    }
}

/// Rotates the box, held by a compliant grip and pushed into a corner (floor and wall), from a
/// 20° tilt into the corner in 2° steps about its estimated instantaneous centre of rotation;
/// before each step the centre is re-estimated from three rotational dithers (0.5°, 2 Hz)
/// about P̂ and P̂ + 10 mm at ±45° (the thesis's unsigned form needs dither centres displaced
/// in both x and y: a centre moved along x alone says nothing about P_y). Sensor noise
/// σ = 0.02 N.
pub fn fig5_9(opts: &Options) -> Result<Outcome<Fig59Summary>, ExperimentError> {
    let params = BoxParams::default();
    let size = params.size_m[0].max(params.size_m[1]);
    let tilt0 = 20f64.to_radians();
    let touch = BoxPlant::touching_pose(&params, tilt0);
    let sensor_params = SensorParams {
        noise_force_n: 0.02,
        ..opts.base.sensor
    };
    let dt = 1e-4;
    let mut rig = Rig {
        plant: BoxWorld::new(&opts.base, params, touch, dt)?,
        sensor: SensorModel::new(sensor_params, opts.seed),
        target: [touch[0] - 0.0006, touch[1] - 0.0006, tilt0],
        t: 0.0,
        dt,
        sensor_period: 1.0 / sensor_params.rate_hz,
        next_sample: 0.0,
        reading: Wrench::default(),
        trace: Vec::new(),
    };
    let tare = crate::sim::tare(&mut rig.sensor);
    let dither = Dithers::default();
    let (amp, freq, supp_amp, supp_hz) = (dither.amp, dither.freq, dither.supp_amp, dither.supp_hz);
    let force_target = Vec2::new(2.0, 2.0);
    let m = 0.01;
    // Initial guess: the box centre (the thesis starts from the box's size and the forces).
    let mut p_hat = Vec2::new(rig.target[0], rig.target[1]);
    settle(&mut rig, p_hat, tare.force, force_target, supp_amp, supp_hz);
    let mut estimates = Vec::new();
    let mut steps = 0;
    while rig.target[2] > 0.2f64.to_radians() && steps < 30 {
        steps += 1;
        let base = rig.target;
        let diag = m * std::f64::consts::FRAC_1_SQRT_2;
        let centres = [
            p_hat,
            p_hat + Vec2::new(diag, diag),
            p_hat + Vec2::new(diag, -diag),
        ];
        let mut records: Vec<Vec<WrenchSample>> = Vec::new();
        let mut mean = MeanWrench::default();
        let truth_before = rig.plant.truth().rotation_centre;
        for (k, c) in centres.iter().enumerate() {
            let first = (k == 0).then_some(&mut mean);
            records.push(dither_about(
                &mut rig,
                &dither,
                base,
                *c,
                p_hat,
                tare.force,
                tare.torque,
                first,
            ));
        }
        // In-phase response per radian of each dither (the suppression dither removed by a
        // one-period comb), then P from the signed responses and the thesis's unsigned form.
        let flat: Vec<(usize, f64, f64, Vec2)> = records
            .iter()
            .enumerate()
            .flat_map(|(k, rec)| rec.iter().map(move |&(t, ph, f, _, _)| (k, t, ph, f)))
            .collect();
        let Some(fit) = estimate_rotation_centre(&centres, &flat, amp, supp_hz) else {
            return Err(ExperimentError::no_result(
                "fig5.9",
                "the rotation-centre estimate is singular",
            ));
        };
        let (est, a_fit, thesis) = (fit.centre, fit.response_matrix, fit.thesis_centre);
        // Friction filter on the mean wrench of the first dither: moments about R = the corner.
        let n_mean = mean.n.max(1.0);
        let f_mean = mean.force / n_mean;
        let o = Vec2::new(base[0], base[1]);
        let m_r = mean.torque / n_mean + cross(o, f_mean);
        let split = friction_filter(f_mean, m_r, est);
        let truth = truth_before.unwrap_or(Vec2::new(f64::NAN, f64::NAN));
        estimates.push(CentreEstimate {
            t_s: rig.t,
            tilt_deg: base[2].to_degrees(),
            truth_m: [truth.x, truth.y],
            estimate_m: [est.x, est.y],
            error_fraction: (est - truth).norm() / size,
            thesis_m: thesis.map(|p| [p.x, p.y]),
            thesis_error_fraction: thesis.map(|p| (p - truth).norm() / size),
            friction_estimated_n: split.map(|(_, t)| [t.x, t.y]),
            friction_true_n: {
                let ft = mean.friction / n_mean;
                [ft.x, ft.y]
            },
            response_matrix: [
                [a_fit[(0, 0)], a_fit[(0, 1)]],
                [a_fit[(1, 0)], a_fit[(1, 1)]],
            ],
            coupling: (a_fit[(0, 0)].hypot(a_fit[(1, 1)])) / (a_fit[(0, 1)].hypot(a_fit[(1, 0)])),
        });
        p_hat = est;
        rotate_towards_corner(&mut rig, base, p_hat);
        settle(&mut rig, p_hat, tare.force, force_target, supp_amp, supp_hz);
    }
    let max_err = estimates
        .iter()
        .map(|e| e.error_fraction)
        .fold(0.0, f64::max);
    let thesis_max = estimates
        .iter()
        .filter_map(|e| e.thesis_error_fraction)
        .fold(0.0, f64::max);
    let final_tilt = rig.plant.pose()[2].to_degrees();
    let checks = vec![
        Check::at_most(
            "rotation_centre_error_over_box_max",
            "largest rotation-centre error / box size",
            max_err,
            0.01,
        ),
        Check::at_most("final_tilt_deg", "final tilt (deg)", final_tilt.abs(), 1.0),
    ];
    let figure = fig5_9_figure(&rig.trace, &estimates);
    Ok(Outcome {
        simulated_s: rig.t,
        summary: Fig59Summary {
            size_m: params.size_m,
            initial_tilt_deg: tilt0.to_degrees(),
            final_tilt_deg: final_tilt,
            dither_deg: amp.to_degrees(),
            dither_hz: freq,
            noise_n: sensor_params.noise_force_n,
            max_error_fraction: max_err,
            thesis_max_error_fraction: thesis_max,
            estimates,
        },
        checks,
        figure,
    })
}

/// The rotational dithers of `fig5.9`: the estimation dithers about each centre, and the
/// friction-suppression dither about P̂ superposed on them (thesis §6.3: a 20 Hz rotational
/// dither keeps the contacts sliding).
struct Dithers {
    /// Estimation dither amplitude (rad), frequency (Hz), periods, ramp in and out (s).
    amp: f64,
    freq: f64,
    periods: usize,
    ramp: f64,
    /// Suppression dither amplitude (rad) and frequency (Hz).
    supp_amp: f64,
    supp_hz: f64,
}

impl Default for Dithers {
    fn default() -> Self {
        Self {
            amp: 0.5f64.to_radians(),
            freq: 2.0,
            periods: 4,
            ramp: 0.25,
            supp_amp: 0.5f64.to_radians(),
            supp_hz: 20.0,
        }
    }
}

/// Sums over a dither's recorded samples: force and moment measured, friction true, count.
#[derive(Default)]
struct MeanWrench {
    force: Vec2,
    torque: f64,
    friction: Vec2,
    n: f64,
}

/// One rotational dither about `c` (with the suppression dither about `p_hat` superposed),
/// from the pose `base`; its record (every 10th tick of the full periods); the mean wrench
/// summed into `mean` if given.
#[allow(clippy::too_many_arguments)]
fn dither_about(
    rig: &mut Rig,
    d: &Dithers,
    base: Pose,
    c: Vec2,
    p_hat: Vec2,
    tare_force: Vec2,
    tare_torque: f64,
    mut mean: Option<&mut MeanWrench>,
) -> Vec<WrenchSample> {
    let omega = std::f64::consts::TAU * d.freq;
    let total = 2.0 * d.ramp + d.periods as f64 / d.freq;
    let n = (total / rig.dt).round() as usize;
    let mut wrenches: Vec<WrenchSample> = Vec::new();
    for i in 0..n {
        let tau = i as f64 * rig.dt;
        let e = if tau < d.ramp {
            0.5 * (1.0 - (std::f64::consts::PI * tau / d.ramp).cos())
        } else if tau > total - d.ramp {
            0.5 * (1.0 - (std::f64::consts::PI * (total - tau) / d.ramp).cos())
        } else {
            1.0
        };
        let phase = omega * (tau - d.ramp);
        let angle = d.amp * e * phase.sin();
        let supp = d.supp_amp * (std::f64::consts::TAU * d.supp_hz * rig.t).sin();
        let target = rotate_about(rotate_about(base, c, angle), p_hat, supp);
        let ang_vel = d.amp * e * omega * phase.cos();
        let r = Vec2::new(target[0], target[1]) - c;
        rig.step(target, [-ang_vel * r.y, ang_vel * r.x, ang_vel]);
        if tau >= d.ramp && tau < d.ramp + d.periods as f64 / d.freq && i % 10 == 0 {
            let f = rig.reading.force - tare_force;
            let o = Vec2::new(target[0], target[1]);
            wrenches.push((rig.t, phase, f, rig.reading.torque - tare_torque, o));
            if let Some(m) = mean.as_deref_mut() {
                m.friction += rig.plant.truth().friction_resultant;
                m.force += f;
                m.torque += rig.reading.torque - tare_torque;
                m.n += 1.0;
            }
        }
    }
    wrenches
}

/// Rotates the box towards the corner by 2° (or what is left) about `p_hat`, smoothly over
/// 0.5 s, and makes that pose the target.
fn rotate_towards_corner(rig: &mut Rig, base: Pose, p_hat: Vec2) {
    let step = -(2f64.to_radians()).min(base[2]);
    let n = (0.5 / rig.dt) as usize;
    for i in 0..n {
        let s = (i + 1) as f64 / n as f64;
        let e = 0.5 * (1.0 - (std::f64::consts::PI * s).cos());
        let target = rotate_about(base, p_hat, step * e);
        rig.step(target, [0.0; 3]);
    }
    rig.target = rotate_about(base, p_hat, step);
}

/// `fig5.9`'s plot: the rotation centre's coordinates (true, estimated, the thesis's form),
/// the error, the tilt.
fn fig5_9_figure(trace: &[[f64; 5]], estimates: &[CentreEstimate]) -> Figure {
    Figure {
        title: "fig5.9/5.10: rotating a box into a corner about its estimated rotation centre"
            .into(),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "rotation centre x (mm)".into(),
                series: vec![
                    series("true", trace.iter().map(|r| [r[0], r[1] * 1e3]).collect()),
                    markers(
                        "estimated (3 signed dithers)",
                        estimates
                            .iter()
                            .map(|e| [e.t_s, e.estimate_m[0] * 1e3])
                            .collect(),
                    ),
                    markers(
                        "thesis form (RMS)",
                        estimates
                            .iter()
                            .filter_map(|e| e.thesis_m.map(|p| [e.t_s, p[0] * 1e3]))
                            .collect(),
                    ),
                ],
            },
            Panel {
                x_label: None,
                y_label: "rotation centre y (mm)".into(),
                series: vec![
                    series("true", trace.iter().map(|r| [r[0], r[2] * 1e3]).collect()),
                    markers(
                        "estimated (3 signed dithers)",
                        estimates
                            .iter()
                            .map(|e| [e.t_s, e.estimate_m[1] * 1e3])
                            .collect(),
                    ),
                    markers(
                        "thesis form (RMS)",
                        estimates
                            .iter()
                            .filter_map(|e| e.thesis_m.map(|p| [e.t_s, p[1] * 1e3]))
                            .collect(),
                    ),
                ],
            },
            Panel {
                x_label: None,
                y_label: "error / box size (%)".into(),
                series: vec![markers(
                    "estimated",
                    estimates
                        .iter()
                        .map(|e| [e.t_s, 100.0 * e.error_fraction])
                        .collect(),
                )],
            },
            Panel {
                x_label: None,
                y_label: "box tilt (deg)".into(),
                series: vec![series(
                    "tilt",
                    trace.iter().map(|r| [r[0], r[3].to_degrees()]).collect(),
                )],
            },
        ],
    }
}
