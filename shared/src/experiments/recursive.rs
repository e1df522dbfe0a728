//! The recursive form of eq. 5.10 in use: the servo follows a slowly turning surface on the
//! batch estimate of each probe record (as the thesis), on recursive least squares with
//! exponential forgetting, or on recursive least squares with a drifting angle
//! ([`TangentRls::with_drift`]), all fed the same probes.

use super::*;
use crate::error::ExperimentError;
use crate::math::{Vec2, perp, unit, wrap_angle};
use crate::servo::ServoMode;
use crate::sim::Lockstep;
use crate::tangent::{self, TangentOutcome, TangentRls, probe_stats};
use crate::tuner::TunerConfig;
use serde::Serialize;

/// Which estimate the servo follows in a run of `rls`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Follow {
    /// The batch estimate of each record (eq. 5.8's least-squares form).
    Batch,
    /// Eq. 5.10 as RLS with exponential forgetting λ per probe.
    Forgetting,
    /// Eq. 5.10 as RLS whose angle drifts (process noise along the angle only).
    Drift,
}

/// One answered probe record.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct RlsAnswer {
    /// Time of the answer (s).
    pub time_s: f64,
    /// True tangent angle then (rad).
    pub true_angle_rad: f64,
    /// The batch estimate, if the record gave one (rad).
    pub batch_angle_rad: Option<f64>,
    /// The RLS with exponential forgetting after this record's probes (rad).
    pub forgetting_angle_rad: f64,
    /// The RLS with a drifting angle after this record's probes (rad).
    pub drift_angle_rad: f64,
}

/// One run of `rls`.
#[derive(Debug, Clone, Serialize)]
pub struct RlsRun {
    /// The estimate the servo followed.
    pub follow: Follow,
    /// Records answered.
    pub answers: Vec<RlsAnswer>,
    /// Records without a batch estimate (re-probe or failure).
    pub unanswered: usize,
    /// RMS of batch − true over the answers after the first two (deg).
    pub batch_rms_error_deg: f64,
    /// RMS of the forgetting RLS − true over the same answers (deg).
    pub forgetting_rms_error_deg: f64,
    /// RMS of the drift RLS − true over the same answers (deg).
    pub drift_rms_error_deg: f64,
    /// RMS of the servo's tangent − true over time after the second answer (deg).
    pub tracking_rms_error_deg: f64,
    /// Largest |servo's tangent − true| after the second answer (deg).
    pub tracking_worst_error_deg: f64,
}

/// Summary of `rls`.
#[derive(Debug, Clone, Serialize)]
pub struct RlsSummary {
    /// Rate at which the surface turns about the contact point (deg/s).
    pub turn_rate_deg_per_s: f64,
    /// Forgetting factor λ per probe of the forgetting form.
    pub forgetting: f64,
    /// Angle random walk per probe of the drift form (deg).
    pub drift_deg_per_probe: f64,
    /// Force noise the drift form assumes (N).
    pub drift_force_noise_n: f64,
    /// Simulated time per run (s).
    pub duration_s: f64,
    /// Per run.
    pub runs: Vec<RlsRun>,
}

const TURN_RATE_DEG_S: f64 = 0.02;
const FORGETTING: f64 = 0.7;
/// Angle random walk per probe for the drift form: about the turn between two probes.
const DRIFT_DEG: f64 = 0.1;
/// Scatter of an in-phase force about the model across records (the stiffness the records see
/// varies by about ±3 %); the measured standard error √2·r_std is smaller, about 0.0007 N.
const FORCE_NOISE_N: f64 = 0.003;
const DURATION_S: f64 = 150.0;

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}

