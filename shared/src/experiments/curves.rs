//! The friction law's own figures (thesis §4.2–4.3, figs. 4.1–4.3): eq. 4.5's components, its
//! curve against velocity and the friction under a pure dither, each checked against an
//! independent evaluation (closed forms, quadrature). Fig. 4.4, measured in the lockstep
//! simulation, is in `nominal.rs`.

use super::*;
use crate::error::ExperimentError;
use crate::friction::{FrictionLaw, Presliding};
use serde::Serialize;

/// `n + 1` evenly spaced values from `lo` to `hi`.
pub(super) fn grid(lo: f64, hi: f64, n: usize) -> impl Iterator<Item = f64> {
    (0..=n).map(move |i| lo + (hi - lo) * i as f64 / n as f64)
}

fn sgn(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

// ---------------------------------------------------------------------------------------------
// fig4.1

/// Summary of `fig4.1`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig41Summary {
    /// The law plotted (eq. 4.5 at the reference normal force).
    pub law: FrictionLaw,
    /// eq. 4.1's k_fric: the presliding stiffness σ0 (N/m).
    pub static_stiffness_n_per_m: f64,
    /// Slope of the presliding force against displacement over the elastic zone, measured on
    /// the model driven at 0.1 mm/s (N/m).
    pub static_slope_n_per_m: f64,
    /// Presliding force at the end of the ramp, sliding (N).
    pub static_final_n: f64,
    /// eq. 4.5 at the ramp's velocity (N): where the static force must end.
    pub sliding_level_n: f64,
    /// Velocity where the Stribeck term's curvature changes sign, found on the sampled curve
    /// (m/s; NaN without a Stribeck term). The thesis calls ẋ_s the inflection point; it is the
    /// half-value point.
    pub stribeck_inflection_m_per_s: f64,
    /// The closed form of that inflection, ẋ_s/√3 (m/s).
    pub stribeck_inflection_closed_form_m_per_s: f64,
    /// Largest |kinetic + Stribeck + viscous − eq. 4.5 as implemented| over ±50 mm/s (N).
    pub sum_gap_n: f64,
}

