//! Fault injection on the real binaries (`afs chaos`, and signals sent by the test itself):
//! killed and frozen boards, bad force samples, a killed supervisor, a soak of random kills
//! ([`soak`]). Each test
//! has its own prefix and leaves none of its shared memory behind; none asserts a run time.
//!
//! The tests assert mechanisms and correctness: every planned fault injected, every faulted
//! board back, nothing lost or reordered, no leak, counters equal, agreement with the lockstep
//! reference. The report's targets (safe within 2 ms, a sensor back within 500 ms, the normal
//! force within 2× the preload) are figures a loaded or stalled machine can miss: `afs chaos`
//! reports them and docs/reliability.md gives their distribution; here a time is only bounded
//! relative to the configured policy with an allowance a stalled VM cannot use up.

use afs::chaos::FaultRecord;
use afs::supervisor::RunReport;
use afs_shared::servo::ServoMode;
use std::process::Output;
use std::time::{Duration, Instant};

#[path = "../common/mod.rs"]
mod common;
mod soak;
use common::*;

/// `afs chaos ... --json` on its own prefix; returns the report (and asserts it is one).
fn chaos(p: &str, args: &[&str]) -> (Output, RunReport) {
    let out = afs()
        .args(["chaos", "--json", "--quiet", "--prefix", p])
        .args(args)
        .output()
        .unwrap();
    let r = run_report(&out);
    (out, r)
}

/// Every correctness check passed (the targets may be missed on a loaded machine: then the run
/// exits with 1, and that is all a missed target may change).
fn assert_correct(out: &Output, r: &RunReport) {
    let failed: Vec<String> = r
        .checks
        .iter()
        .filter(|c| !c.pass && !c.is_target())
        .map(|c| c.line())
        .collect();
    assert!(
        correct(out, r),
        "failed checks: {failed:?} (exit {:?})\nfaults: {:#?}\nprocesses: {:#?}\nstderr: {}",
        out.status.code(),
        r.chaos.as_ref().map(|c| &c.faults),
        r.processes,
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `afs run` has no targets: every check must pass.
fn assert_passed(out: &Output, r: &RunReport) {
    assert_correct(out, r);
    assert!(out.status.success() && r.passed, "{}", failed(r));
}

/// Time a restarted board may take beyond its backoff in these tests (ms): restarts take
/// 20–90 ms beyond it on an idle machine (docs/reliability.md); the allowance is for a VM that
/// stalls or a CI machine that is busy.
const RESTART_ALLOWANCE_MS: f64 = 3000.0;

/// Allowance over the servo's force-age limit (1.5 ms) for going safe in these tests (ms).
const SAFE_ALLOWANCE_MS: f64 = 10.0;

/// The fault came back within its backoff plus [`RESTART_ALLOWANCE_MS`].
fn assert_back_in_time(fault: &FaultRecord) {
    let backoff = fault
        .restart
        .and_then(|t| t.backoff_ms)
        .unwrap_or_else(|| panic!("no restart backoff: {fault:?}"));
    let back = fault
        .back_ms
        .unwrap_or_else(|| panic!("never back: {fault:?}"));
    let detected = fault.detected_ms.unwrap_or(0.0);
    assert!(
        back <= detected + backoff + RESTART_ALLOWANCE_MS,
        "back after {back} ms (backoff {backoff} ms): {fault:?}"
    );
}

/// The chaos part of a report.
fn chaos_of(r: &RunReport) -> &afs::chaos::ChaosReport {
    r.chaos.as_ref().expect("a chaos report")
}

/// The faults of one kind.
fn faults_of<'a>(r: &'a RunReport, kind: &str) -> Vec<&'a FaultRecord> {
    chaos_of(r)
        .faults
        .iter()
        .filter(|f| f.kind == kind)
        .collect()
}

