//! The thesis's friction experiments (§4.5.2) in the deterministic lockstep simulation.
//!
//! Each experiment returns an [`Outcome`]: a typed summary (the figures it measured), a
//! [`Figure`] (plot data; rendering is the CLI's job), and [`Check`]s stating the acceptance
//! criteria with measured value and limit. Everything is a pure function of the options.
//!
//! | name          | thesis            | what                                                          |
//! |---------------|-------------------|---------------------------------------------------------------|
//! | `friction-id` | eq. 4.23          | constant-velocity strokes, eq. 4.5 identified                  |
//! | `fig4.1`      | fig. 4.1          | eq. 4.5's components: static, kinetic, Stribeck, viscous       |
//! | `fig4.2`      | fig. 4.2          | eq. 4.5 against velocity and its minimum                       |
//! | `fig4.3`      | fig. 4.3, eq. 4.9 | friction under a pure dither, zero mean                        |
//! | `fig4.4`      | fig. 4.4, eq. 4.11| mean friction against nominal velocity under a dither          |
//! | `fig4.5`      | fig. 4.5          | the same traverse without and with a fixed dither              |
//! | `fig4.6`      | fig. 4.6          | μ from normal/tangential force trials                          |
//! | `fig4.7`      | fig. 4.7          | dither amplitude raised step-wise, oscillation per step        |
//! | `fig4.8`      | fig. 4.8          | on-line tuning from Aω = 0.2 ẋ_o, thesis tuner vs cost tuner   |
//! | `fig4.9`      | fig. 4.9          | slow tuning: the mean friction as Aω passes ẋ_o                |
//! | `fig4.10`     | fig. 4.10         | slow tuning: amplitude, oscillation and normal force           |
//! | `tangent`     | §5.3, eqs. 5.6–5.10, 6.1 | tangent estimate against α0, noise, friction, dither    |
//! | `rls`         | eq. 5.10          | a turning surface followed on the batch vs the recursive estimate |
//! | `fig5.3`      | fig. 5.3          | the preliminary correlation method vs the dither method        |
//! | `fig5.6`      | fig. 5.6          | tracking an unknown sinusoidal surface                         |
//! | `corners`     | §5.2, §7.2        | tracking a piecewise-linear surface through its corners        |
//! | `fig5.9`      | figs. 5.9, 5.10   | a box rotated into a corner about its estimated rotation centre |

mod curves;
mod friction;
mod multicontact;
mod recursive;
mod tracking;

pub use curves::*;
pub use friction::*;
pub use multicontact::*;
pub use recursive::*;
pub use tracking::*;

pub use crate::check::Check;
use crate::sim::SimConfig;
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
    /// The rig `base` was set up as (already applied to `base`; kept for reports).
    pub rig: crate::setups::Rig,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            seed: 1,
            base: SimConfig::default(),
            thesis_table: false,
            rig: crate::setups::Rig::Afs,
        }
    }
}

/// The experiment names, in the order the README lists them.
pub const NAMES: [&str; 17] = [
    "friction-id",
    "fig4.1",
    "fig4.2",
    "fig4.3",
    "fig4.4",
    "fig4.5",
    "fig4.6",
    "fig4.7",
    "fig4.8",
    "fig4.9",
    "fig4.10",
    "tangent",
    "rls",
    "fig5.3",
    "fig5.6",
    "corners",
    "fig5.9",
];

/// The experiments of the thesis's chapter 4 (friction), which `--rig thesis` applies to.
pub const FRICTION_NAMES: [&str; 11] = [
    "friction-id",
    "fig4.1",
    "fig4.2",
    "fig4.3",
    "fig4.4",
    "fig4.5",
    "fig4.6",
    "fig4.7",
    "fig4.8",
    "fig4.9",
    "fig4.10",
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
    /// This panel's own x-axis label where its x is not the figure's (None: the figure's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub x_label: Option<String>,
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
        crate::check::all_pass(&self.checks)
    }
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
