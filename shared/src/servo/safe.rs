//! The safe state of the fast loop: entered whenever the force data cannot be trusted (stale,
//! missing or insane), left once it has been good for a while ([`SafeParams`]).

use super::{ServoCore, ServoMode};
use crate::hybrid::SetpointOffset;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

wire_struct! {
    /// Where the safe state is (a part of [`super::ServoState`], valid with its `SAFE` flag).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::SafeState")]
    pub struct SafeState {
        /// Velocity to restore (m/s).
        pub resume_velocity_m_per_s: f64,
        /// Aω to restore (m/s).
        pub resume_a_omega_m_per_s: f64,
        /// Back-off still to apply (m).
        pub backoff_left_m: f64,
        /// Time the data has been good again (s).
        pub good_for_s: f64,
    }
}

impl ServoCore {
    /// The velocity target the servo tracks at, or goes back to after an estimation or the
    /// safe state (m/s).
    pub fn resume_velocity(&self) -> f64 {
        match (&self.safe, self.mode) {
            (Some(s), _) => s.resume_velocity_m_per_s,
            (None, ServoMode::Track) => self.hybrid.velocity_target(),
            (None, _) => self.track.resume_velocity_m_per_s,
        }
    }

    /// The Aω the servo dithers at, or goes back to after the safe state (m/s).
    pub fn resume_a_omega(&self) -> f64 {
        match &self.safe {
            Some(s) => s.resume_a_omega_m_per_s,
            None => self
                .resume_a_omega
                .unwrap_or(self.dither.velocity_amplitude()),
        }
    }

    /// True while in the safe state.
    pub fn is_safe(&self) -> bool {
        self.safe.is_some()
    }

    /// Enters, runs or leaves the safe state for this tick's force-data validity.
    pub(super) fn update_safe(&mut self, valid: bool, dt: f64) {
        let recovery = self.params.safe.recovery_s;
        match self.safe.as_mut() {
            None if !valid => self.enter_safe(),
            None => return,
            Some(s) if valid => {
                s.good_for_s += dt;
                if s.good_for_s >= recovery {
                    self.leave_safe();
                    return;
                }
            }
            Some(s) => s.good_for_s = 0.0,
        }
        let p = self.params.safe;
        let total =
            p.backoff_fraction * self.hybrid.params().preload_n / self.hybrid.hooke_stiffness();
        let a = self.dither.velocity_amplitude();
        let decayed = a * (-dt / p.dither_decay_s).exp();
        self.dither.set_velocity_amplitude(
            if decayed < 1e-6 { 0.0 } else { decayed },
            self.amplitude_bound,
        );
        if let Some(s) = self.safe.as_mut() {
            let step = s.backoff_left_m.min(total * dt / p.backoff_s);
            s.backoff_left_m -= step;
            self.hybrid.shift_depth(-step);
        }
    }

    pub(super) fn enter_safe(&mut self) {
        self.counters.safe_entries += 1;
        let resume_velocity = match self.mode {
            ServoMode::Track => self.hybrid.velocity_target(),
            _ => self.track.resume_velocity_m_per_s,
        };
        let resume_a_omega = self
            .resume_a_omega
            .unwrap_or(self.dither.velocity_amplitude());
        self.hybrid.set_velocity(0.0);
        if matches!(self.mode, ServoMode::Stopping | ServoMode::Probing) {
            // The strokes cannot be measured without force data: abandon them.
            self.counters.aborted += 1;
            self.abandon_probe();
        }
        if self.mode != ServoMode::AwaitingEstimate {
            self.mode = ServoMode::Resuming;
        }
        self.last_stroke = SetpointOffset::default();
        self.track.resume_velocity_m_per_s = resume_velocity;
        let p = self.params.safe;
        self.safe = Some(SafeState {
            resume_velocity_m_per_s: resume_velocity,
            resume_a_omega_m_per_s: resume_a_omega,
            backoff_left_m: p.backoff_fraction * self.hybrid.params().preload_n
                / self.hybrid.hooke_stiffness(),
            good_for_s: 0.0,
        });
    }

    pub(super) fn leave_safe(&mut self) {
        let Some(s) = self.safe.take() else {
            return;
        };
        self.track.resume_velocity_m_per_s = s.resume_velocity_m_per_s;
        self.resume_a_omega = Some(s.resume_a_omega_m_per_s);
        self.track.stopped_s = 0.0;
        self.track.settled_s = 0.0;
        if self.mode != ServoMode::AwaitingEstimate {
            self.mode = ServoMode::Resuming;
        }
    }
}
