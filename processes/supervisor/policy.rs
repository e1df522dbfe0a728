//! The supervisor's restart, backoff and stall policy, as pure functions of what happened to a
//! board (the stack file's `restart`, `max_restarts`, `backoff_ms`, `stall_ms`).

use crate::stack::Restart;
use afs_shared::msg::Board;
use std::time::{Duration, Instant};

/// A process whose data flowed this long came up healthy: its death is not a crash loop, and
/// its next restart waits the first backoff again.
pub const HEALTHY_AFTER: Duration = Duration::from_millis(250);

/// The backoff doubles with each death before a board came up healthy, up to this.
pub const MAX_BACKOFF: Duration = Duration::from_secs(2);

/// Whether a process that ended is started again: by its policy, while it has restarts left
/// (`restarts` so far, `allowed` in all).
pub fn restarts(policy: Restart, exited_ok: bool, restarts: u32, allowed: u32) -> bool {
    let wanted = match policy {
        Restart::Always => true,
        Restart::OnFailure => !exited_ok,
        Restart::Never => false,
    };
    wanted && restarts < allowed
}

/// The wait before a restart, and the crash-loop streak after it: a process that came up
/// healthy restarts after `first_ms`; one that died before, after `first_ms` doubled once per
/// death in a row, up to [`MAX_BACKOFF`].
pub fn backoff(first_ms: u64, streak: u32, healthy: bool) -> (Duration, u32) {
    let streak = if healthy { 0 } else { streak };
    let wait = Duration::from_millis(first_ms.saturating_mul(1 << streak.min(6))).min(MAX_BACKOFF);
    (wait, streak + 1)
}

/// How long a board may take before its data first flows: the servo waits for the sensor.
pub fn start_grace(board: Option<Board>) -> Duration {
    Duration::from_secs(if board == Some(Board::Servo) { 5 } else { 2 })
}

/// Since when a running board counts as silent: its newest data, the moment its data first
/// flowed (or its start, before that), or the moment the fault injector last let it go. A
/// board held frozen for longer than its stall limit and then thawed has been silent all that
/// time, but not of its own doing: its limit starts again when it is let go.
pub fn silent_since(
    last_data: Instant,
    flowing_since: Option<Instant>,
    started: Instant,
    released: Option<Instant>,
) -> Instant {
    let from = last_data.max(flowing_since.unwrap_or(started));
    released.map_or(from, |r| from.max(r))
}

/// Whether a running board is alive but stalled: silent for longer than its `stall` limit
/// (zero: never), counted from its newest data or the moment its data first flowed; before
/// its data flows, only once its start-up grace is over. A board held on purpose (frozen by
/// the fault injector) is not stalled.
pub fn stalled(
    stall: Duration,
    silent_for: Duration,
    flowing: bool,
    up_for: Duration,
    grace: Duration,
    held: bool,
) -> bool {
    !stall.is_zero() && !held && (flowing || up_for > grace) && silent_for > stall
}
