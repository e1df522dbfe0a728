//! Chapter 4, on-line tuning of the dither: the thesis's tuner against afs's cost tuner from
//! Aω = 0.2 ẋ_o (fig. 4.8), and slow tuning as Aω passes ẋ_o (figs. 4.9, 4.10).

use super::*;
use crate::config::SimConfig;
use crate::error::ExperimentError;
use crate::sim::Lockstep;
use crate::ticks::{Tick, decimate, run_recording, sliding_periods, window};
use crate::tuner::{CostTunerParams, ThesisTunerParams, TunerConfig, TunerReport};
use serde::Serialize;

/// One tuner's run in `fig4.8`.
#[derive(Debug, Clone, Serialize)]
pub struct TunerRun {
    /// "thesis" or "cost".
    pub tuner: &'static str,
    /// Mean friction at the start, Aω = 0.2 ẋ_o (N).
    pub start_mean_n: f64,
    /// Mean friction over the 3 periods ending 5 s after tuning started (N).
    pub mean_at_5s_n: f64,
    /// mean_at_5s / start.
    pub ratio_at_5s: f64,
    /// First time (s after tuning started) the 3-period mean fell below 25 % of the start.
    pub time_to_quarter_s: Option<f64>,
    /// Worst |F_N − preload| / preload after 0.5 s, true force.
    pub worst_normal_deviation: f64,
    /// Same on the measured (noisy) force.
    pub worst_normal_deviation_measured: f64,
    /// Smallest true normal force over the run (N).
    pub min_normal_n: f64,
    /// Aω averaged over the last second (m/s).
    pub settled_a_omega_m_per_s: f64,
    /// settled Aω / ẋ_o.
    pub settled_ratio: f64,
    /// Change of Aω over the last second ((m/s)/s).
    pub final_rate_m_per_s2: f64,
    /// Upper bound of Aω (m/s).
    pub a_omega_bound_m_per_s: f64,
    /// The tuner's final state.
    pub report: TunerReport,
    /// Where it settles and why.
    pub why: String,
}

/// Summary of `fig4.8`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig48Summary {
    /// Nominal velocity (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Preload (N).
    pub preload_n: f64,
    /// Per tuner.
    pub runs: Vec<TunerRun>,
}