fn run(
    opts: &Options,
    follow: Follow,
    trace: &mut Vec<[f64; 3]>,
) -> Result<RlsRun, ExperimentError> {
    let cfg = config(opts, TunerConfig::Fixed);
    let params = cfg.servo.tangent;
    let mut sim = Lockstep::new(&cfg)?;
    sim.set_auto_estimate(false);
    let start = cfg.surface.tangent_angle_at(cfg.start_u_m);
    let k0 = cfg.plant.contact.stiffness();
    let mut forgetting = TangentRls::new(FORGETTING, 1e12, start, k0);
    let mut drift = TangentRls::with_drift(1e12, start, k0, DRIFT_DEG.to_radians(), FORCE_NOISE_N);
    let rate = TURN_RATE_DEG_S.to_radians();
    let every = 10;
    let dt = sim.dt();
    let steps = (DURATION_S / dt).round() as usize;
    let mut answers = Vec::new();
    let mut unanswered = 0;
    let mut last_answer = 0.0;
    sim.run((0.3 / dt) as usize);
    for i in 0..steps {
        if i % every == 0 {
            // Turn the surface about the contact point.
            let mut s = sim.world().surface().clone();
            let c = sim.truth().tip;
            let d = rate * every as f64 * dt;
            let o = Vec2::new(s.frame.origin_m[0], s.frame.origin_m[1]) - c;
            let r = (nalgebra::Rotation2::new(d) * o) + c;
            s.frame.origin_m = [r.x, r.y];
            s.frame.angle_rad += d;
            sim.set_surface(s);
        }
        sim.step();
        if i % 1000 == 0 {
            let est = {
                let t = sim.servo().hybrid().frame().tangent();
                t.y.atan2(t.x)
            };
            trace.push([
                sim.time(),
                sim.truth().tangent_angle_rad.to_degrees(),
                est.to_degrees(),
            ]);
        }
        let mode = sim.servo().mode();
        if mode == ServoMode::Track && sim.time() - last_answer > 0.5 {
            sim.servo_mut().request_tangent_estimate();
        }
        let Some(req) = sim.servo().pending_probe() else {
            continue;
        };
        let batch = tangent::estimate(req.samples, req.plan, req.base_angle, &params, req.reprobe);
        if let TangentOutcome::Reprobe { .. } = batch {
            sim.servo_mut().apply_tangent_outcome(&batch);
            continue;
        }
        // The record's probes, the force projected on the normal the probes refer to.
        let count = req.plan.count.min(tangent::MAX_PROBES);
        let normal = perp(unit(req.base_angle));
        let stats: Vec<_> = (0..count)
            .map(|k| {
                probe_stats(
                    req.samples,
                    k as u8,
                    req.plan.offsets[k],
                    req.base_angle,
                    normal,
                    req.plan.periods,
                    req.plan.dither_hz,
                )
            })
            .collect();
        forgetting.update_from(&stats, req.base_angle);
        drift.update_from(&stats, req.base_angle);
        let base = req.base_angle;
        let truth = sim.truth().tangent_angle_rad;
        let batch_angle = match batch {
            TangentOutcome::Estimate(e) => Some(e.tangent_angle_rad),
            _ => None,
        };
        if batch_angle.is_none() {
            unanswered += 1;
        }
        answers.push(RlsAnswer {
            time_s: sim.time(),
            true_angle_rad: truth,
            batch_angle_rad: batch_angle,
            forgetting_angle_rad: forgetting.tangent_angle(),
            drift_angle_rad: drift.tangent_angle(),
        });
        let recursive = match follow {
            Follow::Batch => None,
            Follow::Forgetting => Some(forgetting.tangent_angle()),
            Follow::Drift => Some(drift.tangent_angle()),
        };
        let applied = match (recursive, batch) {
            (Some(angle), TangentOutcome::Estimate(mut e)) => {
                e.tangent_angle_rad = angle;
                e.alpha0_rad = wrap_angle(base - angle);
                TangentOutcome::Estimate(e)
            }
            _ => batch,
        };
        sim.servo_mut().apply_tangent_outcome(&applied);
        last_answer = sim.time();
    }
    let settled: Vec<&RlsAnswer> = answers.iter().skip(2).collect();
    let deg = |a: f64, b: f64| wrap_angle(a - b).to_degrees();
    let after = answers.get(1).map_or(f64::INFINITY, |a| a.time_s);
    let tracked: Vec<f64> = trace
        .iter()
        .filter(|p| p[0] > after)
        .map(|p| p[2] - p[1])
        .collect();
    Ok(RlsRun {
        follow,
        batch_rms_error_deg: rms(settled
            .iter()
            .filter_map(|a| a.batch_angle_rad.map(|b| deg(b, a.true_angle_rad)))),
        forgetting_rms_error_deg: rms(settled
            .iter()
            .map(|a| deg(a.forgetting_angle_rad, a.true_angle_rad))),
        drift_rms_error_deg: rms(settled
            .iter()
            .map(|a| deg(a.drift_angle_rad, a.true_angle_rad))),
        tracking_rms_error_deg: rms(tracked.iter().copied()),
        tracking_worst_error_deg: tracked.iter().fold(0.0, |m: f64, e| m.max(e.abs())),
        answers,
        unanswered,
    })
}

