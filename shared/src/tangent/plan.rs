//! What a probe run is: the estimator's settings ([`TangentParams`]), the plan the servo runs
//! ([`ProbePlan`]) and what it records ([`ProbeSample`]).

use crate::error::ConfigError;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// Most probes one estimate can use.
pub const MAX_PROBES: usize = 6;

/// Settings of the tangent estimator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TangentParams {
    /// First probe angles δα1, δα2 off the estimated tangent (deg); thesis 5° and 10°.
    pub probe_angles_deg: [f64; 2],
    /// Re-probe angles, used on both sides (deg).
    pub reprobe_angles_deg: [f64; 2],
    /// Stroke amplitude A (m).
    pub amplitude_m: f64,
    /// Stroke frequency (Hz), ≤ 1 Hz (thesis §4.5.1).
    pub frequency_hz: f64,
    /// Whole stroke periods measured per probe.
    pub periods: usize,
    /// Ramp in and out of each probe (s).
    pub ramp_s: f64,
    /// Hold before probing, to settle and measure the noise (s).
    pub settle_s: f64,
    /// A sign is trusted when |in-phase amplitude| exceeds this many standard errors.
    pub sign_threshold: f64,
    /// R1 ≈ R2: re-probe when |R1/A1 − R2/A2| is below this many standard errors.
    pub equal_threshold: f64,
    /// Largest standard error of α0 accepted (deg).
    pub max_std_error_deg: f64,
    /// Contact counts as lost when the normal force falls below this fraction of the hold mean.
    pub contact_loss_fraction: f64,
    /// Configured sensor noise standard deviation (N), used when the hold gives no estimate.
    pub noise_std_n: f64,
    /// The contact stiffness the stroke is sized for (N/m): the thesis's 10 kN/m, on which the
    /// 1-mm stroke gives a normal-force response well above the sensor's noise. A first probe
    /// set whose regression finds a contact softer than [`SOFT_CONTACT_FRACTION`] of it is run
    /// again with the stroke scaled up ([`TangentParams::soft_contact_stroke`]); 0 never does.
    pub design_stiffness_n_per_m: f64,
}

/// A contact softer than this fraction of [`TangentParams::design_stiffness_n_per_m`] is
/// re-probed with a longer stroke.
pub const SOFT_CONTACT_FRACTION: f64 = 0.5;

/// The soft-contact re-probe's inner angle off the corrected tangent (deg); the outer one is
/// twice it.
pub const SOFT_CONTACT_ANGLE_DEG: f64 = 2.0;

/// The longest stroke a soft-contact re-probe runs (m): ten times the default.
pub const SOFT_CONTACT_MAX_STROKE_M: f64 = 0.01;

/// The share of the hold's normal force a soft-contact re-probe's normal swing may take
/// at its widest probe: a quarter of what tracking tolerates (`afs experiment fig5.6` checks
/// the dither-period mean of the normal force within 0.2 of the preload; the swing adds to
/// what the tracking itself deviates, and a share of 0.1 took it to 0.22 on 1 kN/m).
pub const SOFT_CONTACT_MARGIN: f64 = 0.05;

impl Default for TangentParams {
    fn default() -> Self {
        Self {
            probe_angles_deg: [5.0, 10.0],
            reprobe_angles_deg: [8.0, 16.0],
            amplitude_m: 1e-3,
            frequency_hz: 1.0,
            periods: 2,
            ramp_s: 1.0,
            settle_s: 0.3,
            sign_threshold: 4.0,
            equal_threshold: 3.0,
            max_std_error_deg: 0.5,
            contact_loss_fraction: 0.1,
            noise_std_n: 0.02,
            design_stiffness_n_per_m: 1e4,
        }
    }
}

