//! Chapter 5 experiments: tangent estimation by dither, surface tracking, corners.

use super::*;
use crate::config::SimConfig;
use crate::error::ExperimentError;
use crate::friction::FrictionLaw;
use crate::sim::{EstimateLog, Lockstep};
use crate::tangent::TangentOutcome;
use crate::tuner::TunerConfig;
use serde::Serialize;

/// Friction-free law (all coefficients zero).
pub(crate) fn frictionless() -> FrictionLaw {
    FrictionLaw {
        kinetic_n: 0.0,
        viscous_n_s_per_m: 0.0,
        stribeck_n: 0.0,
        stribeck_velocity_m_per_s: 0.01,
    }
}

/// One estimation on a flat surface with a known tangent error.
#[derive(Debug, Clone, Serialize)]
pub struct TangentTrial {
    /// True α0 = estimated − true tangent (deg).
    pub alpha0_deg: f64,
    /// The estimator's first answer: "estimate", "reprobe" or "failed".
    pub first: &'static str,
    /// The final answer: "estimate" or "failed".
    pub last: &'static str,
    /// Why the estimator asked for a re-probe, if it did ("fold", "equal_responses", ...).
    pub reprobe_reason: Option<String>,
    /// Final estimate's error (deg), if any.
    pub error_deg: Option<f64>,
    /// The thesis's eq. 5.8 on broadband RMS of the first two probes: its error (deg).
    pub thesis_error_deg: Option<f64>,
    /// Eq. 6.1 on broadband RMS with the measured strokes: its error (deg).
    pub thesis_6_1_error_deg: Option<f64>,
    /// The signed ratio of the responses to the commanded strokes (exact eq. 5.8): its error (deg).
    pub ratio_error_deg: Option<f64>,
    /// Rule used ("MotionRegression", "CommandedRatio" or "TipPath").
    pub method: Option<String>,
    /// Reported standard error (deg).
    pub std_error_deg: Option<f64>,
    /// Failure text, if any.
    pub failure: Option<String>,
    /// Time the estimation took (s).
    pub duration_s: f64,
}

/// One case of the `tangent` sweep.
#[derive(Debug, Clone, Serialize)]
pub struct TangentCase {
    /// Case name.
    pub case: String,
    /// Largest |error| over |α0| ≤ 10° (deg).
    pub max_error_within_10_deg: f64,
    /// Largest |error| over all accepted estimates (deg).
    pub max_error_deg: f64,
    /// Accepted estimates more than 0.5° off (never acceptable).
    pub wrong_answers: usize,
    /// First answers that were re-probe requests.
    pub reprobes: usize,
    /// Final answers that were explicit failures.
    pub failures: usize,
    /// RMS error of the thesis's eq. 5.8 on broadband RMS (deg).
    pub thesis_rms_error_deg: f64,
    /// RMS error of eq. 6.1 with the measured strokes (deg).
    pub thesis_6_1_rms_error_deg: f64,
    /// RMS error of the signed commanded-stroke ratio (deg).
    pub ratio_rms_error_deg: f64,
    /// Trials.
    pub trials: Vec<TangentTrial>,
}

/// Summary of `tangent`.
#[derive(Debug, Clone, Serialize)]
pub struct TangentSummary {
    /// Stroke amplitude (m), frequency (Hz), probe angles (deg).
    pub amplitude_m: f64,
    /// Stroke frequency (Hz).
    pub frequency_hz: f64,
    /// First probe angles (deg).
    pub probe_angles_deg: [f64; 2],
    /// The α0 sweeps.
    pub cases: Vec<TangentCase>,
    /// Noise sweep at α0 = 3°, no friction: (σ N, error deg, reported standard error deg).
    pub noise_sweep: Vec<[f64; 3]>,
}

fn outcome_name(o: &TangentOutcome) -> &'static str {
    match o {
        TangentOutcome::Estimate(_) => "estimate",
        TangentOutcome::Reprobe { .. } => "reprobe",
        TangentOutcome::Failed(_) => "failed",
    }
}