/// A flat surface turns at 0.02°/s about the contact point for 150 s while the servo holds the
/// preload and re-estimates the tangent 0.5 s after every answer (one record: two probes,
/// about 9 s). Three runs: the servo follows the batch estimate of each record, the RLS with
/// exponential forgetting (λ = 0.7 per probe), or the RLS with a drifting angle (0.1° per
/// probe); every run computes all three on its own records.
pub fn rls(opts: &Options) -> Result<Outcome<RlsSummary>, ExperimentError> {
    let mut runs = Vec::new();
    let mut traces = Vec::new();
    for follow in [Follow::Batch, Follow::Forgetting, Follow::Drift] {
        let mut trace = Vec::new();
        runs.push(run(opts, follow, &mut trace)?);
        traces.push(trace);
    }
    let (batch, forgetting, drift) = (&runs[0], &runs[1], &runs[2]);
    let answers = runs.iter().map(|r| r.answers.len()).min().unwrap_or(0);
    let checks = vec![
        Check::at_least("answers_per_run", "answers per run", answers as f64, 10.0),
        Check::at_most(
            "batch_tracking_rms_error_deg",
            "servo on the batch estimate: tracking RMS error (deg)",
            batch.tracking_rms_error_deg,
            0.5,
        ),
        Check::at_most(
            "drift_rls_tracking_rms_error_deg",
            "servo on the drift RLS: tracking RMS error (deg)",
            drift.tracking_rms_error_deg,
            0.5,
        ),
        Check::at_most(
            "drift_rls_over_batch_rms_error",
            "drift RLS / batch, RMS error at the answers (run on the drift RLS)",
            drift.drift_rms_error_deg / drift.batch_rms_error_deg,
            1.0,
        ),
    ];
    let error_series = |trace: &[[f64; 3]]| -> Vec<[f64; 2]> {
        trace.iter().map(|p| [p[0], p[2] - p[1]]).collect()
    };
    let at_answers = |r: &RlsRun, pick: fn(&RlsAnswer) -> Option<f64>| -> Vec<[f64; 2]> {
        r.answers
            .iter()
            .filter_map(|a| {
                pick(a).map(|v| [a.time_s, wrap_angle(v - a.true_angle_rad).to_degrees()])
            })
            .collect()
    };
    let figure = Figure {
        title: format!(
            "rls: a surface turning at {TURN_RATE_DEG_S}°/s, batch vs recursive eq. 5.10 (forgetting λ = {FORGETTING}, drift {DRIFT_DEG}°/probe)"
        ),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "tangent angle (deg)".into(),
                series: vec![
                    series("true", traces[0].iter().map(|p| [p[0], p[1]]).collect()),
                    series(
                        "servo on batch",
                        traces[0].iter().map(|p| [p[0], p[2]]).collect(),
                    ),
                    series(
                        "servo on RLS, forgetting",
                        traces[1].iter().map(|p| [p[0], p[2]]).collect(),
                    ),
                    series(
                        "servo on RLS, drift",
                        traces[2].iter().map(|p| [p[0], p[2]]).collect(),
                    ),
                ],
            },
            Panel {
                x_label: None,
                y_label: "servo's tangent − true (deg)".into(),
                series: vec![
                    series("on batch", error_series(&traces[0])),
                    series("on RLS, forgetting", error_series(&traces[1])),
                    series("on RLS, drift", error_series(&traces[2])),
                ],
            },
            Panel {
                x_label: None,
                y_label: "estimate − true at each answer (deg)".into(),
                series: vec![
                    markers("batch", at_answers(batch, |a| a.batch_angle_rad)),
                    markers(
                        "RLS, forgetting",
                        at_answers(forgetting, |a| Some(a.forgetting_angle_rad)),
                    ),
                    markers("RLS, drift", at_answers(drift, |a| Some(a.drift_angle_rad))),
                ],
            },
        ],
    };
    Ok(Outcome {
        summary: RlsSummary {
            turn_rate_deg_per_s: TURN_RATE_DEG_S,
            forgetting: FORGETTING,
            drift_deg_per_probe: DRIFT_DEG,
            drift_force_noise_n: FORCE_NOISE_N,
            duration_s: DURATION_S,
            runs,
        },
        checks,
        simulated_s: 3.0 * (DURATION_S + 0.3),
        figure,
    })
}