/// Each tuner runs on the same 6.5 s traverse at 10 mm/s: 0.5 s at Aω = 0.2 ẋ_o (the starting
/// value), then tuning on line.
pub fn fig4_8(opts: &Options) -> Result<Outcome<Fig48Summary>, ExperimentError> {
    let v = 0.01;
    let duration = 6.5;
    let t_tune = 0.5;
    let mut runs = Vec::new();
    let mut checks = Vec::new();
    let mut simulated = 0.0;
    let mut panels = vec![
        Panel {
            x_label: None,
            y_label: "Aω (mm/s)".into(),
            series: vec![],
        },
        Panel {
            x_label: None,
            y_label: "mean tangential force, 3 periods (N)".into(),
            series: vec![],
        },
        Panel {
            x_label: None,
            y_label: "std of tangential force, 3 periods (N)".into(),
            series: vec![],
        },
        Panel {
            x_label: None,
            y_label: "normal force (N)".into(),
            series: vec![],
        },
    ];
    for tuner in [
        TunerConfig::Thesis(ThesisTunerParams::default()),
        TunerConfig::Cost(CostTunerParams::default()),
    ] {
        let mut cfg = config(opts, tuner);
        cfg.start_u_m = -0.5 * v * duration;
        let preload = cfg.servo.hybrid.preload_n;
        let mut sim = Lockstep::new(&cfg)?;
        sim.servo_mut().hybrid_mut().set_velocity(v);
        sim.servo_mut().set_a_omega(0.2 * v);
        let mut ticks = Vec::new();
        let mut ph = 0.0;
        run_recording(&mut sim, t_tune, &mut ticks, &mut ph);
        sim.servo_mut().set_tuning(true);
        run_recording(&mut sim, duration - t_tune, &mut ticks, &mut ph);
        simulated += sim.time();
        let name = sim.servo().tuner_name();
        let start = window(&ticks, 0.15, t_tune).mean_force_n;
        let sliding = sliding_periods(&ticks, 3);
        let at5 = sliding
            .iter()
            .rfind(|p| p[0] <= t_tune + 5.0 + 1e-9)
            .map_or(f64::NAN, |p| p[1]);
        let quarter = sliding
            .iter()
            .find(|p| p[0] > t_tune && p[1] < 0.25 * start)
            .map(|p| p[0] - t_tune);
        let after: Vec<&Tick> = ticks.iter().filter(|k| k.t >= 0.5).collect();
        let worst = after
            .iter()
            .map(|k| (k.normal_true - preload).abs() / preload)
            .fold(0.0, f64::max);
        let worst_meas = after
            .iter()
            .map(|k| (k.normal - preload).abs() / preload)
            .fold(0.0, f64::max);
        let min_normal = ticks
            .iter()
            .map(|k| if k.contact { k.normal_true } else { 0.0 })
            .fold(f64::INFINITY, f64::min);
        let last: Vec<&Tick> = ticks.iter().filter(|k| k.t > duration - 1.0).collect();
        let settled = last.iter().map(|k| k.a_cmd).sum::<f64>() / last.len().max(1) as f64;
        let rate = last.last().map_or(0.0, |k| k.a_cmd) - last.first().map_or(0.0, |k| k.a_cmd);
        let report = sim.servo().tuner_report();
        let bound = sim.servo().tuner_context().a_max;
        let why = explain(name, &report, settled, rate, bound, v, &cfg);
        checks.push(Check::at_most(
            format!("{name}_mean_at_5s_over_start"),
            format!("{name}: mean at 5 s / start"),
            at5 / start,
            0.25,
        ));
        checks.push(Check::at_most(
            format!("{name}_normal_deviation_max"),
            format!("{name}: worst |F_N − preload|/preload after 0.5 s"),
            worst,
            0.10,
        ));
        checks.push(Check::at_least(
            format!("{name}_normal_force_min_n"),
            format!("{name}: smallest normal force (N), contact kept"),
            min_normal,
            1e-6,
        ));
        let ms = |s: &[[f64; 3]], i: usize| -> Vec<[f64; 2]> {
            s.iter().map(|p| [p[0], p[i]]).collect()
        };
        panels[0]
            .series
            .push(series(name, decimate(&ticks, 100, |k| k.a_cmd * 1e3)));
        panels[1].series.push(series(name, ms(&sliding, 1)));
        panels[2].series.push(series(name, ms(&sliding, 2)));
        panels[3]
            .series
            .push(series(name, decimate(&ticks, 20, |k| k.normal_true)));
        runs.push(TunerRun {
            tuner: name,
            start_mean_n: start,
            mean_at_5s_n: at5,
            ratio_at_5s: at5 / start,
            time_to_quarter_s: quarter,
            worst_normal_deviation: worst,
            worst_normal_deviation_measured: worst_meas,
            min_normal_n: min_normal,
            settled_a_omega_m_per_s: settled,
            settled_ratio: settled / v,
            final_rate_m_per_s2: rate,
            a_omega_bound_m_per_s: bound,
            report,
            why,
        });
    }
    let preload = opts.base.servo.hybrid.preload_n;
    Ok(Outcome {
        summary: Fig48Summary {
            nominal_velocity_m_per_s: v,
            preload_n: preload,
            runs,
        },
        checks,
        simulated_s: simulated,
        figure: Figure {
            title:
                "fig4.8: on-line dither tuning from Aω = 0.2·ẋ_o (thesis eq. 4.22 vs cost tuner)"
                    .into(),
            x_label: "time (s)".into(),
            log_x: false,
            panels,
        },
    })
}