/// Runs one requested estimation to its end; returns the estimator's answers.
pub(crate) fn estimate_once(
    cfg: &SimConfig,
    a_omega: f64,
) -> Result<(Vec<EstimateLog>, f64), ExperimentError> {
    let mut sim = Lockstep::new(cfg)?;
    sim.servo_mut().set_a_omega(a_omega);
    sim.run((0.3 / sim.dt()) as usize);
    let t0 = sim.time();
    sim.servo_mut().request_tangent_estimate();
    let limit = (60.0 / sim.dt()) as usize;
    for _ in 0..limit {
        sim.step();
        if sim.servo().mode() == crate::servo::ServoMode::Track && !sim.estimates().is_empty() {
            break;
        }
    }
    Ok((sim.estimates().to_vec(), sim.time() - t0))
}

fn trial(cfg: &SimConfig, alpha0_deg: f64, a_omega: f64) -> Result<TangentTrial, ExperimentError> {
    let mut cfg = cfg.clone();
    cfg.tangent_error_rad = alpha0_deg.to_radians();
    let (logs, duration) = estimate_once(&cfg, a_omega)?;
    let first = logs
        .first()
        .ok_or_else(|| ExperimentError::no_result("tangent", "the estimation never finished"))?;
    let last = logs
        .last()
        .ok_or_else(|| ExperimentError::no_result("tangent", "the estimation never finished"))?;
    // The thesis formulas answer α0 from the first two strokes; compare each with the true
    // α0 = base − true angle.
    let cross_check = |pick: fn(&crate::tangent::TangentEstimate) -> Option<f64>| {
        logs.iter().find_map(|l| match l.outcome {
            TangentOutcome::Estimate(e) => {
                pick(&e).map(|a| (a - (l.base_angle_rad - l.true_angle_rad)).to_degrees())
            }
            _ => None,
        })
    };
    let thesis_error_deg = cross_check(|e| e.thesis_alpha0_rad);
    let thesis_6_1_error_deg = cross_check(|e| e.thesis_6_1_alpha0_rad);
    let ratio_error_deg = cross_check(|e| e.ratio_alpha0_rad);
    let (error_deg, method, std_error_deg, failure) = match last.outcome {
        TangentOutcome::Estimate(e) => (
            Some((e.tangent_angle_rad - last.true_angle_rad).to_degrees()),
            Some(format!("{:?}", e.method)),
            Some(e.std_error_rad.to_degrees()),
            None,
        ),
        TangentOutcome::Failed(f) => (None, None, None, Some(f.to_string())),
        TangentOutcome::Reprobe { .. } => {
            (None, None, None, Some("re-probe left unanswered".into()))
        }
    };
    Ok(TangentTrial {
        alpha0_deg,
        first: outcome_name(&first.outcome),
        reprobe_reason: match first.outcome {
            TangentOutcome::Reprobe { reason, .. } => Some(format!("{reason:?}")),
            _ => None,
        },
        last: outcome_name(&last.outcome),
        error_deg,
        thesis_error_deg,
        thesis_6_1_error_deg,
        ratio_error_deg,
        method,
        std_error_deg,
        failure,
        duration_s: duration,
    })
}