/// The four components of eq. 4.5 (fig. 4.1): (a) static friction, eq. 4.1's spring, measured
/// on the presliding model driven slowly from rest; (b) kinetic, eq. 4.2; (c) Stribeck, eq.
/// 4.3, with its inflection; (d) viscous, eq. 4.4.
pub fn fig4_1(opts: &Options) -> Result<Outcome<Fig41Summary>, ExperimentError> {
    let law = opts.base.plant.friction;
    let pre = opts.base.plant.presliding;
    let sigma0 = pre.stiffness_n_per_m;
    // (a) A ramp at 0.1 mm/s from rest to three break-away deflections.
    let v_ramp = 1e-4;
    let dt = 1e-6;
    let z_break = law.breakaway() / sigma0;
    let steps = (3.0 * z_break / (v_ramp * dt)).ceil() as usize;
    let mut state = Presliding::default();
    let mut ramp = Vec::new();
    let mut f = 0.0;
    for i in 1..=steps {
        f = state.step(&law, &pre, v_ramp, dt);
        if i % 50 == 0 {
            ramp.push([v_ramp * dt * i as f64, f]);
        }
    }
    // Least-squares slope over the first 60 % of the elastic zone (z_ba = ratio · z_ss).
    let z_ba = pre.breakaway_ratio * law.sliding_level(v_ramp) / sigma0;
    let elastic: Vec<&[f64; 2]> = ramp
        .iter()
        .filter(|p| p[0] >= 0.1 * z_ba && p[0] <= 0.6 * z_ba)
        .collect();
    let n = elastic.len().max(1) as f64;
    let (mx, my) = (
        elastic.iter().map(|p| p[0]).sum::<f64>() / n,
        elastic.iter().map(|p| p[1]).sum::<f64>() / n,
    );
    let sxy: f64 = elastic.iter().map(|p| (p[0] - mx) * (p[1] - my)).sum();
    let sxx: f64 = elastic.iter().map(|p| (p[0] - mx).powi(2)).sum();
    let slope = if sxx > 0.0 { sxy / sxx } else { f64::NAN };
    let sliding = law.resistance(v_ramp);
    // (c) The Stribeck term's inflection from second differences of the sampled curve.
    let vs = law.stribeck_velocity_m_per_s;
    let h = vs / 2000.0;
    let stribeck = |v: f64| law.sliding_level(v.abs()) - law.kinetic_n;
    let curvature = |v: f64| stribeck(v + h) - 2.0 * stribeck(v) + stribeck(v - h);
    let mut inflection = f64::NAN;
    let mut prev = (h, curvature(h));
    for v in grid(2.0 * h, 3.0 * vs, 6000) {
        let c = curvature(v);
        if prev.1 < 0.0 && c >= 0.0 {
            inflection = prev.0 + (v - prev.0) * prev.1 / (prev.1 - c);
            break;
        }
        prev = (v, c);
    }
    let closed = vs / 3f64.sqrt();
    // (b)-(d) and their sum against the implemented law.
    let velocities: Vec<f64> = grid(-0.05, 0.05, 2000).collect();
    let kinetic = |v: f64| law.kinetic_n * sgn(v);
    let stribeck_signed = |v: f64| law.stribeck_n * sgn(v) / (1.0 + (v / vs).powi(2));
    let viscous = |v: f64| law.viscous_n_s_per_m * v;
    let sum_gap = velocities
        .iter()
        .map(|&v| (kinetic(v) + stribeck_signed(v) + viscous(v) - law.resistance(v)).abs())
        .fold(0.0, f64::max);
    let curve = |g: &dyn Fn(f64) -> f64| -> Vec<[f64; 2]> {
        velocities.iter().map(|&v| [v * 1e3, g(v)]).collect()
    };
    let mut checks = vec![
        Check::at_most(
            "static_slope_error",
            "|static slope / k_fric − 1| (eq. 4.1)",
            (slope / sigma0 - 1.0).abs(),
            0.01,
        ),
        Check::at_most(
            "static_force_error",
            "|static force at the end / eq. 4.5 − 1|",
            (f / sliding - 1.0).abs(),
            0.01,
        ),
        Check::at_most(
            "components_sum_error_n",
            "components' sum − eq. 4.5 (N)",
            sum_gap,
            1e-12,
        ),
    ];
    // Without a Stribeck term (F_s = 0) there is no curve to have an inflection.
    if law.stribeck_n > 0.0 {
        checks.insert(
            2,
            Check::at_most(
                "stribeck_inflection_error",
                "|Stribeck inflection / (ẋ_s/√3) − 1|",
                (inflection / closed - 1.0).abs(),
                0.005,
            ),
        );
    }
    let figure = Figure {
        title: "fig4.1: the components of eq. 4.5 (static, kinetic, Stribeck, viscous)".into(),
        x_label: "relative velocity ẋ (mm/s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: Some("displacement from rest Δx (µm), driven at 0.1 mm/s".into()),
                y_label: "(a) static (N)".into(),
                series: vec![
                    series(
                        "presliding model",
                        ramp.iter().map(|p| [p[0] * 1e6, p[1]]).collect(),
                    ),
                    series(
                        "eq. 4.1: k_fric Δx",
                        ramp.iter()
                            .filter(|p| sigma0 * p[0] <= law.breakaway())
                            .map(|p| [p[0] * 1e6, sigma0 * p[0]])
                            .collect(),
                    ),
                ],
            },
            Panel {
                x_label: None,
                y_label: "(b) kinetic F_t sgn ẋ (N)".into(),
                series: vec![series("eq. 4.2", curve(&kinetic))],
            },
            Panel {
                x_label: None,
                y_label: "(c) Stribeck (N)".into(),
                series: vec![
                    series("eq. 4.3", curve(&stribeck_signed)),
                    markers(
                        "inflection ±ẋ_s/√3",
                        vec![
                            [closed * 1e3, stribeck_signed(closed)],
                            [-closed * 1e3, stribeck_signed(-closed)],
                        ],
                    ),
                ],
            },
            Panel {
                x_label: None,
                y_label: "(d) viscous F_v ẋ (N)".into(),
                series: vec![series("eq. 4.4", curve(&viscous))],
            },
        ],
    };
    Ok(Outcome {
        summary: Fig41Summary {
            law,
            static_stiffness_n_per_m: sigma0,
            static_slope_n_per_m: slope,
            static_final_n: f,
            sliding_level_n: sliding,
            stribeck_inflection_m_per_s: inflection,
            stribeck_inflection_closed_form_m_per_s: closed,
            sum_gap_n: sum_gap,
        },
        checks,
        simulated_s: steps as f64 * dt,
        figure,
    })
}

// ---------------------------------------------------------------------------------------------
// fig4.2

