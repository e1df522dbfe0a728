//! The servo's settings: the loop, the hybrid controller, the dither and its tuner, the
//! tangent probes, when to estimate on its own, and the safe state (all from the stack's
//! `[sim.servo]`, checked by [`ServoParams::validate`]).

use crate::dither::DitherParams;
use crate::error::ConfigError;
use crate::friction::FrictionLaw;
use crate::hybrid::HybridParams;
use crate::tangent::TangentParams;
use crate::tuner::TunerConfig;
use serde::{Deserialize, Serialize};

/// The force loop during a tangent probe's strokes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProbeForceLoop {
    /// Frozen on soft contacts, on where the contact's normal mode is above ω_d/√2.
    #[default]
    Auto,
    /// Frozen: the set-point holds still along the normal, as in the thesis (§5.3.2).
    Frozen,
    /// On: the force loop keeps the preload while the strokes run.
    On,
}

/// Settings of the servo board.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServoParams {
    /// Servo rate (Hz); thesis-style default 10 kHz.
    pub rate_hz: f64,
    /// Closed-loop joint bandwidths (Hz); thesis §4.5.1: ≈3 Hz and ≈15 Hz.
    pub joint_bandwidth_hz: [f64; 2],
    /// Damping ratio of the joint PD part.
    pub joint_damping_ratio: f64,
    /// Integral corner of the joint PIDs as a fraction of their natural frequency.
    pub joint_integral_ratio: f64,
    /// Hybrid controller.
    pub hybrid: HybridParams,
    /// Dither.
    pub dither: DitherParams,
    /// Dither tuner.
    pub tuner: TunerConfig,
    /// Friction model the tuner uses (identified beforehand, eq. 4.23).
    pub friction_model: FrictionLaw,
    /// Normal force at which `friction_model` holds (N).
    pub friction_model_reference_n: f64,
    /// Tool mass beyond the sensor (kg), for the tuner's oscillation model.
    pub tool_mass_kg: f64,
    /// Add the arm's inverse dynamics of the commanded motion, `M(q_d) q̈_d + h(q_d, q̇_d)`,
    /// to the PID torques. Without it the dither's joint-2 acceleration couples into joint 1
    /// through M12 away from the decoupled point and shakes the normal force.
    pub inertia_feedforward: bool,
    /// Add the joint torques that transmit the preload along the estimated normal,
    /// `−J(q)ᵀ F_d n̂`, recomputed every tick. Without it the joint integrators hold the preload
    /// as a fixed torque, and the force it transmits changes with the configuration as the tool
    /// moves (0.25 % per mm here), which tilts the tangent estimate by about 0.35°.
    pub preload_feedforward: bool,
    /// Damping ratio ζ_c the servo gives the contact's normal mode (the arm's effective mass on
    /// the contact's stiffness in parallel with the servo's), by adding damping along the
    /// normal where its own falls short (docs/contact.md). 0: none added.
    pub contact_damping_ratio: f64,
    /// Adopt the contact stiffness fitted on line when it is tight and more than a factor of 2
    /// from the one in use, and re-derive the gains that depend on it (docs/contact.md).
    pub contact_adaptation: bool,
    /// The force loop during a probe's strokes (docs/contact.md, *The force loop during the
    /// probes*): frozen as in the thesis, kept on, or `auto`: kept on where the contact's
    /// normal mode sits above ω_d/√2 (the mode would amplify the dither's normal error).
    pub probe_force_loop: ProbeForceLoop,
    /// Tangent-estimation probes (thesis §5.3).
    pub tangent: TangentParams,
    /// When to start a tangent estimation on its own (thesis §5.3.2).
    pub tracking: TrackingParams,
    /// What to do while the force data cannot be trusted.
    pub safe: SafeParams,
    /// The guarded approach, when the servo starts off the surface.
    pub approach: ApproachParams,
}

/// The guarded approach (docs/contact.md, *First touch*): a servo that starts with a normal
/// force below `touch_fraction` of the preload is off the surface. Its force loop then moves
/// the normal set-point at no more than the speed whose impact on the stiffest contact expected
/// is the preload, `v_a = F_d / √(k_max m_n)` (m_n the arm's effective mass along the normal),
/// with the tangential motion held; at the touch it settles the preload, then moves on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ApproachParams {
    /// The stiffest contact the tool may meet, k_max (N/m): the contact in series with the
    /// sensor, as the arm sees it.
    pub stiffest_contact_n_per_m: f64,
    /// The normal force, as a fraction of the preload, that ends the approach.
    pub touch_fraction: f64,
}

