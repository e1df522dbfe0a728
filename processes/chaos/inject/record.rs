//! What the injector sees of the stack ([`ServoView`], [`BoardView`]), what it asks the
//! supervisor to do ([`Action`]), and the record of each fault as it went ([`FaultRecord`]):
//! chaos's own types, which the supervisor fills in and reports.

use crate::stack::Timeline;
use afs_shared::faults::Board;
use afs_shared::servo::ServoMode;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// What the supervisor knows of the servo's controller, from its newest sample.
#[derive(Debug, Clone, Copy, Default)]
pub struct ServoView {
    /// Its mode (None before the first sample, or an unknown code).
    pub mode: Option<ServoMode>,
    /// Estimations it has started.
    pub started: u32,
}

/// What the supervisor knows of a board.
#[derive(Debug, Clone, Copy, Default)]
pub struct BoardView {
    /// Its pid (0: none running).
    pub pid: i32,
    /// When the current process's data started to flow (sensor: its first wrench sample;
    /// servo: its first world tick, a restarted one's first new tick; estimator: its ports
    /// open, from its start-up report).
    pub data_since: Option<Instant>,
    /// The supervisor kills it when silent (`stall_ms` > 0).
    pub stall_policy: bool,
}

/// What the supervisor is asked to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Send a signal to the board's process.
    Signal(Board, i32),
    /// Exempt the board from the stall policy (the injector holds it frozen on purpose) or not;
    /// the supervisor lifts the hold when the process ends.
    Hold(Board, bool),
    /// Ask the servo to estimate the tangent (stop, probe), unless more than `started_before`
    /// estimations have started by the time it can.
    AskProbe {
        /// The servo's estimations started, as last seen.
        started_before: u32,
    },
    /// Send a signal to the link board.
    SignalLink(i32),
    /// Cut the link (true) or restore it (false) with the stack file's commands.
    CutLink(bool),
}

/// One fault as it went.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FaultRecord {
    /// The kind's name.
    pub kind: String,
    /// Planned simulated time (s).
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub due_s: f64,
    /// Simulated time of the injection (s).
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub injected_at_s: f64,
    /// Wall time of the injection since the stack started (s).
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub wall_s: f64,
    /// The process signalled.
    pub pid: i32,
    /// The servo's mode at the injection.
    pub servo_mode: Option<ServoMode>,
    /// Probes the injector asked the servo for, for this fault.
    pub probes_asked: u32,
    /// A frozen board: time until the supervisor's stall policy killed it (ms).
    pub detected_ms: Option<f64>,
    /// Time from the fault to the board's data flowing again (ms).
    pub back_ms: Option<f64>,
    /// Frozen and let go again (SIGCONT), not killed: nothing to come back.
    pub thawed: bool,
    /// Anything unusual.
    pub note: String,
    /// Where the faulted board's restart spent its time (from the supervisor's exit record of
    /// `pid`).
    pub restart: Option<Timeline>,
}
