//! The world snapshot the servo keeps in the supervisor's blackboard, for a restarted servo.

use super::samples::PlantSample;
use crate::servo::ServoState;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

/// The world's state the servo keeps in the supervisor's blackboard so that a restarted servo
/// resumes the world and its controller where they were (one entry per servo incarnation of
/// [`service::WORLD`](super::service::WORLD)).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::WorldSnapshot")]
#[repr(C)]
pub struct WorldSnapshot {
    /// [`VERSION`](super::VERSION); 0 means "no snapshot yet".
    pub version: u32,
    /// The scenario driver's leg (friction-id), u32::MAX if none.
    pub driver_leg: u32,
    /// Servo tick the snapshot was taken at; the restarted servo continues at `seq + 1`.
    pub seq: u64,
    /// Simulated time (s).
    pub time_s: f64,
    /// Joint angles (rad).
    pub q_rad: [f64; 2],
    /// Joint rates (rad/s).
    pub qd_rad_per_s: [f64; 2],
    /// Friction slots: face index (u64::MAX empty).
    pub friction_face: [u64; 2],
    /// Friction slots: bristle deflection (m).
    pub friction_deflection_m: [f64; 2],
    /// The driver's leg start: time (s) and surface position (m).
    pub driver_leg_start: [f64; 2],
    /// The controller ([`crate::servo::ServoCore::state`]): a restarted servo carries on
    /// with it.
    pub controller: ServoState,
    /// The world sample of tick `seq`, exactly as published (written before it is sent): a
    /// restarted servo sends it again, so the tick reaches subscribers whether or not its
    /// predecessor died before sending it; a subscriber drops the identical repeat.
    pub plant: PlantSample,
}