/// The slow on-line tuning run behind `fig4.9` and `fig4.10`.
struct SlowTuning {
    ticks: Vec<Tick>,
    nominal: f64,
    preload: f64,
    tune_at: f64,
    duration: f64,
    learning_rate: f64,
    simulated: f64,
}

/// The thesis's tuner (eq. 4.22) at half its default learning rate ("kept at a very
/// low value so that the gradual effect of the parameter change could be visualized"), from
/// Aω = 0.2 ẋ_o at 10 mm/s: 1 s untuned, then 6 s of tuning.
fn slow_tuning(opts: &Options) -> Result<SlowTuning, ExperimentError> {
    let v = 0.01;
    let (tune_at, duration) = (1.0, 7.0);
    let params = ThesisTunerParams {
        learning_rate: 0.5 * ThesisTunerParams::default().learning_rate,
        ..Default::default()
    };
    let mut cfg = config(opts, TunerConfig::Thesis(params));
    cfg.start_u_m = -0.5 * v * duration;
    let mut sim = Lockstep::new(&cfg)?;
    sim.servo_mut().hybrid_mut().set_velocity(v);
    sim.servo_mut().set_a_omega(0.2 * v);
    let mut ticks = Vec::with_capacity((duration / sim.dt()) as usize + 1);
    let mut ph = 0.0;
    run_recording(&mut sim, tune_at, &mut ticks, &mut ph);
    sim.servo_mut().set_tuning(true);
    run_recording(&mut sim, duration - tune_at, &mut ticks, &mut ph);
    Ok(SlowTuning {
        ticks,
        nominal: v,
        preload: cfg.servo.hybrid.preload_n,
        tune_at,
        duration,
        learning_rate: params.learning_rate,
        simulated: sim.time(),
    })
}

impl SlowTuning {
    /// First time the commanded Aω exceeds ẋ_o (s).
    fn crossing(&self) -> Option<f64> {
        self.ticks
            .iter()
            .find(|k| k.a_cmd > self.nominal)
            .map(|k| k.t)
    }
}

/// Summary of `fig4.9`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig49Summary {
    /// Nominal velocity ẋ_o (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Learning rate of eq. 4.22 (half the default).
    pub learning_rate: f64,
    /// When tuning starts (s).
    pub tuning_starts_s: f64,
    /// When the commanded Aω first exceeds ẋ_o (s).
    pub crossing_s: Option<f64>,
    /// Mean friction before tuning, Aω = 0.2 ẋ_o (N).
    pub mean_before_n: f64,
    /// Standard deviation of the friction before tuning (N).
    pub std_before_n: f64,
    /// Largest 1-period standard deviation within ±0.5 s of the crossing (N): the thesis's
    /// "the signal became worse" in the transition.
    pub std_in_transition_n: f64,
    /// Mean friction over the last second (N).
    pub mean_last_s_n: f64,
    /// mean_last_s / mean_before.
    pub ratio_last_s: f64,
}