impl TangentParams {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (n, v) in [
            ("probe_angles_deg[0]", self.probe_angles_deg[0]),
            ("probe_angles_deg[1]", self.probe_angles_deg[1]),
            ("reprobe_angles_deg[0]", self.reprobe_angles_deg[0]),
            ("reprobe_angles_deg[1]", self.reprobe_angles_deg[1]),
        ] {
            if !(v.is_finite() && v.abs() < 60.0) {
                return Err(ConfigError::setting(
                    format!("tangent.{n}"),
                    v,
                    "must lie in (−60, 60) degrees",
                ));
            }
        }
        if self.probe_angles_deg[0] == self.probe_angles_deg[1] {
            return Err(ConfigError::rule(
                "tangent.probe_angles_deg",
                "must be two different angles",
            ));
        }
        if !(self.amplitude_m.is_finite() && self.amplitude_m > 0.0 && self.amplitude_m < 0.02) {
            return Err(ConfigError::setting(
                "tangent.amplitude_m",
                self.amplitude_m,
                "must lie in (0, 0.02)",
            ));
        }
        if !(self.frequency_hz.is_finite() && self.frequency_hz > 0.0 && self.frequency_hz <= 5.0) {
            return Err(ConfigError::setting(
                "tangent.frequency_hz",
                self.frequency_hz,
                "must lie in (0, 5]",
            ));
        }
        if self.periods == 0 || self.periods > 20 {
            return Err(ConfigError::setting(
                "tangent.periods",
                self.periods as f64,
                "must lie in 1..=20",
            ));
        }
        for (n, v) in [
            ("ramp_s", self.ramp_s),
            ("settle_s", self.settle_s),
            ("sign_threshold", self.sign_threshold),
            ("equal_threshold", self.equal_threshold),
            ("max_std_error_deg", self.max_std_error_deg),
            ("noise_std_n", self.noise_std_n),
            ("design_stiffness_n_per_m", self.design_stiffness_n_per_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ConfigError::setting(
                    format!("tangent.{n}"),
                    v,
                    "must be ≥ 0",
                ));
            }
        }
        if !(0.0..1.0).contains(&self.contact_loss_fraction) {
            return Err(ConfigError::setting(
                "tangent.contact_loss_fraction",
                self.contact_loss_fraction,
                "must lie in [0, 1)",
            ));
        }
        Ok(())
    }

    /// The first probe set (rad).
    pub fn first_plan(&self) -> ProbePlan {
        ProbePlan::new(
            &[
                self.probe_angles_deg[0].to_radians(),
                self.probe_angles_deg[1].to_radians(),
            ],
            self,
        )
    }

    /// The re-probe set: both sides, wider angles (rad).
    pub fn reprobe_plan(&self) -> ProbePlan {
        let [a, b] = self.reprobe_angles_deg.map(f64::to_radians);
        ProbePlan::new(&[-b, -a, a, b], self)
    }

    /// Largest stroke amplitude that keeps contact (m): the normal-force swing
    /// `k · A · sin(largest angle + uncertainty)` must stay below `margin` × preload, with k the
    /// stiffness the force controller uses (contact in series with the servo).
    pub fn amplitude_bound(
        &self,
        preload_n: f64,
        stiffness_n_per_m: f64,
        uncertainty_rad: f64,
        margin: f64,
    ) -> f64 {
        let widest = self
            .probe_angles_deg
            .iter()
            .chain(&self.reprobe_angles_deg)
            .fold(0.0f64, |m, a| m.max(a.abs()));
        let s = (widest.to_radians() + uncertainty_rad).sin().max(1e-6);
        margin * preload_n / (stiffness_n_per_m * s)
    }

    /// The stroke of a re-probe on a soft contact (m), or None where the contact is not soft or
    /// a longer stroke would gain little.
    ///
    /// The regression's error goes as the force noise over `k_e A` (the tip's travel along the
    /// surface times the contact's stiffness, `stiffness_n_per_m`), so on a contact softer than
    /// the design stiffness the stroke `A · k_design / k_e` would give the design's accuracy.
    /// What the stroke costs is the normal force's swing, `k_c A sin(δα + α0)`, with `k_c`
    /// (`response_n_per_m`) the in-phase normal force per metre of the commanded stroke's
    /// normal part: the contact in series with the servo, less what the force loop takes out at
    /// the stroke's frequency. The soft re-probe runs about the corrected tangent
    /// ([`TangentParams::soft_contact_plan`]), at ±[`SOFT_CONTACT_ANGLE_DEG`] and twice that,
    /// so its widest angle off the truth is 2 × that plus `uncertainty_rad`; the swing there is
    /// held to [`SOFT_CONTACT_MARGIN`] × the hold's `preload_n`, and the stroke to
    /// [`SOFT_CONTACT_MAX_STROKE_M`]. Less than 1.5× the configured stroke is not worth a
    /// second probe set.
    pub fn soft_contact_stroke(
        &self,
        stiffness_n_per_m: f64,
        response_n_per_m: f64,
        preload_n: f64,
        uncertainty_rad: f64,
    ) -> Option<f64> {
        let design = self.design_stiffness_n_per_m;
        let soft = stiffness_n_per_m.is_finite()
            && stiffness_n_per_m > 0.0
            && stiffness_n_per_m < SOFT_CONTACT_FRACTION * design;
        let numbers = response_n_per_m.is_finite()
            && response_n_per_m > 0.0
            && preload_n.is_finite()
            && preload_n > 0.0
            && uncertainty_rad.is_finite()
            && uncertainty_rad >= 0.0;
        if !(soft && numbers) {
            return None;
        }
        let widest = (2.0 * SOFT_CONTACT_ANGLE_DEG.to_radians() + uncertainty_rad).sin();
        let bound = SOFT_CONTACT_MARGIN * preload_n / (response_n_per_m * widest);
        let stroke = (self.amplitude_m * design / stiffness_n_per_m)
            .min(bound)
            .min(SOFT_CONTACT_MAX_STROKE_M);
        (stroke >= 1.5 * self.amplitude_m).then_some(stroke)
    }

    /// The soft-contact re-probe set (see [`TangentParams::soft_contact_stroke`]): four probes
    /// at ±[`SOFT_CONTACT_ANGLE_DEG`] and ±twice that off the corrected tangent, the estimated
    /// tangent less the first set's `alpha0_rad` (offsets `±a − α0`), with the stroke
    /// `stroke_m`. Close to the tangent the stroke travels along the surface, which is what
    /// the regression's accuracy needs, and barely into it, which is what the swing costs; the
    /// probes on both sides keep the stiffness (the regression's other unknown) determined.
    pub fn soft_contact_plan(&self, stroke_m: f64, alpha0_rad: f64) -> ProbePlan {
        let a = SOFT_CONTACT_ANGLE_DEG.to_radians();
        let mut plan = ProbePlan::new(&[-2.0 * a, -a, a, 2.0 * a].map(|o| o - alpha0_rad), self);
        plan.amplitude_m = stroke_m;
        plan
    }
}

