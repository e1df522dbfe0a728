//! The thesis's friction experiments (§4.5.2) in the deterministic lockstep simulation.
//!
//! Each experiment returns an [`Outcome`]: a typed summary (the figures it measured), a
//! [`Figure`] (plot data; rendering is the CLI's job), and [`Check`]s stating the acceptance
//! criteria with measured value and limit. Everything is a pure function of the options.
//!
//! | name          | thesis            | what                                                          |
//! |---------------|-------------------|---------------------------------------------------------------|
//! | `friction-id` | eq. 4.23          | constant-velocity strokes, eq. 4.5 identified                  |
//! | `fig4.5`      | fig. 4.5          | the same traverse without and with a fixed dither              |
//! | `fig4.6`      | fig. 4.6          | μ from normal/tangential force trials                          |
//! | `fig4.7`      | fig. 4.7          | dither amplitude raised step-wise, oscillation per step        |
//! | `fig4.8`      | figs. 4.8–4.10    | on-line tuning from Aω = 0.2 ẋ_o, thesis tuner vs cost tuner   |
//! | `tangent`     | §5.3, eqs. 5.6–5.10, 6.1 | tangent estimate against α0, noise, friction, dither    |
//! | `fig5.3`      | fig. 5.3          | the preliminary correlation method vs the dither method        |
//! | `fig5.6`      | fig. 5.6          | tracking an unknown sinusoidal surface                         |
//! | `corners`     | §5.2, §7.2        | tracking a piecewise-linear surface through its corners        |
//! | `fig5.9`      | figs. 5.9, 5.10   | a box rotated into a corner about its estimated rotation centre |

mod friction;
mod multicontact;
mod tracking;

pub use friction::*;
pub use multicontact::*;
pub use tracking::*;

use crate::sim::{Lockstep, SimConfig};
use crate::tuner::TunerConfig;
use serde::Serialize;

/// Options common to all experiments.
#[derive(Debug, Clone)]
pub struct Options {
    /// Seed of the sensor noise and of the random surface roughness.
    pub seed: u64,
    /// The set-up the experiment starts from (its own settings are applied on top).
    pub base: SimConfig,
    /// `fig4.6` only: use the six trials printed in the thesis instead of simulating.
    pub thesis_table: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            seed: 1,
            base: SimConfig::default(),
            thesis_table: false,
        }
    }
}

/// The experiment names, in the order the README lists them.
pub const NAMES: [&str; 10] = [
    "friction-id",
    "fig4.5",
    "fig4.6",
    "fig4.7",
    "fig4.8",
    "tangent",
    "fig5.3",
    "fig5.6",
    "corners",
    "fig5.9",
];

/// One data series of a plot.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// (x, y) points.
    pub points: Vec<[f64; 2]>,
    /// Draw markers instead of a line.
    pub markers: bool,
}

/// One panel (shared x axis).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Panel {
    /// Y-axis label with unit.
    pub y_label: String,
    /// Data.
    pub series: Vec<Series>,
}

/// Plot data of an experiment.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figure {
    /// Title.
    pub title: String,
    /// X-axis label with unit.
    pub x_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Panels, top to bottom.
    pub panels: Vec<Panel>,
}

/// One acceptance criterion, measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    /// What is checked.
    pub name: String,
    /// Measured value.
    pub value: f64,
    /// Limit.
    pub limit: f64,
    /// `"<="` or `">="`.
    pub relation: &'static str,
    /// Whether it holds.
    pub pass: bool,
}

impl Check {
    pub(crate) fn at_most(name: impl Into<String>, value: f64, limit: f64) -> Self {
        Self {
            name: name.into(),
            value,
            limit,
            relation: "<=",
            pass: value <= limit,
        }
    }
    pub(crate) fn at_least(name: impl Into<String>, value: f64, limit: f64) -> Self {
        Self {
            name: name.into(),
            value,
            limit,
            relation: ">=",
            pass: value >= limit,
        }
    }
}

/// What an experiment produced.
#[derive(Debug, Clone, Serialize)]
pub struct Outcome<S> {
    /// The measured figures.
    pub summary: S,
    /// Acceptance criteria.
    pub checks: Vec<Check>,
    /// Simulated time (s).
    pub simulated_s: f64,
    /// Plot data.
    #[serde(skip)]
    pub figure: Figure,
}

impl<S> Outcome<S> {
    /// True when every check passes.
    pub fn passed(&self) -> bool {
        self.checks.iter().all(|c| c.pass)
    }
}

/// One recorded servo tick.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Tick {
    pub(crate) t: f64,
    /// Measured friction resisting the nominal motion (N).
    pub(crate) friction: f64,
    /// Measured normal force (N).
    pub(crate) normal: f64,
    /// True normal force (N).
    pub(crate) normal_true: f64,
    /// Friction scale truth: F_N/F_ref × roughness.
    pub(crate) scale: f64,
    /// Tip velocity along the estimated tangent, in the nominal direction (m/s).
    pub(crate) velocity: f64,
    pub(crate) phase: f64,
    pub(crate) period_end: bool,
    pub(crate) a_cmd: f64,
    pub(crate) contact: bool,
}