/// Tangent estimation on a flat surface for α0 from −15° to +15° in three cases: no friction;
/// eq. 4.23 friction with the friction-suppression dither running (Aω = 50 mm/s); eq. 4.23
/// friction without dither. Plus a sensor-noise sweep. Stroke 1 mm at 1 Hz, k_e = 10e3 N/m.
pub fn tangent(opts: &Options) -> Result<Outcome<TangentSummary>, ExperimentError> {
    let base = config(opts, TunerConfig::Fixed);
    let p = base.servo.tangent;
    let angles: Vec<f64> = (-15..=15).map(f64::from).collect();
    let mut cases = Vec::new();
    let mut simulated = 0.0;
    let variants: [(&str, bool, f64); 3] = [
        ("no friction", false, 0.0),
        ("friction + dither", true, 0.05),
        ("friction, no dither", true, 0.0),
    ];
    for (name, friction, a_omega) in variants {
        let mut cfg = base.clone();
        if !friction {
            cfg.plant.friction = frictionless();
        }
        let mut trials = Vec::new();
        for &a in &angles {
            let t = trial(&cfg, a, a_omega)?;
            simulated += t.duration_s + 0.3;
            trials.push(t);
        }
        let errs = |within: f64| {
            trials
                .iter()
                .filter(|t| t.alpha0_deg.abs() <= within)
                .filter_map(|t| t.error_deg)
                .fold(0.0f64, |m, e| m.max(e.abs()))
        };
        let rms =
            |v: Vec<f64>| (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt();
        let thesis_rms = rms(trials.iter().filter_map(|t| t.thesis_error_deg).collect());
        let thesis_61 = rms(trials
            .iter()
            .filter_map(|t| t.thesis_6_1_error_deg)
            .collect());
        let ratio = rms(trials.iter().filter_map(|t| t.ratio_error_deg).collect());
        cases.push(TangentCase {
            case: name.into(),
            max_error_within_10_deg: errs(10.0),
            max_error_deg: errs(90.0),
            wrong_answers: trials
                .iter()
                .filter(|t| t.error_deg.is_some_and(|e| e.abs() > 0.5))
                .count(),
            reprobes: trials.iter().filter(|t| t.first == "reprobe").count(),
            failures: trials.iter().filter(|t| t.last == "failed").count(),
            thesis_rms_error_deg: thesis_rms,
            thesis_6_1_rms_error_deg: thesis_61,
            ratio_rms_error_deg: ratio,
            trials,
        });
    }
    let mut noise_sweep = Vec::new();
    for sigma in [0.005, 0.01, 0.02, 0.05, 0.1] {
        let mut cfg = base.clone();
        cfg.plant.friction = frictionless();
        cfg.sensor.noise_force_n = sigma;
        cfg.servo.tangent.noise_std_n = sigma;
        let t = trial(&cfg, 3.0, 0.0)?;
        simulated += t.duration_s + 0.3;
        noise_sweep.push([
            sigma,
            t.error_deg.unwrap_or(f64::NAN),
            t.std_error_deg.unwrap_or(f64::NAN),
        ]);
    }
    let checks = vec![
        Check::at_most(
            "no_friction_error_max_deg",
            "no friction: max |error| for |α0| ≤ 10° (deg)",
            cases[0].max_error_within_10_deg,
            0.1,
        ),
        Check::at_most(
            "dither_error_max_deg",
            "friction + dither: max |error| for |α0| ≤ 10° (deg)",
            cases[1].max_error_within_10_deg,
            0.5,
        ),
        Check::at_most(
            "no_friction_wrong_answers",
            "no friction: accepted answers > 0.5° off, |α0| ≤ 15°",
            cases[0].wrong_answers as f64,
            0.0,
        ),
        Check::at_most(
            "dither_wrong_answers",
            "friction + dither: accepted answers > 0.5° off, |α0| ≤ 15°",
            cases[1].wrong_answers as f64,
            0.0,
        ),
    ];
    let pts = |c: &TangentCase, thesis: bool| -> Vec<[f64; 2]> {
        c.trials
            .iter()
            .filter_map(|t| {
                if thesis {
                    t.thesis_error_deg
                } else {
                    t.error_deg
                }
                .map(|e| [t.alpha0_deg, e])
            })
            .collect()
    };
    let figure = Figure {
        title: format!(
            "tangent: estimation error against the tangent error α0 (A = {} mm, {} Hz)",
            p.amplitude_m * 1e3,
            p.frequency_hz
        ),
        x_label: "α0, estimated − true tangent (deg)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "error of the estimate (deg)".into(),
                series: cases
                    .iter()
                    .map(|c| markers(&c.case, pts(c, false)))
                    .collect(),
            },
            Panel {
                x_label: None,
                y_label: "thesis eq. 5.8 on RMS: error (deg)".into(),
                series: cases
                    .iter()
                    .map(|c| markers(&c.case, pts(c, true)))
                    .collect(),
            },
        ],
    };
    Ok(Outcome {
        summary: TangentSummary {
            amplitude_m: p.amplitude_m,
            frequency_hz: p.frequency_hz,
            probe_angles_deg: p.probe_angles_deg,
            cases,
            noise_sweep,
        },
        checks,
        simulated_s: simulated,
        figure,
    })
}

pub use crate::monitor::{TrackSample, TrackingRun};

