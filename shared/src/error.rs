//! The core's errors: a setting that cannot be used (and the surface and inverse-kinematics
//! errors it wraps), a scenario or fault kind that does not exist, a controller snapshot that
//! must not be restored, an experiment without a result. Each message says what to change.

use crate::friction::FrictionError;

/// A set-up that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    /// A setting outside the values it allows (`sensor.rate_hz = 5 must lie in [10, 100000]`).
    #[error("{setting} = {value} {rule}")]
    Setting {
        /// The setting, as a dotted path of the configuration.
        setting: String,
        /// Its value.
        value: f64,
        /// What it must be.
        rule: String,
    },
    /// Settings that do not fit together, or one that has no value to print.
    #[error("{setting} {rule}")]
    Rule {
        /// The setting(s).
        setting: String,
        /// What they must be.
        rule: String,
    },
    /// The surface.
    #[error(transparent)]
    Surface(#[from] SurfaceError),
    /// A friction law.
    #[error(transparent)]
    Friction(#[from] FrictionError),
    /// The start point is out of the arm's reach.
    #[error("start point: {0}")]
    StartPoint(#[from] IkError),
}

impl ConfigError {
    /// A setting outside its values.
    pub fn setting(setting: impl Into<String>, value: f64, rule: impl Into<String>) -> Self {
        ConfigError::Setting {
            setting: setting.into(),
            value,
            rule: rule.into(),
        }
    }

    /// Settings that do not fit together.
    pub fn rule(setting: impl Into<String>, rule: impl Into<String>) -> Self {
        ConfigError::Rule {
            setting: setting.into(),
            rule: rule.into(),
        }
    }
}

/// A name that is not one of the known ones (a scenario, a fault kind).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} '{name}' (one of: {})", known.join(", "))]
pub struct UnknownName {
    /// What kind of name.
    pub what: &'static str,
    /// The name given.
    pub name: String,
    /// The names there are.
    pub known: Vec<&'static str>,
}

/// Why a scenario cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScenarioError {
    /// No such scenario.
    #[error(transparent)]
    Unknown(#[from] UnknownName),
    /// Its set-up cannot be used.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A servo restart could not be replayed: the controller's snapshot was refused.
    #[error("servo restart at tick {tick}: {reason}")]
    Restart {
        /// The tick.
        tick: u64,
        /// Why.
        reason: SnapshotError,
    },
}

/// A controller snapshot that must not be restored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SnapshotError {
    /// A number in it is NaN or infinite.
    #[error("the controller snapshot holds a non-finite value")]
    NotFinite,
    /// A mode or trigger code it holds is unknown.
    #[error("the controller snapshot holds an unknown mode or trigger code")]
    UnknownCode,
}

/// Why an experiment could not produce its figures.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExperimentError {
    /// Its set-up cannot be used.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The simulated run did not give what the figure needs (an estimation that never
    /// finished, a fit with nothing to fit).
    #[error("{experiment}: {reason}")]
    NoResult {
        /// The experiment.
        experiment: &'static str,
        /// What was missing.
        reason: String,
    },
}

impl ExperimentError {
    /// `experiment` found no result: `reason`.
    pub fn no_result(experiment: &'static str, reason: impl ToString) -> Self {
        ExperimentError::NoResult {
            experiment,
            reason: reason.to_string(),
        }
    }
}

/// Why inverse kinematics has no answer.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum IkError {
    /// The point is outside the annulus the arm can reach.
    #[error(
        "point ({x:.4}, {y:.4}) m is out of reach (distance {r:.4} m not in [{min:.4}, {max:.4}])"
    )]
    OutOfReach {
        /// X (m).
        x: f64,
        /// Y (m).
        y: f64,
        /// Distance from the base (m).
        r: f64,
        /// Inner reach (m).
        min: f64,
        /// Outer reach (m).
        max: f64,
    },
    /// A coordinate is not finite.
    #[error("inverse kinematics was given a non-finite point")]
    NotFinite,
}

/// Why a surface description is rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SurfaceError {
    /// A number is NaN or infinite.
    #[error("surface parameter '{0}' is not a finite number")]
    NotFinite(&'static str),
    /// Sinusoid wavelength must be positive.
    #[error("sinusoid wavelength_m = {0} must be > 0")]
    BadWavelength(f64),
    /// Polyline needs at least two vertices with strictly increasing u.
    #[error("polyline needs ≥ 2 vertices with strictly increasing u (vertex {0} breaks this)")]
    BadPolyline(usize),
    /// Too many vertices for the allocation-free contact query.
    #[error("polyline has {count} vertices; at most {max} are supported")]
    TooManyVertices {
        /// Vertices given.
        count: usize,
        /// Most supported.
        max: usize,
    },
}