pub(crate) fn record(sim: &Lockstep, last_phase: &mut f64) -> Tick {
    let d = sim.servo().diag();
    let tr = sim.truth();
    let dir = if sim.servo().hybrid().velocity_target() < 0.0 {
        -1.0
    } else {
        1.0
    };
    let period_end = d.dither_phase < *last_phase;
    *last_phase = d.dither_phase;
    let f_ref = sim.plant().params().reference_normal_force_n;
    Tick {
        t: sim.time(),
        friction: -d.tangential_force_n * dir,
        normal: d.normal_force_n,
        normal_true: tr.normal_force_n,
        scale: tr.normal_force_n / f_ref * tr.roughness_factor,
        velocity: d.tangent_velocity_m_per_s * dir,
        phase: d.dither_phase,
        period_end,
        a_cmd: d.a_omega_m_per_s,
        contact: tr.contact_count > 0 && tr.normal_force_n > 0.0,
    }
}

/// Runs `sim` for `seconds`, recording every tick into `out`.
pub(crate) fn run_recording(
    sim: &mut Lockstep,
    seconds: f64,
    out: &mut Vec<Tick>,
    last_phase: &mut f64,
) {
    let n = (seconds / sim.dt()).round() as usize;
    for _ in 0..n {
        sim.step();
        out.push(record(sim, last_phase));
    }
}

/// Statistics over the whole dither periods inside [t0, t1).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct WindowSummary {
    /// Mean friction force resisting the motion (N), measured.
    pub mean_force_n: f64,
    /// Its standard deviation (N).
    pub std_force_n: f64,
    /// Mean tip velocity along the tangent (m/s): the ẋ_o the contact saw.
    pub velocity_seen_m_per_s: f64,
    /// Dither velocity amplitude at the tip (m/s, lock-in): the Aω the contact saw.
    pub a_omega_seen_m_per_s: f64,
    /// Mean commanded Aω (m/s).
    pub a_omega_commanded_m_per_s: f64,
    /// Mean measured normal force (N).
    pub mean_normal_n: f64,
    /// Mean of the true friction scale F_N/F_ref × roughness.
    pub friction_scale: f64,
    /// Peak-to-peak of the friction force (N).
    pub peak_to_peak_n: f64,
    /// Window start and end (s).
    pub window_s: [f64; 2],
}

pub(crate) fn window(ticks: &[Tick], t0: f64, t1: f64) -> WindowSummary {
    // Align to period boundaries: from the first period end ≥ t0 to the last ≤ t1.
    let start = ticks
        .iter()
        .position(|k| k.t >= t0 && k.period_end)
        .map(|i| i + 1)
        .unwrap_or(0);
    let end = ticks
        .iter()
        .rposition(|k| k.t <= t1 && k.period_end)
        .map(|i| i + 1)
        .unwrap_or(ticks.len());
    let w = if end > start {
        &ticks[start..end]
    } else {
        ticks
    };
    let n = w.len().max(1) as f64;
    let mean = w.iter().map(|k| k.friction).sum::<f64>() / n;
    let var = w.iter().map(|k| (k.friction - mean).powi(2)).sum::<f64>() / n;
    let v0 = w.iter().map(|k| k.velocity).sum::<f64>() / n;
    let i = 2.0 * w.iter().map(|k| k.velocity * k.phase.cos()).sum::<f64>() / n;
    let q = 2.0 * w.iter().map(|k| k.velocity * k.phase.sin()).sum::<f64>() / n;
    let (lo, hi) = w
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), k| {
            (a.min(k.friction), b.max(k.friction))
        });
    WindowSummary {
        mean_force_n: mean,
        std_force_n: var.sqrt(),
        velocity_seen_m_per_s: v0,
        a_omega_seen_m_per_s: (i * i + q * q).sqrt(),
        a_omega_commanded_m_per_s: w.iter().map(|k| k.a_cmd).sum::<f64>() / n,
        mean_normal_n: w.iter().map(|k| k.normal).sum::<f64>() / n,
        friction_scale: w.iter().map(|k| k.scale).sum::<f64>() / n,
        peak_to_peak_n: hi - lo,
        window_s: [
            w.first().map_or(0.0, |k| k.t),
            w.last().map_or(0.0, |k| k.t),
        ],
    }
}

/// Sliding statistics over `periods` whole periods, one point per period end: (t, mean, std).
pub(crate) fn sliding_periods(ticks: &[Tick], periods: usize) -> Vec<[f64; 3]> {
    let ends: Vec<usize> = ticks
        .iter()
        .enumerate()
        .filter(|(_, k)| k.period_end)
        .map(|(i, _)| i)
        .collect();
    let mut out = Vec::new();
    for w in ends.windows(periods + 1) {
        let s = &ticks[w[0] + 1..=w[periods]];
        let n = s.len() as f64;
        let m = s.iter().map(|k| k.friction).sum::<f64>() / n;
        let v = s.iter().map(|k| (k.friction - m).powi(2)).sum::<f64>() / n;
        out.push([ticks[w[periods]].t, m, v.sqrt()]);
    }
    out
}

pub(crate) fn decimate<F: Fn(&Tick) -> f64>(ticks: &[Tick], every: usize, f: F) -> Vec<[f64; 2]> {
    ticks
        .iter()
        .step_by(every.max(1))
        .map(|k| [k.t, f(k)])
        .collect()
}

pub(crate) fn series(label: &str, points: Vec<[f64; 2]>) -> Series {
    Series {
        label: label.into(),
        points,
        markers: false,
    }
}

pub(crate) fn markers(label: &str, points: Vec<[f64; 2]>) -> Series {
    Series {
        label: label.into(),
        points,
        markers: true,
    }
}

pub(crate) fn config(opts: &Options, tuner: TunerConfig) -> SimConfig {
    let mut cfg = opts.base.clone();
    cfg.seed = opts.seed;
    cfg.servo.tuner = tuner;
    cfg
}
