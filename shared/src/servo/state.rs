//! [`ServoState`]: everything the fast loop carries from one tick to the next, made of named
//! parts, each owned by the module that defines its behaviour (the joint servos, the hybrid
//! controller, the dither, the tuner, the tracker, the safe state). It is what a restarted
//! servo resumes from (the world snapshot, `msg::WorldSnapshot`).

use super::{EstimationCounters, SafeState, ServoCore, ServoMode, TrackState, Trigger};
use crate::arm::JointServoState;
use crate::dither::DitherState;
use crate::error::SnapshotError;
use crate::hybrid::{HybridState, SetpointOffset};
use crate::math::Vec2;
use crate::sensor::Wrench;
use crate::tuner::TunerState;
use crate::window::SlidingSummary;
use crate::wire::WireField;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use nalgebra::Vector2;
use serde::Serialize;

wire_flags! {
    /// [`ServoState::flags`].
    pub struct ServoStateFlags {
        /// On-line tuning on.
        const TUNING = 1;
        /// The normal force loop on.
        const FORCE_CONTROL = 2;
        /// The force trigger armed.
        const FORCE_ARMED = 4;
        /// In the safe state (the `safe` part holds it).
        const SAFE = 8;
        /// An Aω to restore when `Resuming` ends (`resume_a_omega_m_per_s`).
        const RESUME_A_OMEGA = 16;
        /// An accepted estimate so far (`last_estimate_rad`, `last_estimate_at_m`).
        const LAST_ESTIMATE = 32;
        /// The last estimate turned a corner: estimate once more `corner_confirm_m` on.
        const CONFIRM_CORNER = 64;
    }
}

wire_struct! {
    /// The sensor's zero-load reading the servo subtracts (a part of [`ServoState`]).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::TareState")]
    pub struct TareState {
        /// Force (N, sensor frame).
        pub force_n: [f64; 2],
        /// Moment (N·m).
        pub torque_nm: f64,
    }
}

impl From<Wrench> for TareState {
    fn from(w: Wrench) -> Self {
        Self {
            force_n: [w.force.x, w.force.y],
            torque_nm: w.torque,
        }
    }
}

impl From<&TareState> for Wrench {
    fn from(t: &TareState) -> Self {
        Wrench {
            force: Vec2::new(t.force_n[0], t.force_n[1]),
            torque: t.torque_nm,
        }
    }
}

wire_struct! {
    /// Everything the fast loop carries from one tick to the next, for a snapshot: a servo built
    /// with the same settings and start ([`ServoCore::new`]) and given this state
    /// ([`ServoCore::restore`]) carries on where the one that took it stopped. Two things come
    /// back in brief: the moving average of the normal force over a dither period (and the
    /// thesis tuner's friction window) keep their mean and variance, not their samples
    /// ([`SlidingSummary`]); and a probe run in progress, whose record is not kept, starts
    /// again from its beginning (stop, settle, strokes), as does one whose estimate was
    /// awaited.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::ServoState")]
    pub struct ServoState {
        /// [`ServoMode`] as its wire code.
        pub mode: u32,
        /// [`ServoStateFlags`].
        pub flags: ServoStateFlags,
        /// What started the last estimation: 0 none, else a [`Trigger`] code.
        pub last_trigger: u32,
        /// Consecutive ticks the normal force has been below the contact guard's threshold.
        pub contact_lost_ticks: u32,
        /// The tangent estimation's counters.
        pub counters: EstimationCounters,
        /// Joint servos.
        pub joints: JointServoState,
        /// Hybrid controller (task frame, set-points, force loop).
        pub hybrid: HybridState,
        /// Dither oscillator.
        pub dither: DitherState,
        /// Dither tuner.
        pub tuner: TunerState,
        /// The tracker's memory between estimations.
        pub track: TrackState,
        /// The safe state (valid with the `SAFE` flag).
        pub safe: SafeState,
        /// The sensor's zero-load reading in use.
        pub tare: TareState,
        /// Moving average of the normal force over a dither period, in brief.
        pub normal_window: SlidingSummary,
        /// Last reachable joint set-point (rad).
        pub last_q_d_rad: [f64; 2],
        /// Last accepted estimate: tangent angle (rad) ...
        pub last_estimate_rad: f64,
        /// ... and the total travel at it (m).
        pub last_estimate_at_m: f64,
        /// Aω to restore when `Resuming` ends (m/s; valid with `RESUME_A_OMEGA`).
        pub resume_a_omega_m_per_s: f64,
        /// The probe stroke commanded last tick (m, world), absorbed into the set-point if a
        /// probe run is restarted.
        pub last_stroke_m: [f64; 2],
        /// What the servo knows of its contact.
        pub contact: super::ContactState,
    }
}

impl ServoState {
    /// Checks that every number is finite and the codes are known (a snapshot that is not must
    /// not be restored).
    pub fn check(&self) -> Result<(), SnapshotError> {
        if !self.all_finite() {
            Err(SnapshotError::NotFinite)
        } else if ServoMode::try_from(self.mode).is_err()
            || (self.last_trigger != 0 && Trigger::try_from(self.last_trigger).is_err())
        {
            Err(SnapshotError::UnknownCode)
        } else {
            Ok(())
        }
    }
}

