//! The servo learns its contact: the normal stiffness fitted on line from the encoders and the
//! sensor ([`crate::contact`]), and what depends on it (the Hooke's-law stiffness, the rate
//! feedforward β, the contact mode's damping, the dither's amplitude bound) re-derived when the
//! fit is tight and far from the stiffness in use (docs/contact.md, *Knowing the contact*).

use super::{ServoCore, ServoMode};
use crate::contact::{StiffnessEstimate, StiffnessFitState};
use crate::math::Vec2;
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
/// After a guarded approach, the fit takes samples from this fraction of the preload up: the
/// contact is then certain (the sensor's noise is a hundredth of it).
const FIT_FROM_FRACTION: f64 = 0.2;

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
        /// 1 while the gains are the guarded approach's (set for the stiffest contact
        /// expected) and the fit's first tight reading is to be adopted whichever way it
        /// lies; 0 otherwise.
        pub provisional: u32,
        /// Zero (padding; a later field).
        pub reserved: u32,
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
            provisional: u32::from(self.provisional),
            reserved: 0,
        }
    }

    pub(super) fn restore_contact(&mut self, c: &ContactState) {
        self.adopted = c.adopted;
        self.contact_phase = c.phase;
        self.normal_damping = c.normal_damping_n_s_per_m;
        self.stiffness.restore(&c.fit);
        self.stiffness_frame = *self.hybrid.frame();
        self.provisional = c.provisional != 0;
        // The bound follows the stiffness in use (the dither's own state comes after).
        self.derive_amplitude_bound();
    }

    /// Feeds the fit the tool's encoder position (`tip`, m) in the task frame and
    /// the measured normal force, and adopts the fit when it is tight and far from the stiffness
    /// in use. A re-based frame restarts the fit (its coordinates jump).
    pub(super) fn observe_contact(&mut self, dt: f64, tip: Vec2, normal_n: f64) {
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
        let r = tip - frame.origin;
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
        let tight = e.samples >= MIN_SAMPLES && e.relative_error() <= MAX_RELATIVE_ERROR;
        // The approach's gains were an assumption, not a reading: the first tight fit
        // replaces them whichever way it lies.
        if tight && (self.provisional || k >= ADOPT_FACTOR * in_use) {
            self.provisional = false;
            self.adopt_stiffness(k);
        }
    }

    /// Whether the fit observes this tick: while tracking, and after the first touch while
    /// the approach's gains are provisional (the settling of the preload compresses the
    /// contact, the reading the fit needs); free-flight samples would read no stiffness.
    pub(super) fn observes_contact(&self, normal_n: f64) -> bool {
        match self.mode {
            ServoMode::Track => true,
            ServoMode::Approach | ServoMode::Resuming => {
                self.provisional && normal_n >= FIT_FROM_FRACTION * self.hybrid.params().preload_n
            }
            _ => false,
        }
    }

    /// The guarded approach's gains: the contact-dependent ones (β, the contact mode's damping,
    /// the dither's bound) for the stiffest contact expected, provisional until the fit reads
    /// the contact.
    pub(super) fn assume_stiffest_contact(&mut self) {
        let k = self
            .params
            .approach
            .stiffest_contact_n_per_m
            .max(self.params.hybrid.stiffness_estimate_n_per_m);
        self.use_stiffness(k);
        self.provisional = true;
    }

    /// The guarded approach's tick (mode [`ServoMode::Approach`]): the tangential motion is held
    /// (a velocity asked for is kept for after the touch), and a normal force of
    /// `touch_fraction` of the preload ends it; the servo then settles the preload as after an
    /// estimate (`Resuming`) and moves on.
    pub(super) fn approach(&mut self, force: Vec2) {
        let wanted = self.hybrid.velocity_target();
        if wanted != 0.0 {
            self.track.resume_velocity_m_per_s = wanted;
            self.hybrid.set_velocity(0.0);
        }
        let preload = self.hybrid.params().preload_n;
        if force.dot(&self.hybrid.frame().normal()) >= self.params.approach.touch_fraction * preload
        {
            self.mode = ServoMode::Resuming;
            self.track.stopped_s = 0.0;
            self.track.settled_s = 0.0;
        }
    }

    /// The guarded approach's speed (m/s).
    pub fn approach_speed(&self) -> f64 {
        self.approach_speed
    }

    /// Re-derives the gains that depend on the contact's stiffness for `stiffness` (N/m), and
    /// counts an adoption.
    pub fn adopt_stiffness(&mut self, stiffness: f64) {
        if self.use_stiffness(stiffness) {
            self.adopted = self.adopted.saturating_add(1);
        }
    }

    /// Re-derives the gains that depend on the contact's stiffness for `stiffness` (N/m): the
    /// Hooke's-law stiffness and β, the contact mode's damping, the dither's bound; false
    /// (nothing changed) unless it is finite and positive.
    pub(super) fn use_stiffness(&mut self, stiffness: f64) -> bool {
        if !(stiffness.is_finite() && stiffness > 0.0) {
            return false;
        }
        let [mass, servo_damping, servo_stiffness] = self.contact_mode;
        self.hybrid
            .set_stiffness_estimate(stiffness, servo_stiffness, self.loop_delay);
        self.normal_damping = contact_damping(
            Self::contact_damping_ratio_for(&self.params, stiffness, servo_stiffness, mass),
            stiffness,
            servo_stiffness,
            mass,
            servo_damping,
        );
        self.derive_amplitude_bound();
        true
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

/// Damping to add along the normal (N·s/m) so that the contact mode, the effective mass
/// `mass` (kg) on the contact `stiffness` (N/m) in parallel with the servo's `servo_stiffness`,
/// has the damping ratio `zeta` with the servo's own `servo_damping` (N·s/m):
/// `max(0, 2ζ √((k̂_e + k_s) m) − c_s)` (docs/contact.md).
pub fn contact_damping(
    zeta: f64,
    stiffness: f64,
    servo_stiffness: f64,
    mass: f64,
    servo_damping: f64,
) -> f64 {
    let want = 2.0 * zeta * ((stiffness + servo_stiffness) * mass).sqrt();
    if want.is_finite() {
        (want - servo_damping).max(0.0)
    } else {
        0.0
    }
}

/// The damping ratio the contact's normal mode needs so that it does not amplify the dither:
/// the mode (natural frequency ω_c = √((k̂_e + k_s)/m)) driven at the dither's ω_d has the gain
/// `1/√((1 − r²)² + (2ζr)²)`, r = ω_d/ω_c, and that is at most 1 when
/// `ζ ≥ √(1 − (1 − r²)²) / (2r)`; above r = √2 no damping is needed (docs/contact.md, *The
/// contact mode and the dither*). 0 when the inputs are not finite and positive.
pub fn dither_damping_ratio(
    dither_omega: f64,
    stiffness: f64,
    servo_stiffness: f64,
    mass: f64,
) -> f64 {
    let Some(r) = dither_over_mode(dither_omega, stiffness, servo_stiffness, mass) else {
        return 0.0;
    };
    let detune = (1.0 - r * r).powi(2);
    if detune >= 1.0 {
        0.0
    } else {
        (1.0 - detune).sqrt() / (2.0 * r)
    }
}

/// True when the contact's normal mode (ω_c = √((k̂_e + k_s)/m)) sits above ω_d/√2, the
/// ratio r = ω_d/ω_c below √2 at which the mode amplifies what drives it at the dither's
/// frequency ([`dither_damping_ratio`] is then above 0). With the force loop frozen, the
/// dither's normal error along a tangent that is off then reaches the force at the contact's
/// stiffness or more (docs/contact.md, *The force loop during the probes*). False when the
/// inputs are not finite and positive.
pub fn contact_mode_above_dither(
    dither_omega: f64,
    stiffness: f64,
    servo_stiffness: f64,
    mass: f64,
) -> bool {
    dither_over_mode(dither_omega, stiffness, servo_stiffness, mass)
        .is_some_and(|r| r < std::f64::consts::SQRT_2)
}

/// r = ω_d/ω_c, the dither's frequency over the contact mode's `√((k̂_e + k_s)/m)`; None unless
/// finite and positive.
fn dither_over_mode(
    dither_omega: f64,
    stiffness: f64,
    servo_stiffness: f64,
    mass: f64,
) -> Option<f64> {
    let r = dither_omega / ((stiffness + servo_stiffness) / mass).sqrt();
    (r.is_finite() && r > 0.0).then_some(r)
}
