//! Soaks: many random kills of the boards in one run, every fault recovered and nothing lost
//! or leaked.

use super::{assert_back_in_time, assert_correct, chaos, chaos_of, faults_of};
use crate::common::*;

/// 10 random SIGKILLs of servo, sensor and estimator in 12 simulated seconds, the density of
/// the long soak below: every fault recovered, the world resumed each time (every tick once,
/// none lost or reordered, at most one servo sample lost per servo kill), no file of a dead
/// process left in /dev/shm, the supervisor's heap and the boards' memory flat, and nothing
/// left at the end.
#[test]
fn soak_ten_random_kills() {
    soak("soak", 10, 12);
}

/// The long soak, a long check outside the test command (docs/testing.md): 50 random kills in
/// one simulated minute (the README's soak spreads them over two), the same assertions.
/// `.ci/test --run-ignored only -E 'test(soak_fifty)'`
#[test]
#[ignore = "a long check (about 70 s): .ci/test --run-ignored only -E 'test(soak_fifty)'"]
fn soak_fifty_random_kills() {
    soak("soak50", 50, 60);
}

/// `kills` random kills of servo, sensor and estimator in `duration_s` of surface tracking at
/// seed 11, and every assertion of the soak.
fn soak(tag: &str, kills: u64, duration_s: u64) {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix(tag);
    let (duration, n) = (duration_s.to_string(), kills.to_string());
    let (out, r) = chaos(
        &p,
        &[
            "--scenario",
            "surface-tracking",
            "--duration",
            &duration,
            "--kills",
            &n,
            "--seed",
            "11",
            "--faults",
            "kill-servo,kill-sensor,kill-estimator",
        ],
    );
    assert_correct(&out, &r);
    let c = chaos_of(&r);
    assert_eq!(c.injected as u64, kills);
    for fault in &c.faults {
        assert_back_in_time(fault);
    }
    let s = &r.samples;
    assert_eq!(
        (s.plant_received, s.plant_lost, s.reordered),
        (duration_s * 10_000 + 1, 0, 0),
        "{s:?}"
    );
    let servo_kills = faults_of(&r, "kill-servo").len() as u64;
    assert!(servo_kills > 0);
    let servo = process(&r, "servo");
    assert_eq!(
        u64::from(servo.restarts),
        servo_kills,
        "servo restarts against kill-servo faults; its exits: {:#?}\nstderr: {}",
        servo.exits,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(s.servo_lost <= servo_kills, "{s:?}");
    // Each restarted servo sends its predecessor's last tick once more; a repeat that had
    // arrived is dropped, never counted as received twice.
    assert!(s.plant_repeats_dropped <= servo_kills, "{s:?}");
    let (Some(before), Some(after)) = (&c.steady_before_first_fault, &c.steady_after_last_fault)
    else {
        panic!("no steady footprints: {c:?}");
    };
    assert!(after.stale_files.is_empty(), "{after:?}");
    assert_eq!(before.shm_files, after.shm_files);
    let grew = |a: u64, b: u64| a as f64 - b as f64;
    assert!(
        grew(
            after.supervisor_rss_kib.anon,
            before.supervisor_rss_kib.anon
        ) < 8192.0,
        "{c:?}"
    );
    assert!(
        grew(after.boards_rss_kib.anon, before.boards_rss_kib.anon).abs() < 8192.0,
        "{c:?}"
    );
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}