/// Summary of `fig4.2`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig42Summary {
    /// The law plotted.
    pub law: FrictionLaw,
    /// Force to start sliding, F_t + F_s (N).
    pub breakaway_n: f64,
    /// Velocity of the curve's minimum from the closed-form condition
    /// `F_v (1 + u²)² = 2 F_s u / ẋ_s`, u = ẋ/ẋ_s, its larger root (m/s); none if F_v = 0.
    pub minimum_velocity_m_per_s: Option<f64>,
    /// eq. 4.5 there (N).
    pub minimum_force_n: Option<f64>,
    /// The minimum found on the curve sampled every 0.01 mm/s (m/s).
    pub sampled_minimum_velocity_m_per_s: f64,
}

/// The larger root u of `F_v ẋ_s (1 + u²)² = 2 F_s u`: where eq. 4.5's slope turns from
/// negative (Stribeck) to positive (viscous). None without viscous friction.
pub fn friction_minimum(law: &FrictionLaw) -> Option<f64> {
    let (fv, fs, vs) = (
        law.viscous_n_s_per_m,
        law.stribeck_n,
        law.stribeck_velocity_m_per_s,
    );
    if fv <= 0.0 || fs <= 0.0 {
        return None;
    }
    let h = |u: f64| fv * vs * (1.0 + u * u).powi(2) - 2.0 * fs * u;
    // 2 F_s u / (1 + u²)² peaks at u = 1/√3; beyond it h rises monotonically.
    let mut lo = 1.0 / 3f64.sqrt();
    if h(lo) >= 0.0 {
        return None; // the Stribeck dip never beats the viscous slope: monotone curve
    }
    let mut hi = 2.0 * lo;
    while h(hi) < 0.0 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if h(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi) * vs)
}

/// eq. 4.5 against velocity (fig. 4.2), with its minimum from the closed-form condition.
pub fn fig4_2(opts: &Options) -> Result<Outcome<Fig42Summary>, ExperimentError> {
    let law = opts.base.plant.friction;
    let v_min = friction_minimum(&law);
    let top = v_min.map_or(0.2, |v| (2.5 * v).max(0.05));
    let n = (top / 1e-5).round() as usize;
    let (mut best_v, mut best_f) = (f64::NAN, f64::INFINITY);
    for v in grid(1e-5, top, n) {
        let f = law.resistance(v);
        if f < best_f {
            (best_v, best_f) = (v, f);
        }
    }
    let mut checks = Vec::new();
    if let Some(v) = v_min {
        checks.push(Check::at_most(
            "minimum_error",
            "|sampled minimum / closed-form minimum − 1|",
            (best_v / v - 1.0).abs(),
            0.005,
        ));
    }
    checks.push(Check::at_most(
        "breakaway_force_error_n",
        "|eq. 4.5 at 0+ − (F_t + F_s)| (N)",
        (law.resistance(1e-12) - law.breakaway()).abs(),
        1e-9,
    ));
    let curve: Vec<[f64; 2]> = grid(-top, top, 4000)
        .map(|v| [v * 1e3, law.resistance(v)])
        .collect();
    let low = 5.0 * law.stribeck_velocity_m_per_s;
    let mut mins = Vec::new();
    if let Some(v) = v_min {
        mins.push([v * 1e3, law.resistance(v)]);
        mins.push([-v * 1e3, law.resistance(-v)]);
    }
    let figure = Figure {
        title: "fig4.2: eq. 4.5, friction against velocity (eq. 4.23's coefficients)".into(),
        x_label: "relative velocity ẋ (mm/s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "friction F_f (N)".into(),
                series: vec![
                    series("eq. 4.5", curve),
                    markers("minimum (closed form)", mins.clone()),
                ],
            },
            Panel {
                x_label: Some("relative velocity ẋ (mm/s), low speeds".into()),
                y_label: "friction F_f (N)".into(),
                series: vec![series(
                    "eq. 4.5",
                    grid(0.0, low, 1000)
                        .map(|v| [v * 1e3, law.resistance(v)])
                        .collect(),
                )],
            },
        ],
    };
    Ok(Outcome {
        summary: Fig42Summary {
            law,
            breakaway_n: law.breakaway(),
            minimum_velocity_m_per_s: v_min,
            minimum_force_n: v_min.map(|v| law.resistance(v)),
            sampled_minimum_velocity_m_per_s: best_v,
        },
        checks,
        simulated_s: 0.0,
        figure,
    })
}

// ---------------------------------------------------------------------------------------------
// fig4.3

/// One dither level of `fig4.3`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct PureDither {
    /// Dither velocity amplitude Aω (m/s).
    pub a_omega_m_per_s: f64,
    /// Cycle mean of eq. 4.8 by quadrature (N); eq. 4.9 says 0.
    pub mean_n: f64,
    /// Standard deviation over the cycle, closed form (N).
    pub std_n: f64,
    /// The same by quadrature (N).
    pub std_quadrature_n: f64,
    /// Peak-to-peak over the cycle (N).
    pub peak_to_peak_n: f64,
}