/// Tracks the surface of `cfg` from its start along +u at `velocity` until the contact reaches
/// `u_end` (or `time_limit`), with tangent estimation triggered by the force limits and the
/// friction-suppression dither at `a_omega`.
pub(crate) fn run_tracking(
    cfg: &SimConfig,
    velocity: f64,
    u_end: f64,
    a_omega: f64,
    settle_s: f64,
    time_limit: f64,
) -> Result<TrackingRun, ExperimentError> {
    use crate::monitor::{MonitorTick, TrackingMonitor};
    use crate::msg::{PlantSample, ServoSample};
    let mut cfg = cfg.clone();
    cfg.servo.tracking.enabled = true;
    let mut sim = Lockstep::new(&cfg)?;
    sim.servo_mut().set_a_omega(a_omega);
    let mut moving = false;
    let period = (1.0 / (cfg.servo.dither.frequency_hz * sim.dt()))
        .round()
        .max(1.0) as usize;
    let mut monitor = TrackingMonitor::new(cfg.servo.hybrid.preload_n, period);
    let limit = (time_limit / sim.dt()) as u64;
    for seq in 0..limit {
        // The travel starts once the tool has dithered at rest for `settle_s`, on the tick the
        // scenario driver starts it.
        if !moving && sim.time() >= settle_s - crate::scenario::SCENARIO_TIME_EPS_S {
            moving = true;
            sim.servo_mut().hybrid_mut().set_velocity(velocity);
        }
        sim.step();
        let p = PlantSample::of_tick(sim.truth(), seq, 0);
        let s = ServoSample::of_tick(sim.servo(), seq, 0, sim.time());
        monitor.push(&MonitorTick::from_samples(&p, &s));
        if sim.truth().surface_u_m >= u_end {
            break;
        }
    }
    let mut run = monitor.finish(sim.servo().counters());
    run.estimates = sim.estimates().to_vec();
    Ok(run)
}

pub(super) fn tracking_figure(title: String, runs: &[(&str, &TrackingRun)]) -> Figure {
    let mut panels = vec![
        Panel {
            x_label: None,
            y_label: "tangent angle (deg)".into(),
            series: vec![],
        },
        Panel {
            x_label: None,
            y_label: "tangent error (deg)".into(),
            series: vec![],
        },
        Panel {
            x_label: None,
            y_label: "normal force (N)".into(),
            series: vec![],
        },
    ];
    for (i, (name, run)) in runs.iter().enumerate() {
        let s = &run.samples;
        if i == 0 {
            panels[0].series.push(series(
                "true",
                s.iter()
                    .map(|x| [x.u_m * 1e3, x.true_angle_rad.to_degrees()])
                    .collect(),
            ));
        }
        panels[0].series.push(series(
            &format!("{name}: estimated"),
            s.iter()
                .map(|x| [x.u_m * 1e3, x.estimated_angle_rad.to_degrees()])
                .collect(),
        ));
        panels[1].series.push(series(
            name,
            s.iter()
                .map(|x| {
                    [
                        x.u_m * 1e3,
                        crate::math::wrap_angle(x.estimated_angle_rad - x.true_angle_rad)
                            .to_degrees(),
                    ]
                })
                .collect(),
        ));
        panels[2].series.push(series(
            name,
            s.iter().map(|x| [x.u_m * 1e3, x.normal_n]).collect(),
        ));
        let est: Vec<[f64; 2]> = run
            .estimates
            .iter()
            .filter_map(|e| match e.outcome {
                TangentOutcome::Estimate(x) => Some([
                    run.samples
                        .iter()
                        .min_by(|a, b| (a.t - e.time_s).abs().total_cmp(&(b.t - e.time_s).abs()))
                        .map_or(0.0, |s| s.u_m * 1e3),
                    x.tangent_angle_rad.to_degrees(),
                ]),
                _ => None,
            })
            .collect();
        panels[0]
            .series
            .push(markers(&format!("{name}: estimates"), est));
    }
    Figure {
        title,
        x_label: "position along the surface u (mm)".into(),
        log_x: false,
        panels,
    }
}

/// Summary of `fig5.6`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig56Summary {
    /// Sinusoid amplitude and wavelength (m).
    pub amplitude_m: f64,
    /// Wavelength (m).
    pub wavelength_m: f64,
    /// Nominal velocity (m/s).
    pub velocity_m_per_s: f64,
    /// The run.
    pub run: TrackingRun,
}

/// fig5.6's sinusoid: amplitude (m) and wavelength (m).
const FIG5_6_AMPLITUDE_M: f64 = 0.003;
const FIG5_6_WAVELENGTH_M: f64 = 0.12;