/// The thesis's fig. 4.9: a slow tuning that takes Aω from below ẋ_o to above it; the mean
/// friction is steady and non-zero while ẋ_o dominates, then falls towards zero once Aω passes
/// ẋ_o.
pub fn fig4_9(opts: &Options) -> Result<Outcome<Fig49Summary>, ExperimentError> {
    let run = slow_tuning(opts)?;
    let before = window(&run.ticks, 0.2, run.tune_at);
    let last = window(&run.ticks, run.duration - 1.0, run.duration);
    let crossing = run.crossing();
    let per_period = sliding_periods(&run.ticks, 1);
    let std_transition = crossing.map_or(f64::NAN, |tc| {
        per_period
            .iter()
            .filter(|p| (p[0] - tc).abs() <= 0.5)
            .map(|p| p[2])
            .fold(0.0, f64::max)
    });
    let ratio = last.mean_force_n / before.mean_force_n;
    let checks = vec![
        Check::at_most(
            "a_omega_crosses_nominal_velocity",
            "Aω crosses ẋ_o, seconds after tuning starts",
            crossing.map_or(f64::INFINITY, |t| t - run.tune_at),
            run.duration - run.tune_at - 2.0,
        ),
        Check::at_most(
            "last_second_over_before_friction",
            "mean friction over the last second / before",
            ratio,
            0.15,
        ),
    ];
    let three = sliding_periods(&run.ticks, 3);
    let v = run.nominal;
    let figure = Figure {
        title: "fig4.9: slow tuning (eq. 4.22), the mean friction as Aω passes ẋ_o".into(),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "tangential force (N)".into(),
                series: vec![
                    series("measured", decimate(&run.ticks, 10, |k| k.friction)),
                    series(
                        "mean, 3 periods",
                        three.iter().map(|p| [p[0], p[1]]).collect(),
                    ),
                ],
            },
            Panel {
                x_label: None,
                y_label: "Aω / ẋ_o".into(),
                series: vec![series(
                    "commanded",
                    decimate(&run.ticks, 100, |k| k.a_cmd / v),
                )],
            },
        ],
    };
    Ok(Outcome {
        summary: Fig49Summary {
            nominal_velocity_m_per_s: v,
            learning_rate: run.learning_rate,
            tuning_starts_s: run.tune_at,
            crossing_s: crossing,
            mean_before_n: before.mean_force_n,
            std_before_n: before.std_force_n,
            std_in_transition_n: std_transition,
            mean_last_s_n: last.mean_force_n,
            ratio_last_s: ratio,
        },
        checks,
        simulated_s: run.simulated,
        figure,
    })
}

/// Summary of `fig4.10`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig410Summary {
    /// Nominal velocity ẋ_o (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Preload (N).
    pub preload_n: f64,
    /// Commanded Aω before tuning and at the end (m/s).
    pub a_omega_m_per_s: [f64; 2],
    /// 3-period standard deviation of the tangential force before tuning and over the last
    /// second (N).
    pub std_n: [f64; 2],
    /// Correlation over the run between the 3-period σ and the commanded Aω at its end.
    pub std_amplitude_correlation: f64,
    /// Standard deviation of the true normal force after tuning starts / preload.
    pub normal_std_fraction: f64,
    /// Worst |F_N − preload| / preload after tuning starts, true force.
    pub normal_worst_fraction: f64,
}

/// The thesis's fig. 4.10: the same slow tuning, the amplitude and the oscillation it brings,
/// with the normal force alongside.
pub fn fig4_10(opts: &Options) -> Result<Outcome<Fig410Summary>, ExperimentError> {
    let run = slow_tuning(opts)?;
    let three = sliding_periods(&run.ticks, 3);
    let a_at = |t: f64| {
        run.ticks
            .iter()
            .rfind(|k| k.t <= t)
            .map_or(f64::NAN, |k| k.a_cmd)
    };
    let pairs: Vec<[f64; 2]> = three.iter().map(|p| [a_at(p[0]), p[2]]).collect();
    let corr = crate::math::correlation(&pairs);
    let before = window(&run.ticks, 0.2, run.tune_at);
    let last = window(&run.ticks, run.duration - 1.0, run.duration);
    let after: Vec<&Tick> = run.ticks.iter().filter(|k| k.t >= run.tune_at).collect();
    let n = after.len().max(1) as f64;
    let mean_n = after.iter().map(|k| k.normal_true).sum::<f64>() / n;
    let std_n = (after
        .iter()
        .map(|k| (k.normal_true - mean_n).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let worst = after
        .iter()
        .map(|k| (k.normal_true - run.preload).abs() / run.preload)
        .fold(0.0, f64::max);
    let checks = vec![
        Check::at_least(
            "sigma_last_second_over_before",
            "σ over the last second / σ before tuning",
            last.std_force_n / before.std_force_n,
            10.0,
        ),
        Check::at_most(
            "normal_force_std_over_preload",
            "std of the normal force after tuning starts / preload",
            std_n / run.preload,
            0.05,
        ),
    ];
    let v = run.nominal;
    let figure = Figure {
        title: "fig4.10: slow tuning (eq. 4.22), amplitude, oscillation and normal force".into(),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "dither amplitude A (mm)".into(),
                series: vec![series(
                    "commanded",
                    decimate(&run.ticks, 100, |k| {
                        k.a_cmd / opts.base.servo.dither.omega() * 1e3
                    }),
                )],
            },
            Panel {
                x_label: None,
                y_label: "std of tangential force, 3 periods (N)".into(),
                series: vec![series(
                    "measured",
                    three.iter().map(|p| [p[0], p[2]]).collect(),
                )],
            },
            Panel {
                x_label: None,
                y_label: "normal force (N)".into(),
                series: vec![
                    series("true", decimate(&run.ticks, 10, |k| k.normal_true)),
                    series(
                        "preload",
                        vec![[0.0, run.preload], [run.duration, run.preload]],
                    ),
                ],
            },
        ],
    };
    Ok(Outcome {
        summary: Fig410Summary {
            nominal_velocity_m_per_s: v,
            preload_n: run.preload,
            a_omega_m_per_s: [0.2 * v, a_at(run.duration)],
            std_n: [before.std_force_n, last.std_force_n],
            std_amplitude_correlation: corr,
            normal_std_fraction: std_n / run.preload,
            normal_worst_fraction: worst,
        },
        checks,
        simulated_s: run.simulated,
        figure,
    })
}