/// The sensor killed at a random moment, killed while the servo dithers to probe (it asks for
/// the probe), and frozen: each time the servo goes safe (when it itself ran on time) within
/// its force-age limit plus an allowance, the normal force stays bounded, a killed sensor's
/// data is back within its backoff plus an allowance, the frozen one is found by the stall
/// policy and replaced, and the scenario agrees with its lockstep reference.
#[test]
fn sensor_killed_or_frozen_the_servo_stays_safe_and_recovers() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("sens");
    let (out, r) = chaos(
        &p,
        &[
            "--scenario",
            "surface-tracking",
            "--duration",
            "16",
            "--kills",
            "3",
            "--faults",
            "kill-sensor,kill-sensor-mid-probe,freeze-sensor",
            "--in-turn",
        ],
    );
    assert_correct(&out, &r);
    assert_eq!(chaos_of(&r).injected, 3);
    let fl = &r.faults;
    // Every fault sends the servo to its safe state; entries where the machine stalled the
    // servo itself are counted apart (docs/reliability.md).
    assert!(
        fl.safe_entries - fl.safe_entries_servo_stalled >= 1,
        "{fl:?}"
    );
    assert!(
        fl.safe_after_last_good_ms_max <= 1.5 + SAFE_ALLOWANCE_MS,
        "{fl:?}"
    );
    assert!(fl.normal_force_max_over_preload <= 3.0, "{fl:?}");
    for kind in ["kill-sensor", "kill-sensor-mid-probe", "freeze-sensor"] {
        let k = faults_of(&r, kind);
        assert_eq!(k.len(), 1, "{kind}");
        assert_back_in_time(k[0]);
    }
    let mid = faults_of(&r, "kill-sensor-mid-probe")[0];
    assert_eq!(
        mid.servo_mode,
        Some(ServoMode::Probing),
        "not killed while probing: {mid:?}"
    );
    let frozen = faults_of(&r, "freeze-sensor")[0];
    assert!(
        frozen.detected_ms.is_some_and(|d| d >= 100.0),
        "before the stall limit: {frozen:?}"
    );
    let sensor = process(&r, "sensor");
    assert_eq!(
        (sensor.restarts, sensor.stalls_killed),
        (3, 1),
        "{:#?}\n{}",
        sensor.exits,
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(r.stack.tracking.ticks_without_contact, 0);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// The estimator frozen while the servo probes and killed once the servo's request is in its
/// queue: the servo times out, re-sends to the restarted estimator, and gets a right tangent.
/// Then the estimator frozen for good: the stall policy kills and replaces it.
#[test]
fn estimator_killed_mid_request_answers_after_the_restart() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("est");
    let (out, r) = chaos(
        &p,
        &[
            "--scenario",
            "surface-tracking",
            "--duration",
            "20",
            "--kills",
            "2",
            "--faults",
            "kill-estimator-mid-request,freeze-estimator",
            "--in-turn",
        ],
    );
    assert_correct(&out, &r);
    let mid = faults_of(&r, "kill-estimator-mid-request")[0];
    assert_eq!(
        mid.servo_mode,
        Some(ServoMode::AwaitingEstimate),
        "not killed mid-request: {mid:?}"
    );
    // A probe the servo cut short (a VM stall put it in its safe state) sends no request: the
    // injector lets the estimator go and waits for the next probe, noting it; never thawed.
    assert!(!mid.thawed, "{mid:?}");
    let est = r.loop_stats.expect("loop statistics").estimator;
    assert!(est.retries >= 1 && est.answers >= 1, "{est:?}");
    let e = &r.stack.tracking.estimations;
    assert!(e.estimates >= 1 && e.failures == 0, "{e:?}");
    // The tangent after the retried estimate is as right as without the fault: the run's
    // tangent error is within 0.5° RMS of the fault-free lockstep reference's.
    let (t, reference) = (&r.stack.tracking, &r.reference.tracking);
    assert!(
        t.tangent_error_rms_deg <= reference.tangent_error_rms_deg + 0.5,
        "{t:?}\nreference: {reference:?}"
    );
    let frozen = faults_of(&r, "freeze-estimator")[0];
    assert!(frozen.detected_ms.is_some(), "{frozen:?}");
    let estimator = process(&r, "estimator");
    assert_eq!((estimator.restarts, estimator.stalls_killed), (2, 1));
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// Bursts of NaN, infinite, absurd, repeated, backwards and future force samples, with the
/// servo killed between them: the gate judges every one sent to the servo by its kind (the
/// counts cross the servo's restarts in the world snapshot), none reaches the controller as a
/// value, and the run still agrees with the lockstep reference (they change nothing).
#[test]
fn bad_samples_are_counted_and_never_reach_the_controller() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("bad");
    let (out, r) = chaos(
        &p,
        &[
            "--scenario",
            "surface-tracking",
            "--duration",
            "8",
            "--kills",
            "5",
            "--faults",
            "bad-samples,kill-servo",
            "--in-turn",
        ],
    );
    assert_correct(&out, &r);
    assert!(check(&r, "bad_samples_unjudged").pass);
    assert!(check(&r, "bad_samples_misjudged").pass);
    let bad = chaos_of(&r).bad_samples;
    let sent = bad.sent;
    let each = [
        sent.nan,
        sent.infinite,
        sent.absurd,
        sent.repeat,
        sent.backwards,
        sent.future,
    ];
    // Three bursts, each after a servo's data has flowed: every sample sent to a servo.
    assert_eq!(each, [3; 6], "{sent:?}");
    assert_eq!((bad.to_servo, bad.not_sent_to_servo), (sent, 0), "{bad:?}");
    assert_eq!(process(&r, "servo").restarts, 2);
    // The last servo's statistics hold the judgements of all three incarnations.
    let j = bad.judged_by_servo.expect("the servo's statistics");
    assert_eq!(j.judged(), 18, "{j:?}");
    assert_eq!((j.non_finite, j.out_of_range, j.future), (6, 3, 3), "{j:?}");
    assert_eq!(j.seq_repeat + j.seq_backwards + j.accepted, 6, "{j:?}");
    assert!(j.accepted <= sent.repeat, "{j:?}");
    let all = r.loop_stats.expect("loop statistics").bad_samples;
    assert!(all.non_finite >= 6 && all.out_of_range >= 3, "{all:?}");
    assert_eq!(r.faults.controller_non_finite, 0);
    assert!(r.faults.controller_force_max_abs_n < 130.0);
    assert!(r.agreement.agrees, "{:#?}", r.agreement);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// The supervisor SIGKILLed: its boards follow it (no child keeps running unsupervised), and
/// the next `afs run` on the prefix removes the dead stack's shared memory and runs.
#[test]
fn a_killed_supervisor_takes_its_boards_and_the_next_run_cleans_up() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("sup");
    let _clean = CleanPrefix(p.clone());
    let mut run = start_run(&p, &["--duration", "60"]);
    wait_running(&p, Duration::from_secs(60));
    let boards: Vec<i32> = ["servo", "sensor", "estimator"]
        .iter()
        .map(|b| board_pid(&p, b))
        .collect();
    // SAFETY: signalling our own child.
    unsafe {
        libc::kill(run.id() as i32, libc::SIGKILL);
    }
    let _ = run.0.as_mut().unwrap().wait();
    let setup = afs::supervisor::setup_dir(&p, run.id());
    assert!(setup.exists(), "{setup:?}: the killed supervisor's set-up");
    let alive = afs::procfs::alive;
    let t0 = Instant::now();
    while boards.iter().any(|&b| alive(b)) {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "boards still running without their supervisor: {:?}",
            boards.iter().filter(|&&b| alive(b)).collect::<Vec<_>>()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // What the dead supervisor left (the boards' nodes may already have removed some of it on
    // their way out) is removed by the next run on the prefix, which then runs.
    let out = afs()
        .args([
            "run",
            "--duration",
            "3",
            "--json",
            "--quiet",
            "--prefix",
            &p,
        ])
        .output()
        .unwrap();
    let r = run_report(&out);
    assert_passed(&out, &r);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
    assert!(!setup.exists(), "{setup:?} left");
}

/// The servo killed, frozen (SIGSTOP) and killed mid-probe: the stall policy finds the frozen
/// one, every restarted servo resumes the world and its controller (every tick of the run
/// exactly once, the normal force bounded right after each restart, the probe cut by the
/// restart run again), and the lockstep reference, restarted at the same ticks, agrees.
#[test]
fn servo_killed_or_frozen_resumes_the_world_and_its_controller() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("srv");
    let (out, r) = chaos(
        &p,
        &[
            "--scenario",
            "surface-tracking",
            "--duration",
            "10",
            "--kills",
            "3",
            "--faults",
            "kill-servo,freeze-servo,kill-servo-mid-probe",
            "--in-turn",
        ],
    );
    assert_correct(&out, &r);
    assert_eq!(chaos_of(&r).injected, 3);
    for kind in ["kill-servo", "freeze-servo", "kill-servo-mid-probe"] {
        let k = faults_of(&r, kind);
        assert_eq!(k.len(), 1, "{kind}");
        assert_back_in_time(k[0]);
    }
    let frozen = faults_of(&r, "freeze-servo")[0];
    assert!(
        frozen.detected_ms.is_some_and(|d| d >= 500.0),
        "before the stall limit: {frozen:?}"
    );
    let mid = faults_of(&r, "kill-servo-mid-probe")[0];
    assert_eq!(
        mid.servo_mode,
        Some(ServoMode::Probing),
        "not killed while probing: {mid:?}"
    );
    let servo = process(&r, "servo");
    assert_eq!((servo.restarts, servo.stalls_killed), (3, 1));
    let s = &r.samples;
    assert_eq!(
        (s.plant_received, s.plant_lost, s.reordered),
        (100_001, 0, 0),
        "{s:?}"
    );
    // Resumed, not restarted afresh: no transient of a controller that forgot its state.
    let preload = 2.5;
    assert!(
        r.faults.normal_force_max_after_servo_restart_n <= 2.0 * preload,
        "{:?}",
        r.faults
    );
    // The probe cut by the kill ran again from its start.
    assert!(r.stack.tracking.estimations.started >= 1);
    assert!(r.agreement.agrees, "{:#?}", r.agreement);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// The servo killed, then frozen, during an insertion (seed 1: while the peg aligns in the
/// hole at 1.7 s, and while it goes in at 3.6 s): each restarted servo resumes the rig from the
/// world snapshot (plant, controller, estimator), every tick runs once, the peg is in within
/// the force limit, and the reference agrees.
#[test]
fn a_servo_killed_mid_insertion_resumes_it() {
    killed_mid_insertion("pin", &SERVO_FAULTS, 10_000, &[]);
}

/// The same with the three-joint arm carrying the wrist (`[sim.insertion] drive = "arm"`) at
/// a real robot's 500 Hz, and the estimator killed after the servo's faults: the restarted
/// servo resumes the arm too (joints, their servos' integrals, the interpolator), and drops
/// its connections to the dead estimator within the stack's steady footprint (it checks them
/// by the clock; counted in ticks, every 1000 was every 2 s at 500 Hz and left them).
#[test]
fn a_servo_killed_mid_insertion_resumes_the_arm_at_500_hz() {
    let stack = StackWithArm::new("stack.toml", 500);
    let faults = ["kill-servo", "freeze-servo", "kill-estimator"];
    killed_mid_insertion("pia", &faults, 500, &["--config", stack.path()]);
}

/// The same on MuJoCo's peg and hole (examples/stack-mujoco.toml's world): the restarted
/// servo resumes MuJoCo's state of the peg (joints, rates, the solver's warm start), so the
/// stack still agrees with its MuJoCo lockstep.
#[cfg(feature = "mujoco")]
#[test]
fn a_servo_killed_mid_insertion_resumes_mujocos_peg() {
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/stack-mujoco.toml");
    killed_mid_insertion("pimj", &SERVO_FAULTS, 10_000, &["--config", config]);
}

/// The same on MuJoCo with the arm carrying the wrist at a real robot's 1 kHz: the
/// restarted servo resumes MuJoCo's peg and MuJoCo's arm (docs/insertion-mujoco.md, *MuJoCo's
/// arm*) from the snapshot, and the stack agrees with its MuJoCo lockstep.
#[cfg(feature = "mujoco")]
#[test]
fn a_servo_killed_mid_insertion_resumes_mujocos_arm_at_1_khz() {
    let stack = StackWithArm::new("stack-mujoco.toml", 1000);
    killed_mid_insertion("pimja", &SERVO_FAULTS, 1000, &["--config", stack.path()]);
}

/// A set-up file of the tests' own: examples/`base` with the arm drive and the servo at
/// `rate_hz`, removed when dropped (a failed test's too).
struct StackWithArm(std::path::PathBuf);

impl StackWithArm {
    fn new(base: &str, rate_hz: u64) -> Self {
        let name = format!("afs-{rate_hz}-arm-{}-{base}", std::process::id());
        let path = std::env::temp_dir().join(name);
        let base = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("examples")
            .join(base);
        let text = std::fs::read_to_string(base).unwrap()
            + &format!(
                "\n[sim.insertion]\ndrive = \"arm\"\n\n[sim.servo]\nrate_hz = {rate_hz}.0\n"
            );
        std::fs::write(&path, text).unwrap();
        Self(path)
    }

    fn path(&self) -> &str {
        self.0.to_str().unwrap()
    }
}

impl Drop for StackWithArm {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// The servo's two faults, in turn.
const SERVO_FAULTS: [&str; 2] = ["kill-servo", "freeze-servo"];

/// `faults` in turn during a 6-s insertion at seed 1 with the servo at `rate_hz` (that of the
/// set-up `extra` gives): the servo's faults during the insertion, every fault back in time,
/// the peg in, the lockstep agreement, every tick once, and no file left (a dead process's
/// after the last fault is a failed check of the report).
fn killed_mid_insertion(name: &str, faults: &[&str], rate_hz: u64, extra: &[&str]) {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix(name);
    let (kills, kinds) = (faults.len().to_string(), faults.join(","));
    let mut args = vec![
        "--scenario",
        "insertion",
        "--duration",
        "6",
        "--seed",
        "1",
        "--kills",
        &kills,
        "--faults",
        &kinds,
        "--in-turn",
    ];
    args.extend_from_slice(extra);
    let (out, r) = chaos(&p, &args);
    assert_correct(&out, &r);
    assert_eq!(chaos_of(&r).injected, faults.len());
    let run = r.stack.insertion.as_ref().expect("the insertion's figures");
    let (find, done) = (run.phase_starts_s[0], run.phase_starts_s[3]);
    for kind in faults {
        let f = faults_of(&r, kind);
        assert_eq!(f.len(), 1, "{kind}");
        assert_back_in_time(f[0]);
        let at = f[0].injected_at_s;
        assert!(
            !kind.ends_with("-servo")
                || find.is_some_and(|t| t < at) && done.is_none_or(|t| at < t),
            "{kind} at {at} s, not during the insertion {:?}",
            run.phase_starts_s
        );
    }
    assert_eq!(process(&r, "servo").restarts, 2);
    assert!(run.inserted, "{run:?}");
    assert!(r.agreement.agrees, "{:#?}", r.agreement);
    let s = &r.samples;
    assert_eq!(
        (s.plant_received, s.plant_lost, s.reordered),
        (6 * rate_hz + 1, 0, 0),
        "{s:?}"
    );
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// Bad `afs chaos` input: a clear message and exit status 2, never a panic or a hang.
#[test]
fn bad_chaos_input_is_refused_clearly() {
    let cases: [(&[&str], &str); 9] = [
        (&["chaos", "--faults", "kill-everything"], "unknown fault"),
        (&["chaos", "--kills", "100000"], "too many"),
        (
            &["chaos", "--duration", "2"],
            "at least 3 simulated seconds",
        ),
        (&["chaos", "--duration=-1"], "must be"),
        (&["chaos", "--kills", "-3"], "unexpected argument '-3'"),
        // Three mid-request kills need three whole probe runs: refused up front, naming the
        // shortest run that holds them.
        (
            &[
                "chaos",
                "--duration",
                "20",
                "--kills",
                "3",
                "--faults",
                "kill-estimator-mid-request",
            ],
            "use a duration of at least 36 s",
        ),
        (
            &["chaos", "--duration", "5", "--kills", "100"],
            "or fewer faults",
        ),
        (
            &[
                "chaos",
                "--scenario",
                "friction-id",
                "--faults",
                "kill-sensor-mid-probe",
            ],
            "needs a scenario that probes the tangent",
        ),
        // The built-in stack has no link board.
        (&["chaos", "--faults", "kill-link"], "needs the link board"),
    ];
    for (args, needle) in cases {
        let out = afs()
            .args(args)
            .args(["--prefix", &prefix("badc")])
            .output()
            .unwrap();
        assert_refused(&out, &args, needle);
    }
}