/// Puts `cfg` on fig5.6's sinusoid, through the arm's operating point, the tool at its start
/// (half a wavelength before it); returns where the run ends (m along the surface).
pub(crate) fn on_fig5_6_sinusoid(cfg: &mut SimConfig) -> f64 {
    let origin = cfg.surface.frame.origin_m;
    cfg.surface = crate::surface::Surface {
        frame: crate::surface::SurfaceFrame {
            origin_m: origin,
            angle_rad: 0.0,
        },
        shape: crate::surface::Shape::Sinusoid {
            amplitude_m: FIG5_6_AMPLITUDE_M,
            wavelength_m: FIG5_6_WAVELENGTH_M,
        },
    };
    cfg.start_u_m = -0.5 * FIG5_6_WAVELENGTH_M;
    0.5 * FIG5_6_WAVELENGTH_M
}

/// Tracking an unknown sinusoidal surface (fig. 5.6): amplitude 3 mm, wavelength 120 mm (slopes
/// ±9°), one wavelength centred on the arm's operating point at 5 mm/s with the
/// friction-suppression dither at 5 ẋ_o, sensor noise σ = 0.02 N; the controller starts with
/// the true tangent and re-estimates when a force limit trips.
pub fn fig5_6(opts: &Options) -> Result<Outcome<Fig56Summary>, ExperimentError> {
    let (amp, wl, v) = (FIG5_6_AMPLITUDE_M, FIG5_6_WAVELENGTH_M, 0.005);
    let mut cfg = config(opts, TunerConfig::Fixed);
    let end = on_fig5_6_sinusoid(&mut cfg);
    let run = run_tracking(&cfg, v, end, 5.0 * v, 0.0, 400.0)?;
    let checks = vec![
        Check::at_most(
            "tangent_error_rms_deg",
            "tangent error RMS (deg)",
            run.tangent_error_rms_deg,
            1.0,
        ),
        Check::at_most(
            "normal_deviation_max",
            "worst |F_N − preload| / preload (dither-period mean)",
            run.worst_normal_deviation,
            0.2,
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
            0.99 * wl,
        ),
    ];
    let figure = tracking_figure(
        format!(
            "fig5.6: tracking a sinusoid ({} mm, {} mm), {} estimations",
            amp * 1e3,
            wl * 1e3,
            run.estimations.estimates
        ),
        &[("dither method", &run)],
    );
    Ok(Outcome {
        simulated_s: run.duration_s,
        summary: Fig56Summary {
            amplitude_m: amp,
            wavelength_m: wl,
            velocity_m_per_s: v,
            run,
        },
        checks,
        figure,
    })
}

#[cfg(test)]
mod scenario_tests {
    use super::*;

    /// The surface-tracking scenario run through the lockstep gives the same figures, bit for
    /// bit, as the `fig5.6` experiment's code over the same 3 s started the scenario's way (one
    /// monitor measures both, the one from the servo's samples).
    #[test]
    fn lockstep_reference_matches_the_experiment_code() {
        let base = SimConfig::default();
        let s = crate::scenario::Scenario::new("surface-tracking", &base).unwrap();
        let r = crate::scenario::run_lockstep(&s, 3.0).unwrap();
        assert_eq!(r.ticks, 30_000);
        let e = run_tracking(
            &s.cfg,
            crate::scenario::TRACKING_VELOCITY,
            s.end_u_m.unwrap(),
            5.0 * crate::scenario::TRACKING_VELOCITY,
            crate::scenario::TRACKING_SETTLE_S,
            3.0,
        )
        .unwrap();
        assert_eq!(r.tracking.tangent_error_rms_deg, e.tangent_error_rms_deg);
        assert_eq!(r.tracking.worst_normal_deviation, e.worst_normal_deviation);
        assert_eq!(r.tracking.travelled_m, e.travelled_m);
        assert_eq!(r.tracking.ticks_without_contact, 0);
        // Every counter crosses the servo's samples, the triggers too.
        assert_eq!(r.tracking.estimations, e.estimations);
        assert_eq!(e.estimations.slope_triggers, 1, "{:?}", e.estimations);
        let c = crate::scenario::compare(&r, &r);
        assert!(c.agrees);
    }
}
