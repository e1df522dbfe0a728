//! The thesis's friction experiments (§4.5.2) in the deterministic lockstep simulation.
//!
//! Each experiment returns an [`Outcome`]: a typed summary (the figures it measured), a
//! [`Figure`] (plot data; rendering is the CLI's job), and [`Check`]s stating the acceptance
//! criteria with measured value and limit. Everything is a pure function of the options.
//!
//! Every experiment is one entry of [`REGISTRY`] (name, thesis section, what it does,
//! whether the thesis's rig is defined for it, the function): the CLI's names, `--rig
//! thesis` and the docs' table (`afs experiment list`, docs/experiments.md) all read it.

mod corners;
mod curves;
mod identification;
mod insertion;
mod multicontact;
mod nominal;
mod recursive;
mod suppression;
mod touch;
#[cfg(test)]
mod trace_tests;
mod tracking;
mod tuning;

pub use corners::*;
pub use curves::*;
pub use identification::*;
pub use insertion::*;
pub use multicontact::*;
pub use nominal::*;
pub use recursive::*;
pub use suppression::*;
pub use touch::*;
pub use tracking::*;
pub use tuning::*;

pub use crate::check::Check;
use crate::config::SimConfig;
use crate::error::ExperimentError;
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
    /// `insertion` only: the fit, the initial errors and the controller.
    pub insertion: InsertionOptions,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            seed: 1,
            base: SimConfig::default(),
            thesis_table: false,
            rig: crate::setups::Rig::Afs,
            insertion: InsertionOptions::default(),
        }
    }
}

/// One experiment of the [`REGISTRY`].
#[derive(Debug, Clone, Copy)]
pub struct Experiment {
    /// Its name on the command line (`fig4.8`).
    pub name: &'static str,
    /// Where the thesis has it (`fig. 4.8`, `eq. 4.23`, `§5.3`).
    pub thesis: &'static str,
    /// What it does, in a line.
    pub what: &'static str,
    /// A friction experiment (ch. 4), for which the thesis's rig is defined (`--rig thesis`).
    pub friction: bool,
    /// Runs it.
    pub run: fn(&Options) -> Result<Run, ExperimentError>,
}

/// An experiment's [`Outcome`] with its summary as JSON: what the registry's entries return.
#[derive(Debug, Clone)]
pub struct Run {
    /// The measured figures (the experiment's own shape).
    pub summary: serde_json::Value,
    /// Acceptance criteria.
    pub checks: Vec<Check>,
    /// Simulated time (s).
    pub simulated_s: f64,
    /// Plot data.
    pub figure: Figure,
}

impl<S: Serialize> From<Outcome<S>> for Run {
    fn from(o: Outcome<S>) -> Self {
        Self {
            // A summary is plain data: numbers, strings, vectors of them.
            summary: serde_json::to_value(&o.summary).unwrap_or_default(),
            checks: o.checks,
            simulated_s: o.simulated_s,
            figure: o.figure,
        }
    }
}

macro_rules! registry {
    ($($name:literal, $thesis:literal, $friction:literal, $f:path, $what:literal;)*) => {
        /// Every experiment, in the order `afs experiment all` runs them.
        pub const REGISTRY: &[Experiment] = &[$(Experiment {
            name: $name,
            thesis: $thesis,
            what: $what,
            friction: $friction,
            run: |o| $f(o).map(Run::from),
        }),*];
    };
}

registry! {
    "friction-id", "eq. 4.23", true, friction_id, "constant-velocity strokes, eq. 4.5 identified";
    "fig4.1", "fig. 4.1", true, fig4_1, "eq. 4.5's components: static, kinetic, Stribeck, viscous";
    "fig4.2", "fig. 4.2", true, fig4_2, "eq. 4.5 against velocity and its minimum";
    "fig4.3", "fig. 4.3, eq. 4.9", true, fig4_3, "friction under a pure dither, zero mean";
    "fig4.4", "fig. 4.4, eq. 4.11", true, fig4_4, "mean friction against nominal velocity under a dither";
    "fig4.5", "fig. 4.5", true, fig4_5, "the same traverse without and with a fixed dither";
    "fig4.6", "fig. 4.6", true, fig4_6, "μ from normal/tangential force trials";
    "fig4.7", "fig. 4.7", true, fig4_7, "dither amplitude raised step-wise, oscillation per step";
    "fig4.8", "fig. 4.8", true, fig4_8, "on-line tuning from Aω = 0.2 ẋ_o, thesis tuner vs cost tuner";
    "fig4.9", "fig. 4.9", true, fig4_9, "slow tuning: the mean friction as Aω passes ẋ_o";
    "fig4.10", "fig. 4.10", true, fig4_10, "slow tuning: amplitude, oscillation and normal force";
    "tangent", "§5.3, eqs. 5.6–5.10, 6.1", false, tangent, "tangent estimate against α0, noise, friction, dither";
    "rls", "eq. 5.10", false, rls, "a turning surface followed on the batch vs the recursive estimate";
    "fig5.3", "fig. 5.3", false, fig5_3, "the preliminary correlation method vs the dither method";
    "fig5.6", "fig. 5.6", false, fig5_6, "tracking an unknown sinusoidal surface";
    "corners", "§5.2, §7.2", false, corners, "tracking a piecewise-linear surface through its corners";
    "touch", "§3.3 (first contact)", false, touch, "from off the surface: the guarded approach, the impact and the preload settled";
    "fig5.9", "figs. 5.9, 5.10", false, fig5_9, "a box rotated into a corner about its estimated rotation centre";
    "insertion", "§5.4 (later study)", false, insertion, "a peg into a hole from initial errors: dither, no-dither or search";
}

/// Experiments that simulate no world (eq. 4.5's curves): they run the same on either, so
/// `--plant mujoco` is refused for them.
pub const WORLD_FREE: &[&str] = &["fig4.1", "fig4.2", "fig4.3", "fig4.4"];

/// The experiment named `name`.
pub fn find(name: &str) -> Option<&'static Experiment> {
    REGISTRY.iter().find(|e| e.name == name)
}

/// The registry as the Markdown table docs/experiments.md shows (`afs experiment list`).
pub fn registry_table() -> String {
    let mut s = String::from("| name | thesis | what | `--rig thesis` |\n|---|---|---|---|\n");
    for e in REGISTRY {
        s += &format!(
            "| `{}` | {} | {} | {} |\n",
            e.name,
            e.thesis,
            e.what,
            if e.friction { "yes" } else { "" }
        );
    }
    s
}

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

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/experiments.md shows the registry's table as `afs experiment list` prints it, and
    /// every name is there once.
    #[test]
    fn the_docs_table_is_the_registry() {
        let doc = include_str!("../../../docs/experiments.md");
        assert!(
            doc.contains(&registry_table()),
            "docs/experiments.md is out of date; run `afs experiment list`:\n{}",
            registry_table()
        );
        for (i, e) in REGISTRY.iter().enumerate() {
            assert!(REGISTRY[..i].iter().all(|f| f.name != e.name), "{}", e.name);
            assert!(find(e.name).is_some_and(|f| f.thesis == e.thesis));
        }
        assert!(find("fig4.99").is_none());
    }
}
