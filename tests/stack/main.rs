//! The multi-process stack, started through the real binaries: `afs run` launches servo,
//! sensor and estimator over iceoryx2, reports figures that agree with the lockstep
//! reference, serves a client in another language, refuses a second stack on its prefix, and
//! leaves no shared memory behind.
//!
//! Stack tests run one at a time (a lock) with their own prefixes; none asserts a run time.

use afs_shared::msg::ProcessState;
use serde_json::Value;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

#[path = "../common/mod.rs"]
mod common;
use common::*;

mod clients;
mod estimator;

/// `afs run --scenario surface-tracking --duration 10 --json`: one JSON object whose tangent
/// error and force regulation agree with the lockstep reference, with the servo's loop
/// statistics (wake jitter and force age percentiles), every tick of 10 s run at 10 kHz and
/// joined, every check with a snake-case identifier of its own, and nothing of the prefix
/// left in /dev/shm or the iceoryx2 root.
#[test]
fn surface_tracking_across_processes_agrees_with_the_lockstep() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("st");
    let out = afs()
        .args(["run", "--scenario", "surface-tracking", "--duration", "10"])
        .args(["--json", "--quiet", "--prefix", &p])
        .output()
        .unwrap();
    let r = run_report(&out);
    assert!(
        out.status.success(),
        "afs run failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        failed(&r)
    );
    assert!(r.passed && r.finished);
    assert_eq!(r.end, afs::supervisor::RunEnd::Finished);
    let ids: std::collections::BTreeSet<&str> = r.checks.iter().map(|c| c.id.as_str()).collect();
    assert_eq!(
        ids.len(),
        r.checks.len(),
        "an identifier twice: {:?}",
        r.checks
    );
    assert!(
        ids.iter().all(|i| afs_shared::check::is_snake_case(i)),
        "{ids:?}"
    );
    assert!(check(&r, "reached_end").pass);
    assert!(r.agreement.agrees, "{:#?}", r.agreement);
    assert_eq!(r.stack.ticks, 100_000);
    assert_eq!(r.samples.plant_lost, 0);
    assert_eq!(r.samples.reordered, 0);
    let l = r.loop_stats.expect("the servo's loop statistics");
    // SCHED_FIFO, mlockall and pinning where permitted; where refused (not root) the run still
    // passes, and the servo said why.
    let err = String::from_utf8_lossy(&out.stderr);
    for (granted, refusal) in [
        (l.sched_fifo, "afs-servo: warning: SCHED_FIFO"),
        (l.mlocked, "afs-servo: warning: mlockall"),
        (l.pinned, "afs-servo: warning: pinning"),
    ] {
        assert!(granted || err.contains(refusal), "no '{refusal}' in: {err}");
    }
    let yes = |on: bool| if on { "granted" } else { "refused, said why" };
    say(&format!(
        "the servo's real-time set-up: SCHED_FIFO {}, mlockall {}, pinning {}",
        yes(l.sched_fifo),
        yes(l.mlocked),
        yes(l.pinned)
    ));
    let w = l.wake_jitter_us;
    for q in [w.p50, w.p99, w.p99_9, w.max] {
        assert!(q.is_finite() && q >= 0.0, "wake jitter {w:?}");
    }
    // The force age is the machine's (reported, measured by `afs bench`); its percentiles
    // must be positive (a sample is never used before it was taken) and in order.
    let a = l.force_age_us;
    assert!(
        0.0 < a.p50 && a.p50 <= a.p99 && a.p99 <= a.p99_9,
        "force age {a:?} µs"
    );
    assert_eq!(l.ticks, 100_000);
    assert!(r.stack.tracking.tangent_error_rms_deg < 1.0);
    // What the servo knew of its contact, from its last snapshot: the gains for the configured
    // 10 kN/m, kept (docs/contact.md), and a fit of that contact.
    let c = r.contact.expect("the servo's contact report");
    assert_eq!((c.stiffness_in_use_n_per_m, c.adoptions), (10e3, 0));
    let fitted = c.fitted_n_per_m.expect("a stiffness fit");
    assert!(fitted > 2e3 && fitted < 4e4, "fitted {fitted} N/m");
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// `afs run --scenario insertion --json`: the servo runs the insertion's rig across the
/// processes (the sensor board samples the peg's wrench on its own clock), the peg is in
/// within the force limit, the figures agree with the lockstep reference (which is `afs
/// experiment insertion` at the same seed), every tick of the 10-s time limit runs once, and
/// nothing of the prefix is left.
#[test]
fn the_insertion_across_processes_agrees_with_the_lockstep() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("ins");
    let mcap = std::env::temp_dir().join(format!("afs-insertion-{p}.mcap"));
    let out = afs()
        .args(["run", "--scenario", "insertion", "--seed", "2"])
        .args(["--json", "--quiet", "--prefix", &p, "--record"])
        .arg(&mcap)
        .output()
        .unwrap();
    let r = run_report(&out);
    assert!(
        out.status.success() && r.passed,
        "afs run failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        failed(&r)
    );
    assert!(r.agreement.agrees, "{:#?}", r.agreement);
    let (stack, reference) = (
        r.stack.insertion.as_ref().expect("the stack's insertion"),
        r.reference.insertion.as_ref().expect("the reference's"),
    );
    assert!(
        stack.inserted && reference.inserted,
        "{stack:?} {reference:?}"
    );
    assert!(check(&r, "state_classification_accuracy").pass);
    // It runs to the time limit, holding at depth once in; the insertion's figures stop at
    // the depth.
    assert_eq!((r.stack.ticks, stack.ticks), (100_000, 100_000));
    assert!(stack.phase_starts_s[3].is_some_and(|t| t < 10.0));
    assert_eq!((r.samples.plant_lost, r.samples.reordered), (0, 0));
    // The recording has the insertion's display record of every tick (the Foxglove layout's
    // insertion panels read it).
    let rec = r.record.as_ref().expect("the recording's summary");
    assert_eq!(rec.messages.get("/insertion"), Some(&100_000), "{rec:?}");
    std::fs::remove_file(&mcap).unwrap();
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// `afs record` attached to a running insertion from outside records the insertion's display
/// record (`/insertion`) beside the other topics, from the first supervisor status on.
#[test]
fn afs_record_attached_to_an_insertion_records_it() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("inr");
    let run = start_run(&p, &["--scenario", "insertion", "--duration", "4"]);
    wait_running(&p, Duration::from_secs(60));
    let mcap = std::env::temp_dir().join(format!("afs-insertion-attached-{p}.mcap"));
    let out = afs()
        .args(["record", "--json", "--prefix", &p, "--out"])
        .arg(&mcap)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rec: Value = serde_json::from_slice(&out.stdout).unwrap();
    let messages = &rec["recording"]["messages"];
    let n = messages["/insertion"].as_u64().unwrap_or(0);
    assert!(n > 1000, "{rec:#}");
    assert!(n <= messages["/plant"].as_u64().unwrap(), "{rec:#}");
    finish_passed(run.take(), "afs run");
    std::fs::remove_file(&mcap).unwrap();
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// Ctrl-C (SIGINT to the supervisor) stops the stack in order, reports what ran, and leaves
/// no file of the prefix behind.
#[test]
fn ctrl_c_stops_the_stack_and_cleans_up() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("cc");
    let _clean = CleanPrefix(p.clone());
    let run = start_run(&p, &["--duration", "60"]);
    wait_running(&p, Duration::from_secs(20));
    // SAFETY: signalling our own child.
    unsafe {
        libc::kill(run.id() as i32, libc::SIGINT);
    }
    let out = finish(run.take(), "afs run");
    let r = run_report(&out);
    assert!(r.interrupted);
    assert_eq!(
        out.status.code(),
        Some(1),
        "an interrupted scenario is not a pass"
    );
    assert!(r.stack.ticks > 1000);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
    assert!(r.cleanup.left.is_empty(), "{:?}", r.cleanup.left);
}

