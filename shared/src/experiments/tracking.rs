//! Chapter 5 experiments: tangent estimation by dither, surface tracking, corners.

use super::*;
use crate::friction::FrictionLaw;
use crate::sim::{EstimateLog, Lockstep, SimConfig};
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
    /// Final estimate's error (deg), if any.
    pub error_deg: Option<f64>,
    /// The thesis's eq. 5.8 on broadband RMS of the first two probes: its error (deg).
    pub thesis_error_deg: Option<f64>,
    /// Rule used ("same_side", "along_probe", "least_squares").
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
) -> Result<(Vec<EstimateLog>, f64), String> {
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

fn trial(cfg: &SimConfig, alpha0_deg: f64, a_omega: f64) -> Result<TangentTrial, String> {
    let mut cfg = cfg.clone();
    cfg.tangent_error_rad = alpha0_deg.to_radians();
    let (logs, duration) = estimate_once(&cfg, a_omega)?;
    let first = logs.first().ok_or("the estimation never finished")?;
    let last = logs.last().ok_or("the estimation never finished")?;
    let thesis_error_deg = logs.iter().find_map(|l| match l.outcome {
        TangentOutcome::Estimate(e) => e
            .thesis_alpha0_rad
            .map(|a| (a - (l.base_angle_rad - l.true_angle_rad)).to_degrees()),
        _ => None,
    });
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
        last: outcome_name(&last.outcome),
        error_deg,
        thesis_error_deg,
        method,
        std_error_deg,
        failure,
        duration_s: duration,
    })
}

/// Tangent estimation on a flat surface for α0 from −15° to +15° in three cases: no friction;
/// eq. 4.23 friction with the friction-suppression dither running (Aω = 50 mm/s); eq. 4.23
/// friction without dither. Plus a sensor-noise sweep. Stroke 1 mm at 1 Hz, k_e = 10e3 N/m.
pub fn tangent(opts: &Options) -> Result<Outcome<TangentSummary>, String> {
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
        let thesis: Vec<f64> = trials.iter().filter_map(|t| t.thesis_error_deg).collect();
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
            thesis_rms_error_deg: (thesis.iter().map(|e| e * e).sum::<f64>()
                / thesis.len().max(1) as f64)
                .sqrt(),
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
            "no friction: max |error| for |α0| ≤ 10° (deg)",
            cases[0].max_error_within_10_deg,
            0.1,
        ),
        Check::at_most(
            "friction + dither: max |error| for |α0| ≤ 10° (deg)",
            cases[1].max_error_within_10_deg,
            0.5,
        ),
        Check::at_most(
            "no friction: accepted answers > 0.5° off, |α0| ≤ 15°",
            cases[0].wrong_answers as f64,
            0.0,
        ),
        Check::at_most(
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
                y_label: "error of the estimate (deg)".into(),
                series: cases
                    .iter()
                    .map(|c| markers(&c.case, pts(c, false)))
                    .collect(),
            },
            Panel {
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