impl Default for ApproachParams {
    fn default() -> Self {
        Self {
            stiffest_contact_n_per_m: 1e6,
            touch_fraction: 0.5,
        }
    }
}

impl ApproachParams {
    /// Checks the settings; the message names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let k = self.stiffest_contact_n_per_m;
        if !(k.is_finite() && (1.0..=1e9).contains(&k)) {
            return Err(ConfigError::setting(
                "servo.approach.stiffest_contact_n_per_m",
                k,
                "must lie in [1, 1e9] N/m",
            ));
        }
        let f = self.touch_fraction;
        if !(f.is_finite() && f > 0.0 && f < 1.0) {
            return Err(ConfigError::setting(
                "servo.approach.touch_fraction",
                f,
                "must lie in (0, 1)",
            ));
        }
        Ok(())
    }

    /// The approach speed `F_d / √(k_max m_n)` (m/s) for the preload `preload_n` (N) and the
    /// arm's effective mass along the normal `normal_mass_kg` (kg).
    pub fn speed(&self, preload_n: f64, normal_mass_kg: f64) -> f64 {
        preload_n / (self.stiffest_contact_n_per_m * normal_mass_kg).sqrt()
    }
}

/// The safe state, entered whenever the force data cannot be trusted (stale, missing or
/// insane): the tangential velocity ramps to zero at the controller's acceleration limit, the
/// dither decays to nothing within a few tens of milliseconds, the force loop freezes and the normal set-point backs off by a fraction of the
/// preload's penetration, so the normal force can only fall below the preload, never rise.
/// Once fresh data has been good for `recovery_s` the force loop restores the preload, and
/// motion and dither resume when the force has settled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafeParams {
    /// Back-off along the normal, as a fraction of the preload penetration F_d/k̂.
    pub backoff_fraction: f64,
    /// Time over which the back-off is applied (s).
    pub backoff_s: f64,
    /// Time constant of the dither's decay (s).
    pub dither_decay_s: f64,
    /// Good data needed before leaving the safe state (s).
    pub recovery_s: f64,
}

impl Default for SafeParams {
    fn default() -> Self {
        Self {
            backoff_fraction: 0.3,
            backoff_s: 0.01,
            dither_decay_s: 0.02,
            recovery_s: 0.02,
        }
    }
}

impl SafeParams {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.backoff_fraction.is_finite() && (0.0..=1.0).contains(&self.backoff_fraction)) {
            return Err(ConfigError::setting(
                "servo.safe.backoff_fraction",
                self.backoff_fraction,
                "must lie in [0, 1]",
            ));
        }
        for (n, v) in [
            ("backoff_s", self.backoff_s),
            ("dither_decay_s", self.dither_decay_s),
            ("recovery_s", self.recovery_s),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 10.0) {
                return Err(ConfigError::setting(
                    format!("servo.safe.{n}"),
                    v,
                    "must lie in (0, 10] s",
                ));
            }
        }
        Ok(())
    }
}

/// Where the drift trigger reads the tangent error from (docs/contact.md, *The drift on a
/// stiff contact*).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DriftSource {
    /// The tip on a stiff contact (the same criterion as `probe_force_loop`'s), the set-point
    /// otherwise.
    #[default]
    Auto,
    /// The force loop's normal set-point rate, `ω_f (F_d − F̄_N)/k̂`: it sees the surface through
    /// the servo's compliance.
    Setpoint,
    /// The tip's measured velocity along the estimated normal: it sees the surface through the
    /// contact's compliance.
    Tip,
}

