//! The servo learns its contact: the normal stiffness fitted on line from the encoders and the
//! sensor ([`crate::contact`]), and what depends on it (the Hooke's-law stiffness, the rate
//! feedforward β, the contact mode's damping, the dither's amplitude bound) re-derived when the
//! fit is tight and far from the stiffness in use (docs/contact.md, *Knowing the contact*).

use super::{ServoCore, contact_damping};
use crate::arm::Pose;
use crate::contact::{StiffnessEstimate, StiffnessFitState};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

/// The fit takes one sample per this many seconds (1 kHz): the sensor's filtered noise is
/// correlated over about half a millisecond, and decorrelated samples keep the fit's standard
/// error honest.
const SAMPLE_PERIOD_S: f64 = 1e-3;
/// Effective samples (0.1 s at 1 kHz) before the fit may be adopted.
pub(crate) const MIN_SAMPLES: f64 = 100.0;
/// The fit is adopted only when its relative standard error is below this ...
pub(crate) const MAX_RELATIVE_ERROR: f64 = 0.1;
/// ... and it is this many times the stiffness in use or more. Only a stiffer contact than
/// assumed threatens the loop (β and the damping were set for a softer one); a softer one only
/// slows it (thesis §3.2). Away from the probes, the fit's tight readings on the default set-up
/// stayed below 0.5 times the truth (fig. 5.3's preliminary method, which drives the normal
/// set-point by position), docs/contact.md.
pub(crate) const ADOPT_FACTOR: f64 = 4.0;

wire_struct! {
    /// What the servo knows of its contact, for a snapshot.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::ContactState")]
    pub struct ContactState {
        /// Times the servo adopted a fitted stiffness.
        pub adopted: u32,
        /// Ticks since the fit's last sample.
        pub phase: u32,
        /// Damping added along the normal (N·s/m).
        pub normal_damping_n_s_per_m: f64,
        /// The stiffness fit's memory.
        pub fit: StiffnessFitState,
    }
}

impl ServoCore {
    /// The contact's normal stiffness as fitted on line, with its standard error; None until
    /// the tool's motion has excited it.
    pub fn stiffness_estimate(&self) -> Option<StiffnessEstimate> {
        self.stiffness.estimate()
    }

    /// Times the servo adopted a fitted stiffness.
    pub fn stiffness_adoptions(&self) -> u32 {
        self.adopted
    }

    pub(super) fn contact_state(&self) -> ContactState {
        ContactState {
            adopted: self.adopted,
            phase: self.contact_phase,
            normal_damping_n_s_per_m: self.normal_damping,
            fit: self.stiffness.state(),
        }
    }

    pub(super) fn restore_contact(&mut self, c: &ContactState) {
        self.adopted = c.adopted;
        self.contact_phase = c.phase;
        self.normal_damping = c.normal_damping_n_s_per_m;
        self.stiffness.restore(&c.fit);
        self.stiffness_frame = *self.hybrid.frame();
        if c.adopted > 0 {
            // The bound follows the adopted stiffness (the dither's own state comes after).
            self.derive_amplitude_bound();
        }
    }

    /// Feeds the fit the tool's encoder position (at the measured `pose`) in the task frame and
    /// the measured normal force, and adopts the fit when it is tight and far from the stiffness
    /// in use. A re-based frame restarts the fit (its coordinates jump).
    pub(super) fn observe_contact(&mut self, dt: f64, pose: &Pose, normal_n: f64) {
        let every = (SAMPLE_PERIOD_S / dt).round().max(1.0) as u32;
        self.contact_phase += 1;
        if self.contact_phase < every {
            return;
        }
        self.contact_phase = 0;
        let frame = *self.hybrid.frame();
        if frame != self.stiffness_frame {
            self.stiffness.reset();
            self.stiffness_frame = frame;
        }
        let r = self.arm.forward_at(pose) - frame.origin;
        let x = -r.dot(&frame.normal());
        self.stiffness
            .push(dt * f64::from(every), x, r.dot(&frame.tangent()), normal_n);
        if !self.params.contact_adaptation {
            return;
        }
        let Some(e) = self.stiffness.estimate() else {
            return;
        };
        let in_use = self.hybrid.params().stiffness_estimate_n_per_m;
        let k = e.stiffness_n_per_m;
        if e.samples >= MIN_SAMPLES
            && e.relative_error() <= MAX_RELATIVE_ERROR
            && k >= ADOPT_FACTOR * in_use
        {
            self.adopt_stiffness(k);
        }
    }

    /// Re-derives the gains that depend on the contact's stiffness for `stiffness` (N/m).
    pub fn adopt_stiffness(&mut self, stiffness: f64) {
        if !(stiffness.is_finite() && stiffness > 0.0) {
            return;
        }
        let [mass, servo_damping, servo_stiffness] = self.contact_mode;
        self.hybrid
            .set_stiffness_estimate(stiffness, servo_stiffness, self.loop_delay);
        self.normal_damping = contact_damping(
            self.params.contact_damping_ratio,
            stiffness,
            servo_stiffness,
            mass,
            servo_damping,
        );
        self.adopted = self.adopted.saturating_add(1);
        self.derive_amplitude_bound();
    }

    /// The dither's amplitude bound for the stiffness in use, and the tuner's Aω range with it;
    /// a dither above the new bound is brought down to it.
    pub(super) fn derive_amplitude_bound(&mut self) {
        // As at the start: the configured preload, the stiffness now in use.
        let stiffness = self.hybrid.params().stiffness_estimate_n_per_m;
        let preload = self.params.hybrid.preload_n;
        self.amplitude_bound = self.params.dither.amplitude_bound(preload, stiffness);
        self.ctx.a_max = self.amplitude_bound * self.ctx.omega;
        let a = self.dither.velocity_amplitude();
        self.dither
            .set_velocity_amplitude(a.min(self.ctx.a_max), self.amplitude_bound);
    }
}

/// What the servo knew of its contact at the end of a run, for the run's report (from its
/// last snapshot).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct ContactReport {
    /// The contact stiffness k̂_e the gains were derived for (N/m): configured, or adopted.
    pub stiffness_in_use_n_per_m: f64,
    /// Times the servo adopted its fit.
    pub adoptions: u32,
    /// The fit's stiffness at the end (N/m), if it was determined: the contact in series with
    /// the sensor, as the encoders and the sensor see it.
    pub fitted_n_per_m: Option<f64>,
    /// Its standard error (N/m).
    pub fitted_std_error_n_per_m: Option<f64>,
    /// β, the fraction of the force loop's rate fed forward.
    pub rate_feedforward: f64,
    /// Damping added along the normal (N·s/m).
    pub added_damping_n_s_per_m: f64,
}

impl ContactReport {
    /// The report of a servo's state.
    pub fn from_state(state: &super::ServoState) -> Self {
        let mut fit = crate::contact::StiffnessEstimator::new(Default::default());
        fit.restore(&state.contact.fit);
        let e = fit.estimate();
        Self {
            stiffness_in_use_n_per_m: state.hybrid.stiffness_estimate_n_per_m,
            adoptions: state.contact.adopted,
            fitted_n_per_m: e.map(|e| e.stiffness_n_per_m),
            fitted_std_error_n_per_m: e.map(|e| e.std_error_n_per_m),
            rate_feedforward: state.hybrid.rate_feedforward,
            added_damping_n_s_per_m: state.contact.normal_damping_n_s_per_m,
        }
    }
}