/// A run the wall-time limit stops before its scenario's end fails, naming the check, and
/// still stops its boards in order and cleans up.
#[test]
fn a_run_stopped_by_the_wall_time_limit_fails_by_name() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("wl");
    let _clean = CleanPrefix(p.clone());
    let out = afs()
        .args(["run", "--json", "--quiet", "--prefix", &p])
        .args(["--duration", "60", "--wall-limit-s", "3"])
        .output()
        .unwrap();
    let r = run_report(&out);
    assert_eq!(out.status.code(), Some(1), "{}", failed(&r));
    assert!(!r.passed && !r.finished && !r.interrupted);
    assert_eq!(r.end, afs::supervisor::RunEnd::WallLimit);
    let c = check(&r, "reached_end");
    assert!(!c.pass, "{c:?}");
    assert!(c.name.contains("wall-time limit"), "{c:?}");
    assert!(failed(&r).contains("wall-time limit"), "{}", failed(&r));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("wall-time limit"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(r.stack.ticks > 0);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// A client built for the servo state's first layout (version 1, 208 bytes), written from the
/// earlier docs/messages.md.
const OLD_CLIENT: &str = r#"
import ctypes, sys, time
from afs_client import subscribe
class ServoSample(ctypes.Structure):
    _fields_ = [("raw", ctypes.c_uint64 * 26)]
    @staticmethod
    def type_name():
        return "afs::ServoSample"
opened = subscribe(sys.argv[1], "afs/servo/state", ServoSample, time.monotonic() + 20)
sys.exit(2 if opened is None else 0)
"#;

/// A client built for an older layout of the servo's state is refused at once, naming both
/// versions; a Python client still subscribed when the run ends is an observer: the run
/// passes, names it and the service it reads, and leaves its files alone. The scenario is the
/// corner (the surface-tracking scenario's other stack tests cover the flat surface).
#[test]
fn an_old_client_is_refused_and_one_attached_at_the_end_is_an_observer() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("obs");
    let _clean = CleanPrefix(p.clone());
    let python = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/python");
    let run = start_run(&p, &["--scenario", "corner", "--duration", "8"]);
    wait_running(&p, Duration::from_secs(60));
    let old = Command::new("python3")
        .args(["-c", OLD_CLIENT, &p])
        .env("PYTHONPATH", &python)
        .output()
        .expect("python3 is needed for this test");
    let err = String::from_utf8_lossy(&old.stderr);
    assert_eq!(old.status.code(), Some(2), "{err}");
    for needle in [
        "afs::ServoSample.v3 (layout version 3, 232 bytes)",
        "afs::ServoSample (layout version 1, 208 bytes)",
    ] {
        assert!(err.contains(needle), "{err}");
    }
    let mut client = KillOnDrop(Some(
        Command::new("python3")
            .arg(python.join("servo_subscriber.py"))
            .args(["--prefix", &p, "--count", "100000000", "--timeout", "600"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    ));
    let out = finish(run.take(), "afs run");
    let r = run_report(&out);
    assert!(
        out.status.success() && r.passed,
        "{}\n{}",
        failed(&r),
        String::from_utf8_lossy(&out.stderr)
    );
    let obs = &r.cleanup.observers;
    assert!(
        obs.iter().any(|o| o.name == "servo_subscriber.py"
            && o.pid == client.id() as i32
            && o.services.iter().any(|s| s == "afs/servo/state")),
        "{obs:?} (client {})",
        client.id()
    );
    assert!(r.cleanup.left.is_empty(), "{:?}", r.cleanup.left);
    assert!(String::from_utf8_lossy(&out.stdout).contains("servo_subscriber.py"));
    if let Some(c) = client.0.as_mut() {
        let _ = c.kill();
        let _ = c.wait();
    }
}

/// Bad input gets one clear line and exit status 2, never a panic or a hang.
/// Stack files with a `[robot]` table, in `dir`: a valid one naming a loopback port where
/// nothing listens (the robot does not answer), one whose tool transform is not rigid, and
/// one whose plane lies 0.25 m farther out, its workspace box's far corners out of the arm's
/// reach.
fn robot_tables(dir: &Path) -> [std::path::PathBuf; 3] {
    // A [robot] table: a tool transform that is not rigid is named; a valid table naming a
    // loopback port where nothing listens is refused because the robot does not answer.
    let closed = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let robot = |tip: &str| {
        format!(
            "{}\n[robot]\nkind = \"franka\"\naddress = \"{closed}\"\n[robot.task_frame]\n\
                 origin_m = [0.45, 0.0, 0.2]\nx_axis = [1.0, 0.0, 0.0]\nnormal = [0.0, 0.0, 1.0]\n\
                 [robot.tool]\nflange_to_tip = [{tip}]\nmass_kg = 0.7\n",
            afs::stack::DEFAULT_STACK
        )
    };
    let identity = "1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.1, 1.0";
    let sheared = identity.replacen("0.0", "0.3", 1);
    let robot_ok = dir.join("robot.toml");
    std::fs::write(&robot_ok, robot(identity)).unwrap();
    let robot_bad = dir.join("robot-bad.toml");
    std::fs::write(&robot_bad, robot(&sheared)).unwrap();
    // The plane 0.25 m farther out: its workspace box's far corners are out of the arm's reach.
    let robot_far = dir.join("robot-far.toml");
    std::fs::write(
        &robot_far,
        robot(identity).replace("origin_m = [0.45,", "origin_m = [0.70,"),
    )
    .unwrap();
    [robot_ok, robot_bad, robot_far]
}

#[test]
fn bad_input_is_refused_clearly() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = std::env::temp_dir().join(format!("afs-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad_toml = dir.join("bad.toml");
    std::fs::write(&bad_toml, "prefix = \"x\"\nscenario = 3\n").unwrap();
    let contradictory = dir.join("contradictory.toml");
    std::fs::write(
        &contradictory,
        afs::stack::DEFAULT_STACK.replace("name = \"sensor\"", "name = \"servo\""),
    )
    .unwrap();
    let bare = dir.join("bare.toml");
    std::fs::write(&bare, "[servo]\ninertia_feedforward = false\n").unwrap();
    let [robot_ok, robot_bad, robot_far] = robot_tables(&dir);
    let missing_bin = dir.join("missing.toml");
    // A board that cannot start fails the run after the prefix was claimed: it is given back.
    let missing_prefix = prefix("nobin");
    std::fs::write(
        &missing_bin,
        afs::stack::DEFAULT_STACK
            .replace("binary = \"afs-sensor\"", "binary = \"afs-nope\"")
            .replace(
                "prefix = \"afs\"",
                &format!("prefix = \"{missing_prefix}\""),
            ),
    )
    .unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["run".into(), "--scenario".into(), "nope".into()],
            "unknown scenario",
        ),
        (vec!["run".into(), "--duration=-3".into()], "must be"),
        (
            vec!["run".into(), "--wall-limit-s".into(), "0".into()],
            "wall_limit_s",
        ),
        (
            vec!["run".into(), "--duration".into(), "1e9".into()],
            "duration_s",
        ),
        (
            vec!["run".into(), "--prefix".into(), "a/b".into()],
            "invalid stack prefix",
        ),
        (
            vec![
                "run".into(),
                "--config".into(),
                "/nonexistent/stack.toml".into(),
            ],
            "reading stack file",
        ),
        (
            vec![
                "run".into(),
                "--config".into(),
                bad_toml.display().to_string(),
            ],
            "parsing stack file",
        ),
        (
            vec![
                "run".into(),
                "--config".into(),
                contradictory.display().to_string(),
            ],
            "listed twice",
        ),
        (
            vec![
                "run".into(),
                "--config".into(),
                missing_bin.display().to_string(),
            ],
            "not found",
        ),
        (
            vec![
                "run".into(),
                "--config".into(),
                robot_bad.display().to_string(),
            ],
            "flange_to_tip is not a rigid transform",
        ),
        (
            vec![
                "run".into(),
                "--config".into(),
                robot_far.display().to_string(),
            ],
            "the FR3 cannot put the tool at x = 0.15 m",
        ),
        (
            vec![
                "run".into(),
                "--config".into(),
                robot_ok.display().to_string(),
            ],
            "the robot does not answer",
        ),
        (
            vec!["run".into(), "--rate-hz".into(), "0".into()],
            "--rate-hz 0 must be",
        ),
        (
            vec!["run".into(), "--mjcf".into(), "/nonexistent/arm.xml".into()],
            "no such model",
        ),
        (
            vec![
                "experiment".into(),
                "fig4.1".into(),
                "--config".into(),
                bare.display().to_string(),
            ],
            "belongs under [sim]",
        ),
        (
            vec!["status".into(), "--prefix".into(), prefix("none")],
            "no stack with prefix",
        ),
        (
            vec!["plot".into(), "/nonexistent.mcap".into()],
            "reading recording",
        ),
    ];
    for (args, needle) in cases {
        let out = afs().args(&args).output().unwrap();
        assert_refused(&out, &args, needle);
    }
    assert!(
        leftovers(&missing_prefix).is_empty(),
        "{:?}",
        leftovers(&missing_prefix)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `afs bench robot` without a robot to hold: one line naming what to give, exit 2.
#[test]
fn bench_robot_without_a_robot_is_refused() {
    let stack = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/stack.toml");
    for (args, needle) in [
        (
            vec!["bench", "robot"],
            "afs bench robot needs --config FILE",
        ),
        (
            vec!["bench", "robot", "--config", stack],
            "has no [robot] table",
        ),
    ] {
        let out = afs().args(&args).output().unwrap();
        assert_refused(&out, &args, needle);
    }
}

/// SIGKILL of the sensor, then of the servo, in a running surface-tracking stack: the
/// supervisor restarts both, the restarted servo resumes the world from the blackboard (every
/// tick of 12 s is run once, no world sample lost or reordered) and its controller, the
/// scenario still passes and agrees with its lockstep reference (restarted at the same tick),
/// and nothing of the prefix is left.
#[test]
fn killed_boards_are_restarted_and_the_world_resumes() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("kill");
    let _clean = CleanPrefix(p.clone());
    let run = start_run(&p, &["--scenario", "surface-tracking", "--duration", "12"]);
    wait_running(&p, Duration::from_secs(60));
    for board in ["sensor", "servo"] {
        kill_board_and_wait_restart(&p, board);
        std::thread::sleep(Duration::from_secs(1));
    }
    let r = finish_passed(run.take(), "afs run");
    assert_eq!(process(&r, "sensor").restarts, 1);
    assert_eq!(process(&r, "servo").restarts, 1);
    // Every world tick once (plus the initial sample 0); a servo killed between publishing a
    // tick's world sample and its servo sample loses that one servo sample.
    let s = &r.samples;
    assert_eq!(s.plant_received, 120_001, "{s:?}");
    assert_eq!(s.plant_lost, 0, "{s:?}");
    assert!(s.servo_lost <= 1, "{s:?}");
    assert_eq!(s.reordered, 0);
    // The restarted servo resumed its controller too, and the reference restarted its servo
    // at the same tick: the agreement is one of the run's checks, and it held.
    assert!(check(&r, "lockstep_agreement").pass, "{:#?}", r.agreement);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// A stack whose tool starts 0.5 mm off a 100 kN/m surface: the servo approaches, touches,
/// learns the contact (its gains were the approach's assumption, docs/contact.md *First
/// touch*) and tracks, in agreement with its lockstep reference, with no tick without contact
/// after the touch and nothing of the prefix left.
#[test]
fn a_stack_started_off_a_stiff_surface_touches_learns_and_tracks() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("touch");
    let _clean = CleanPrefix(p.clone());
    let dir = std::env::temp_dir().join(format!("afs-touch-{p}"));
    std::fs::create_dir_all(&dir).unwrap();
    let stack = stack_file(
        &dir,
        "[sim]\nstart_gap_m = 0.0005\n[sim.plant.contact]\ninteraction_stiffness_n_per_m = 1e5\n",
    );
    let run = start_run(
        &p,
        &["--config", stack.to_str().unwrap(), "--duration", "6"],
    );
    let r = finish_passed(run.take(), "afs run");
    assert!(check(&r, "lockstep_agreement").pass, "{:#?}", r.agreement);
    assert!(check(&r, "ticks_without_contact").pass);
    let c = r.contact.expect("the servo's contact report");
    assert_eq!(c.adoptions, 1, "{c:?}");
    assert!(
        (c.stiffness_in_use_n_per_m / 1e5 - 1.0).abs() < 0.3,
        "{c:?}"
    );
    // It moved on after the touch (the scenario's velocity, held while approaching).
    assert!(
        r.stack.tracking.travelled_m > 1e-3,
        "{:?}",
        r.stack.tracking
    );
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `afs run --rate-hz 1000` runs the servo at 1 kHz, as `afs experiment --rate-hz 1000` runs its
/// lockstep: one flag, one meaning. 2 s, every tick joined, in agreement with the lockstep.
#[test]
fn run_takes_the_rate_flag_of_experiment() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("rate");
    let run = start_run(&p, &["--rate-hz", "1000", "--duration", "2"]);
    let r = finish_passed(run.take(), "afs run --rate-hz 1000");
    let l = r.loop_stats.expect("the servo's loop statistics");
    assert_eq!(l.period_us, 1000.0);
    assert_eq!(r.stack.ticks, 2000);
    assert_eq!(r.samples.plant_lost, 0);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}