/// Limits on the force feedback that start a tangent estimation (thesis §5.3.2: "a sudden
/// change in force level ... could signal loss of contact or attempts to push into the
/// environment"), plus the drift of the force loop's normal set-point per unit of travel,
/// which is the tangent error the force loop is absorbing.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackingParams {
    /// Trigger estimations automatically.
    pub enabled: bool,
    /// Trigger when the normal force, averaged over one period of the friction-suppression
    /// dither (which removes the dither's own ripple), leaves the preload by this fraction.
    pub force_trigger_fraction: f64,
    /// Further first-order smoothing of that average (s).
    pub force_filter_s: f64,
    /// Trigger when the normal set-point drifts by this angle against the travel (deg): the
    /// force loop's set-point rate over the nominal speed, low-passed over `slope_window_m`, is
    /// the tangent error it is absorbing.
    pub slope_trigger_deg: f64,
    /// Travel over which the drift is averaged (m).
    pub slope_window_m: f64,
    /// What the drift is read from: the set-point's normal rate or the tip's normal velocity
    /// over the travel, or `auto` (the tip on a stiff contact).
    pub drift_source: DriftSource,
    /// Travel after an estimate before the drift and travel triggers re-arm (m).
    pub min_travel_m: f64,
    /// Estimate at least every this much travel (m); 0 disables.
    pub max_travel_m: f64,
    /// Turn the tangent between estimates at the curvature the last two estimates imply.
    pub curvature_feedforward: bool,
    /// Largest curvature fed forward (1/m). Two estimates implying more are taken to straddle a
    /// corner, not a curve, and no curvature is fed forward.
    pub max_curvature_per_m: f64,
    /// A change of tangent larger than this between two estimates is a corner whatever the
    /// distance (deg).
    pub corner_angle_deg: f64,
    /// The contact guard (while tracking on its own): when the normal force stays below this
    /// fraction of the preload for `contact_lost_s` during a probe run, a stroke has carried
    /// the tool off the surface (over an edge). The run is abandoned and tracking goes on along
    /// the old tangent with the force loop on; the tracker travels `contact_lost_travel_m`
    /// before it estimates again. 0 turns the guard off.
    pub contact_lost_fraction: f64,
    /// How long the normal force must stay below `contact_lost_fraction` of the preload (s).
    pub contact_lost_s: f64,
    /// Travel after an abandoned probe run before the tracker estimates again (m): far enough
    /// past the edge that the next probe's strokes stay on the face beyond it.
    pub contact_lost_travel_m: f64,
    /// After an estimate that turns the tangent by more than `corner_angle_deg` (a corner),
    /// estimate once more this far on (m), where the probe's strokes no longer reach the
    /// corner: a probe near a corner feels both faces, and its answer can be off by less
    /// than the drift trigger sees. 0: no confirmation.
    pub corner_confirm_m: f64,
}

impl Default for TrackingParams {
    fn default() -> Self {
        Self {
            enabled: false,
            force_trigger_fraction: 0.2,
            force_filter_s: 0.002,
            slope_trigger_deg: 0.75,
            slope_window_m: 0.002,
            drift_source: DriftSource::Auto,
            min_travel_m: 0.001,
            max_travel_m: 0.0,
            curvature_feedforward: true,
            max_curvature_per_m: 10.0,
            corner_angle_deg: 5.0,
            contact_lost_fraction: 0.2,
            contact_lost_s: 0.005,
            contact_lost_travel_m: 0.003,
            corner_confirm_m: 0.003,
        }
    }
}

impl Default for ServoParams {
    fn default() -> Self {
        Self {
            rate_hz: 10_000.0,
            joint_bandwidth_hz: [3.0, 15.0],
            joint_damping_ratio: 0.7,
            joint_integral_ratio: 0.1,
            hybrid: HybridParams::default(),
            dither: DitherParams::default(),
            tuner: TunerConfig::default(),
            friction_model: FrictionLaw::THESIS,
            friction_model_reference_n: 2.5,
            tool_mass_kg: 0.05,
            inertia_feedforward: true,
            preload_feedforward: true,
            contact_damping_ratio: 0.25,
            contact_adaptation: true,
            probe_force_loop: ProbeForceLoop::Auto,
            tangent: TangentParams::default(),
            tracking: TrackingParams::default(),
            safe: SafeParams::default(),
            approach: ApproachParams::default(),
        }
    }
}

impl TrackingParams {
    /// Checks the settings; the message names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        // (name, value, least, most, least allowed)
        let ranges = [
            (
                "force_trigger_fraction",
                self.force_trigger_fraction,
                0.0,
                1.0,
                false,
            ),
            ("force_filter_s", self.force_filter_s, 0.0, 10.0, true),
            (
                "slope_trigger_deg",
                self.slope_trigger_deg,
                0.0,
                90.0,
                false,
            ),
            ("slope_window_m", self.slope_window_m, 0.0, 1.0, false),
            ("min_travel_m", self.min_travel_m, 0.0, 1.0, true),
            ("max_travel_m", self.max_travel_m, 0.0, 10.0, true),
            (
                "max_curvature_per_m",
                self.max_curvature_per_m,
                0.0,
                1e4,
                true,
            ),
            ("corner_angle_deg", self.corner_angle_deg, 0.0, 180.0, false),
            (
                "contact_lost_fraction",
                self.contact_lost_fraction,
                0.0,
                1.0,
                true,
            ),
            ("contact_lost_s", self.contact_lost_s, 0.0, 1.0, false),
            (
                "contact_lost_travel_m",
                self.contact_lost_travel_m,
                0.0,
                1.0,
                true,
            ),
            ("corner_confirm_m", self.corner_confirm_m, 0.0, 1.0, true),
        ];
        for (name, v, lo, hi, lo_ok) in ranges {
            let above = if lo_ok { v >= lo } else { v > lo };
            if !(v.is_finite() && above && v <= hi) {
                let open = if lo_ok { "[" } else { "(" };
                return Err(ConfigError::setting(
                    format!("servo.tracking.{name}"),
                    v,
                    format!("must lie in {open}{lo}, {hi}]"),
                ));
            }
        }
        Ok(())
    }
}

