//! afs::rt

use afs::rt::*;

/// A thread kept off CPU 0 runs on the others and reads back as pinned when one is left;
/// keeping off every CPU is refused with a warning, not done.
#[test]
fn avoiding_cpus_leaves_the_others() {
    let n = available_cpus();
    std::thread::spawn(move || {
        let all: Vec<usize> = (0..n).collect();
        assert!(avoid_cpus(&all).is_some_and(|w| w.contains("every CPU")));
        if n < 2 {
            return;
        }
        assert_eq!(avoid_cpus(&[0]), None);
        // SAFETY: gettid is a plain query.
        let tid = unsafe { libc::gettid() };
        if n == 2 {
            assert_eq!(pinned_cpu(tid), Some(1));
        } else {
            assert_eq!(pinned_cpu(tid), None);
        }
    })
    .join()
    .unwrap();
}

/// Absolute sleeps never return early and the clock moves forward.
#[test]
fn a_loop_moves_one_period_on_and_re_anchors_far_behind() {
    assert_eq!(next_deadline(1_000, 100, 1_050), 1_100);
    // 100 periods late is still caught up period by period ...
    assert_eq!(next_deadline(1_000, 100, 11_100), 1_100);
    // ... beyond that, the loop starts again one period after now.
    assert_eq!(next_deadline(1_000, 100, 11_101), 11_201);
}

#[test]
fn sleep_until_reaches_the_deadline() {
    let t0 = monotonic_ns();
    let deadline = t0 + 2_000_000;
    sleep_until(deadline);
    assert!(monotonic_ns() >= deadline);
    // A deadline in the past returns at once.
    sleep_until(t0);
}

/// A chore every 100 ms is due once per 100 ms of the clock, at any loop rate, and once
/// after a long stall.
#[test]
fn a_chore_is_due_by_the_clock_not_by_ticks() {
    for period_ns in [100_000u64, 1_000_000, 2_000_000] {
        let mut every = Every::new(100_000_000, 0);
        let due = (1..=1_000_000_000 / period_ns)
            .filter(|k| every.due(k * period_ns))
            .count();
        assert_eq!(due, 10, "at a period of {period_ns} ns");
    }
    let mut every = Every::new(100_000_000, 0);
    assert!(!every.due(99_999_999));
    assert!(every.due(5_000_000_000));
    assert!(!every.due(5_050_000_000));
    assert!(every.due(5_100_000_000));
}