fn explain(
    name: &str,
    r: &TunerReport,
    settled: f64,
    rate: f64,
    bound: f64,
    v: f64,
    cfg: &SimConfig,
) -> String {
    match name {
        "thesis" => {
            let stop = if r.at_upper_bound {
                format!(
                    "it stopped at the amplitude bound Aω = {:.1} mm/s",
                    bound * 1e3
                )
            } else {
                format!(
                    "it had not stopped: Aω = {:.1} mm/s and still rising at {:.1} mm/s per second; it stops only at the amplitude bound {:.1} mm/s",
                    settled * 1e3,
                    rate * 1e3,
                    bound * 1e3
                )
            };
            format!(
                "eq. 4.22 multiplies the instantaneous friction, whose mean stays positive while the tool moves, by (F_v/2 − F_s·Aω/(2ẋ̂_s²)), which is negative above the stationary point F_v·ẋ̂_s²/F_s = {:.3} mm/s (eq. 4.18 with ẋ̂_s = {:.1} mm/s re-estimated from the force variance, eq. 4.24). That point is a maximum of the approximated friction (eq. 4.21), not a minimum, and the law started above it, so Aω only grows; {stop}.",
                r.thesis_stationary_point_m_per_s * 1e3,
                r.stribeck_velocity_estimate_m_per_s * 1e3
            )
        }
        _ => {
            let lam = match cfg.servo.tuner {
                TunerConfig::Cost(p) => p.oscillation_weight,
                _ => f64::NAN,
            };
            if r.at_upper_bound || r.cost_minimiser_m_per_s >= r.transmission * bound * 0.999 {
                format!(
                    "J = F̄² + λσ² (λ = {lam}) still falls at the amplitude bound (dJ/da = {:.3e} N²·s/m there): it settles at the bound Aω = {:.1} mm/s",
                    r.cost_gradient_at_minimiser,
                    bound * 1e3
                )
            } else {
                format!(
                    "it settles at the interior minimum of J = F̄² + λσ² (λ = {lam}): a* = {:.1} mm/s at the contact ({:.1}·ẋ_o), commanded {:.1} mm/s with a measured transmission of {:.2}; there dJ/da = {:.1e} N²·s/m. Beyond a*, the oscillation the dither causes (friction reversal and the tool's inertial force m·ω·Aω) grows faster than the mean friction falls.",
                    r.cost_minimiser_m_per_s * 1e3,
                    r.cost_minimiser_m_per_s / v,
                    settled * 1e3,
                    r.transmission,
                    r.cost_gradient_at_minimiser
                )
            }
        }
    }
}
