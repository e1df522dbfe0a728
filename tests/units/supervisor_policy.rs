//! afs::supervisor::policy

use afs::stack::Restart;
use afs::supervisor::policy::*;
use afs_shared::msg::Board;
use std::time::{Duration, Instant};

/// The policies, and the restart budget.
#[test]
fn who_is_restarted() {
    assert!(restarts(Restart::Always, true, 0, 5));
    assert!(!restarts(Restart::OnFailure, true, 0, 5));
    assert!(restarts(Restart::OnFailure, false, 4, 5));
    assert!(!restarts(Restart::OnFailure, false, 5, 5));
    assert!(!restarts(Restart::Never, false, 0, 5));
}

/// Deaths before coming up healthy double the wait (20, 40, 80 … ms, at most 2 s); a death
/// after coming up healthy waits the first backoff again, whatever came before.
#[test]
fn the_backoff_doubles_only_in_a_crash_loop() {
    let mut streak = 0;
    let mut waits = Vec::new();
    for _ in 0..9 {
        let (w, s) = backoff(20, streak, false);
        waits.push(w.as_millis());
        streak = s;
    }
    assert_eq!(waits, [20, 40, 80, 160, 320, 640, 1280, 1280, 1280]);
    assert_eq!(backoff(500, 6, false).0, MAX_BACKOFF);
    let (w, s) = backoff(20, streak, true);
    assert_eq!((w.as_millis(), s), (20, 1));
}

/// Silent beyond the limit is a stall once the data has flowed, or once the start-up grace
/// is over; never while held, never without a limit.
#[test]
fn stalls_are_silence_beyond_the_limit() {
    let ms = Duration::from_millis;
    let grace = start_grace(Some(Board::Servo));
    assert_eq!(grace, Duration::from_secs(5));
    assert_eq!(start_grace(Some(Board::Sensor)), Duration::from_secs(2));
    assert!(stalled(ms(100), ms(101), true, ms(300), grace, false));
    assert!(!stalled(ms(100), ms(99), true, ms(300), grace, false));
    assert!(!stalled(ms(100), ms(101), true, ms(300), grace, true));
    assert!(!stalled(
        Duration::ZERO,
        ms(9_999),
        true,
        ms(300),
        grace,
        false
    ));
    // Starting: only after the grace.
    assert!(!stalled(ms(100), ms(4_000), false, ms(4_000), grace, false));
    assert!(stalled(ms(100), ms(5_100), false, ms(5_100), grace, false));
}

/// Silence counts from the newest of: the data, the flow's start (the start before it),
/// the injector's release of a frozen board.
#[test]
fn silence_starts_again_when_a_held_board_is_let_go() {
    let t0 = Instant::now();
    let s = Duration::from_secs;
    // Started at t0 + 1 s, data from t0 + 2 s, newest data at t0 (before both: the
    // supervisor's initial value).
    assert_eq!(silent_since(t0, None, t0 + s(1), None), t0 + s(1));
    assert_eq!(
        silent_since(t0, Some(t0 + s(2)), t0 + s(1), None),
        t0 + s(2)
    );
    assert_eq!(
        silent_since(t0 + s(3), Some(t0 + s(2)), t0, None),
        t0 + s(3)
    );
    // Frozen from t0 + 3 s (its last data) and let go at t0 + 10 s: silent from 10 s,
    // not 3 s (a 3-s stall limit would kill it the moment it is thawed).
    let r = silent_since(t0 + s(3), Some(t0 + s(2)), t0, Some(t0 + s(10)));
    assert_eq!(r, t0 + s(10));
    assert!(!stalled(
        s(3),
        (t0 + s(10)).duration_since(r),
        true,
        s(10),
        s(2),
        false
    ));
    // A release before its newest data changes nothing.
    assert_eq!(
        silent_since(t0 + s(3), None, t0, Some(t0 + s(1))),
        t0 + s(3)
    );
}