impl ServoParams {
    /// Checks every setting; the message names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.rate_hz.is_finite() && (100.0..=100_000.0).contains(&self.rate_hz)) {
            return Err(ConfigError::setting(
                "servo.rate_hz",
                self.rate_hz,
                "must lie in [100, 100000]",
            ));
        }
        for (j, b) in self.joint_bandwidth_hz.iter().enumerate() {
            if !(b.is_finite() && *b > 0.0 && *b < self.rate_hz / 20.0) {
                return Err(ConfigError::setting(
                    format!("servo.joint_bandwidth_hz[{j}]"),
                    *b,
                    format!("must be > 0 and below rate_hz/20 = {}", self.rate_hz / 20.0),
                ));
            }
        }
        if !(self.joint_damping_ratio.is_finite() && self.joint_damping_ratio > 0.0) {
            return Err(ConfigError::setting(
                "servo.joint_damping_ratio",
                self.joint_damping_ratio,
                "must be > 0",
            ));
        }
        if !(self.joint_integral_ratio.is_finite()
            && self.joint_integral_ratio >= 0.0
            && self.joint_integral_ratio < 1.0)
        {
            return Err(ConfigError::setting(
                "servo.joint_integral_ratio",
                self.joint_integral_ratio,
                "must lie in [0, 1)",
            ));
        }
        if !(self.contact_damping_ratio.is_finite()
            && (0.0..=5.0).contains(&self.contact_damping_ratio))
        {
            return Err(ConfigError::setting(
                "servo.contact_damping_ratio",
                self.contact_damping_ratio,
                "must lie in [0, 5] (0 adds no damping)",
            ));
        }
        self.hybrid.validate()?;
        self.dither.validate()?;
        if self.dither.frequency_hz > self.rate_hz / 10.0 {
            return Err(ConfigError::setting(
                "dither.frequency_hz",
                self.dither.frequency_hz,
                format!(
                    "must stay well below the servo's Nyquist frequency: at most rate_hz/10 = {}",
                    self.rate_hz / 10.0
                ),
            ));
        }
        self.safe.validate()?;
        self.tracking.validate()?;
        self.approach.validate()?;
        self.tuner.validate()?;
        self.friction_model.validate()?;
        if !(self.friction_model_reference_n.is_finite() && self.friction_model_reference_n > 0.0) {
            return Err(ConfigError::setting(
                "servo.friction_model_reference_n",
                self.friction_model_reference_n,
                "must be > 0",
            ));
        }
        if !(self.tool_mass_kg.is_finite() && self.tool_mass_kg >= 0.0) {
            return Err(ConfigError::setting(
                "servo.tool_mass_kg",
                self.tool_mass_kg,
                "must be ≥ 0",
            ));
        }
        Ok(())
    }

    /// Servo period (s).
    pub fn dt(&self) -> f64 {
        1.0 / self.rate_hz
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The defaults pass; a value outside its range, or not a number, is refused by the
    /// setting's name; the open and closed ends are where the message says.
    #[test]
    fn tracking_settings_are_checked_by_name() {
        assert_eq!(ServoParams::default().validate(), Ok(()));
        let refused = |t: TrackingParams| {
            ServoParams {
                tracking: t,
                ..ServoParams::default()
            }
            .validate()
            .unwrap_err()
            .to_string()
        };
        let base = TrackingParams::default();
        let e = refused(TrackingParams {
            contact_lost_fraction: 1.5,
            ..base
        });
        assert_eq!(
            e,
            "servo.tracking.contact_lost_fraction = 1.5 must lie in [0, 1]"
        );
        let e = refused(TrackingParams {
            force_trigger_fraction: f64::NAN,
            ..base
        });
        assert!(
            e.starts_with("servo.tracking.force_trigger_fraction = NaN"),
            "{e}"
        );
        let e = refused(TrackingParams {
            contact_lost_s: 0.0,
            ..base
        });
        assert_eq!(e, "servo.tracking.contact_lost_s = 0 must lie in (0, 1]");
        let off = TrackingParams {
            contact_lost_fraction: 0.0,
            min_travel_m: 0.0,
            ..base
        };
        assert_eq!(off.validate(), Ok(()));
    }
}