/// The probes the servo is to run: offsets from the estimated tangent and stroke settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ProbePlan {
    /// Offsets δα_i (rad); only the first `count` are used.
    pub offsets: [f64; MAX_PROBES],
    /// Number of probes.
    pub count: usize,
    /// Stroke amplitude (m).
    pub amplitude_m: f64,
    /// Stroke frequency (Hz).
    pub frequency_hz: f64,
    /// Measured periods per probe.
    pub periods: usize,
    /// Ramp in/out (s).
    pub ramp_s: f64,
    /// Hold before the first probe (s).
    pub settle_s: f64,
    /// Frequency of the friction-suppression dither running during the strokes (Hz), 0 if
    /// none: the estimator averages the force over one of its periods to remove it.
    pub dither_hz: f64,
}

impl ProbePlan {
    /// A plan for the given offsets (rad), at most [`MAX_PROBES`].
    pub fn new(offsets: &[f64], p: &TangentParams) -> Self {
        let mut o = [0.0; MAX_PROBES];
        let count = offsets.len().min(MAX_PROBES);
        o[..count].copy_from_slice(&offsets[..count]);
        Self {
            offsets: o,
            count,
            amplitude_m: p.amplitude_m,
            frequency_hz: p.frequency_hz,
            periods: p.periods,
            ramp_s: p.ramp_s,
            settle_s: p.settle_s,
            dither_hz: 0.0,
        }
    }

    /// Duration of one probe (s).
    pub fn probe_duration(&self) -> f64 {
        2.0 * self.ramp_s + self.periods as f64 / self.frequency_hz
    }

    /// Duration of the whole plan (s).
    pub fn duration(&self) -> f64 {
        self.settle_s + self.count as f64 * self.probe_duration()
    }
}

/// Marks a hold sample (before the first probe) in [`ProbeSample::probe`].
pub const HOLD: u8 = u8::MAX;

wire_message! {
    version = 1;
    /// One recorded sample of a probe run (also the payload element of a tangent request).
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, ZeroCopySend)]
    #[type_name("afs::ProbeSample")]
    pub struct ProbeSample {
        /// Time (s).
        pub t: f64,
        /// Measured force on the tool, world frame (N).
        pub force: [f64; 2],
        /// Tip position from the encoders, world frame (m).
        pub tip: [f64; 2],
        /// Stroke phase φ (rad): the commanded displacement is A sin φ.
        pub phase: f64,
        /// Probe index, or [`HOLD`].
        pub probe: u8,
        /// True during the measured whole periods (false in ramps).
        pub measured: bool,
    }
}