impl ServoCore {
    /// Everything it carries from tick to tick ([`ServoState`]).
    pub fn state(&self) -> ServoState {
        let mut flags = ServoStateFlags::empty();
        flags.set(ServoStateFlags::TUNING, self.tuning);
        flags.set(ServoStateFlags::FORCE_CONTROL, self.force_control);
        flags.set(ServoStateFlags::FORCE_ARMED, self.force_armed);
        flags.set(ServoStateFlags::SAFE, self.safe.is_some());
        flags.set(
            ServoStateFlags::RESUME_A_OMEGA,
            self.resume_a_omega.is_some(),
        );
        flags.set(ServoStateFlags::LAST_ESTIMATE, self.last_estimate.is_some());
        flags.set(ServoStateFlags::CONFIRM_CORNER, self.confirm_corner);
        let (last_estimate_rad, last_estimate_at_m) = self.last_estimate.unwrap_or((0.0, 0.0));
        ServoState {
            mode: self.mode.into(),
            flags,
            last_trigger: self.last_trigger.map_or(0, u32::from),
            contact_lost_ticks: self.contact_lost_ticks,
            counters: self.counters,
            joints: self.joint_state(),
            hybrid: self.hybrid.state(),
            dither: self.dither.state(),
            tuner: self.tuner.state(),
            track: self.track,
            safe: self.safe.unwrap_or_default(),
            tare: self.tare.into(),
            normal_window: self.normal_window.summary(),
            last_q_d_rad: self.last_q_d(),
            last_estimate_rad,
            last_estimate_at_m,
            resume_a_omega_m_per_s: self.resume_a_omega.unwrap_or(0.0),
            last_stroke_m: [
                self.last_stroke.displacement.x,
                self.last_stroke.displacement.y,
            ],
            contact: self.contact_state(),
        }
    }

    /// Carries on from a state taken by [`ServoCore::state`] of a servo with the same settings
    /// and start. A probe run in progress, or one whose estimate was awaited, starts again from
    /// its beginning: its record is not in the state, and an answer to it would go to the
    /// process that asked. Refuses (and changes nothing) a state with a non-finite number or an
    /// unknown code.
    pub fn restore(&mut self, st: &ServoState) -> Result<(), SnapshotError> {
        st.check()?;
        let mode = ServoMode::try_from(st.mode).unwrap_or_default();
        let has = |f: ServoStateFlags| st.flags.contains(f);
        self.counters = st.counters;
        self.contact_lost_ticks = st.contact_lost_ticks;
        if let super::drive::Drive::TwoLink(two) = &mut self.drive {
            two.pid.restore(&st.joints);
            two.last_q_d = Vector2::new(st.last_q_d_rad[0], st.last_q_d_rad[1]);
        }
        self.hybrid.restore(&st.hybrid);
        self.restore_contact(&st.contact);
        self.dither.restore(&st.dither);
        self.tuner.restore(&st.tuner);
        self.track = st.track;
        self.safe = has(ServoStateFlags::SAFE).then_some(st.safe);
        self.tare = (&st.tare).into();
        self.normal_window.refill(&st.normal_window);
        self.tuning = has(ServoStateFlags::TUNING);
        self.force_control = has(ServoStateFlags::FORCE_CONTROL);
        self.force_armed = has(ServoStateFlags::FORCE_ARMED);
        self.confirm_corner = has(ServoStateFlags::CONFIRM_CORNER);
        self.last_trigger = Trigger::try_from(st.last_trigger).ok();
        self.last_estimate = has(ServoStateFlags::LAST_ESTIMATE)
            .then_some((st.last_estimate_rad, st.last_estimate_at_m));
        self.resume_a_omega =
            has(ServoStateFlags::RESUME_A_OMEGA).then_some(st.resume_a_omega_m_per_s);
        self.last_stroke = SetpointOffset::default();
        self.probe.reset();
        self.reprobe = false;
        self.mode = mode;
        if matches!(mode, ServoMode::Probing | ServoMode::AwaitingEstimate) {
            // The arm stands where the last stroke took it: keep the set-point there, and probe
            // again from the start (stop, settle, strokes).
            if mode == ServoMode::Probing {
                self.hybrid
                    .absorb_offset(Vec2::new(st.last_stroke_m[0], st.last_stroke_m[1]));
            }
            self.track.stopped_s = 0.0;
            self.track.settled_s = 0.0;
            self.mode = ServoMode::Stopping;
        }
        Ok(())
    }
}

impl ServoCore {
    /// The two-link arm's joint servos' state (zeros on a task-space drive, which has none).
    fn joint_state(&self) -> JointServoState {
        match &self.drive {
            super::drive::Drive::TwoLink(two) => two.pid.state(),
            super::drive::Drive::Task(_) => JointServoState::default(),
        }
    }

    /// The two-link arm's last reachable joint set-point (rad; zeros on a task-space drive).
    fn last_q_d(&self) -> [f64; 2] {
        match &self.drive {
            super::drive::Drive::TwoLink(two) => [two.last_q_d[0], two.last_q_d[1]],
            super::drive::Drive::Task(_) => [0.0; 2],
        }
    }
}
