//! Where a process's (re)start spent its time: the supervisor's view of the restart (clean-up,
//! backoff, spawn) and the board's own phases from its start-up report.

use afs_shared::msg::BoardStartup;
use serde::{Deserialize, Serialize};

/// Where a (re)start's time went: the end of each phase in ms after its zero (the exit being
/// seen for a restart, the spawn for a first start); None: not reached, or not reported. The
/// board's own phases come from its start-up report (`msg::BoardStartup`), stamped on the
/// same monotonic clock.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Timeline {
    /// iceoryx2's dead-node clean-up, run by the supervisor when it saw the exit.
    pub cleaned_ms: Option<f64>,
    /// The backoff the restart policy chose (a duration).
    pub backoff_ms: Option<f64>,
    /// The new process spawned (fork and exec returned).
    pub spawned_ms: Option<f64>,
    /// Its `main` entered.
    pub main_ms: Option<f64>,
    /// Its iceoryx2 node created.
    pub node_ms: Option<f64>,
    /// Its services and ports open.
    pub ports_ms: Option<f64>,
    /// Its own preparation done (sensor model and tare, the servo's world restored).
    pub prepared_ms: Option<f64>,
    /// Its first input in hand (the sensor's first world sample, the servo's first force).
    pub input_ms: Option<f64>,
    /// Its real-time set-up done (mlockall, pinning, SCHED_FIFO).
    pub rt_ms: Option<f64>,
    /// Its first output published.
    pub data_ms: Option<f64>,
    /// The supervisor saw that output.
    pub seen_ms: Option<f64>,
}

impl Timeline {
    /// Milliseconds from `zero` to `t` (monotonic ns); None for 0 (a phase not stamped).
    pub(crate) fn ms(zero: u64, t: u64) -> Option<f64> {
        (t != 0).then_some((t as f64 - zero as f64) * 1e-6)
    }

    /// Fills the board's phases from its start-up report.
    pub(crate) fn board(&mut self, zero: u64, r: &BoardStartup) {
        self.main_ms = Self::ms(zero, r.main_ns);
        self.node_ms = Self::ms(zero, r.node_ns);
        self.ports_ms = Self::ms(zero, r.ports_ns);
        self.prepared_ms = Self::ms(zero, r.prepared_ns);
        self.input_ms = Self::ms(zero, r.input_ns);
        self.rt_ms = Self::ms(zero, r.rt_ns);
        self.data_ms = Self::ms(zero, r.data_ns);
    }
}