/// Summary of `fig4.3`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig43Summary {
    /// Dither frequency (Hz).
    pub frequency_hz: f64,
    /// Per Aω.
    pub levels: Vec<PureDither>,
    /// σ at the largest Aω / σ at the smallest; the thesis says the oscillation is proportional
    /// to Aω, which would make this the ratio of the Aω's.
    pub std_growth: f64,
    /// Largest Aω / smallest.
    pub a_omega_ratio: f64,
}

/// eq. 4.8: the friction under a pure dither `ẋ = Aω cos ωt` (fig. 4.3), its zero mean (eq.
/// 4.9) and how its oscillation changes with Aω.
pub fn fig4_3(opts: &Options) -> Result<Outcome<Fig43Summary>, ExperimentError> {
    let law = opts.base.plant.friction;
    let hz = opts.base.servo.dither.frequency_hz;
    let omega = 2.0 * std::f64::consts::PI * hz;
    let levels_mm = [2.5, 5.0, 10.0, 20.0, 40.0, 80.0];
    let mut levels = Vec::new();
    let mut checks = Vec::new();
    let (mut worst_mean, mut worst_gap) = (0.0f64, 0.0f64);
    for a_mm in levels_mm {
        let a = a_mm * 1e-3;
        let (mean, ms) = law.cycle_by_quadrature(0.0, a);
        let closed = law.cycle(0.0, a);
        let std_q = (ms - mean * mean).max(0.0).sqrt();
        let (lo, hi) = grid(0.0, 2.0 * std::f64::consts::PI, 20_000)
            .map(|th| law.resistance(a * th.cos()))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), f| {
                (l.min(f), h.max(f))
            });
        worst_mean = worst_mean.max(mean.abs());
        worst_gap = worst_gap.max((closed.std() - std_q).abs() / std_q);
        levels.push(PureDither {
            a_omega_m_per_s: a,
            mean_n: mean,
            std_n: closed.std(),
            std_quadrature_n: std_q,
            peak_to_peak_n: hi - lo,
        });
    }
    checks.push(Check::at_most(
        "cycle_mean_quadrature_max_n",
        "largest |cycle mean| by quadrature (N), eq. 4.9",
        worst_mean,
        1e-9,
    ));
    checks.push(Check::at_most(
        "sigma_closed_form_error_max",
        "largest |σ closed form − σ quadrature| / σ",
        worst_gap,
        1e-6,
    ));
    let time_history = |a: f64| -> Vec<[f64; 2]> {
        grid(0.0, 2.0 / hz, 2000)
            .map(|t| [t, law.resistance(a * (omega * t).cos())])
            .collect()
    };
    let first = levels[0];
    let last = levels[levels.len() - 1];
    let figure = Figure {
        title: format!("fig4.3: friction under a pure dither ẋ = Aω cos ωt ({hz} Hz)"),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "F_f (N), Aω = 5 and 20 mm/s".into(),
                series: vec![
                    series("Aω = 5 mm/s", time_history(0.005)),
                    series("Aω = 20 mm/s", time_history(0.020)),
                ],
            },
            Panel {
                x_label: Some("dither velocity amplitude Aω (mm/s)".into()),
                y_label: "std of F_f over the cycle (N)".into(),
                series: vec![
                    series(
                        "closed form",
                        grid(1.0, 80.0, 400)
                            .map(|a| [a, law.cycle(0.0, a * 1e-3).std()])
                            .collect(),
                    ),
                    markers(
                        "quadrature",
                        levels
                            .iter()
                            .map(|l| [l.a_omega_m_per_s * 1e3, l.std_quadrature_n])
                            .collect(),
                    ),
                    series(
                        "proportional to Aω (the thesis's statement)",
                        grid(first.a_omega_m_per_s, 4.0 * first.a_omega_m_per_s, 20)
                            .map(|a| [a * 1e3, first.std_n * a / first.a_omega_m_per_s])
                            .collect(),
                    ),
                ],
            },
        ],
    };
    Ok(Outcome {
        summary: Fig43Summary {
            frequency_hz: hz,
            std_growth: last.std_n / first.std_n,
            a_omega_ratio: last.a_omega_m_per_s / first.a_omega_m_per_s,
            levels,
        },
        checks,
        simulated_s: 0.0,
        figure,
    })
}
