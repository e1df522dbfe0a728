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

mod common;
use common::*;

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

/// While a stack runs: the Python client decodes wrench samples with the documented layout;
/// `afs status` lists the boards; a second stack on the same prefix is refused with a clear
/// message while one on another prefix runs beside it. Its recording plots and exports.
#[test]
fn a_running_stack_serves_clients_and_keeps_its_prefix() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("cl");
    let q = prefix("cl2");
    let dir = std::env::temp_dir().join(format!("afs-test-{p}"));
    std::fs::create_dir_all(&dir).unwrap();
    let rec = dir.join("run.mcap");
    let _clean = (CleanPrefix(p.clone()), CleanPrefix(q.clone()));
    let run = start_run(
        &p,
        &[
            "--scenario",
            "friction-suppression",
            "--record",
            rec.to_str().unwrap(),
        ],
    );
    let status = wait_running(&p, Duration::from_secs(20));
    let processes = status.processes.expect("the supervisor's status");
    let names: Vec<&str> = processes.iter().map(|x| x.name.as_str()).collect();
    assert_eq!(names, ["servo", "sensor", "estimator"]);
    assert!(
        processes
            .iter()
            .all(|x| x.state == Some(ProcessState::Running)),
        "{processes:?}"
    );

    // A client in another language.
    let py = Command::new("python3")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/python/wrench_subscriber.py"))
        .args(["--prefix", &p, "--count", "200", "--json"])
        .output()
        .expect("python3 is needed for this test");
    assert!(
        py.status.success(),
        "the Python client failed (install it: pip install -r examples/python/requirements.txt): {}",
        String::from_utf8_lossy(&py.stderr)
    );
    let v: Value = serde_json::from_slice(&py.stdout).unwrap();
    assert_eq!(v["received"], 200);
    assert_eq!(v["versions_ok"], true);
    assert_eq!(v["seq_increasing"], true);
    assert_eq!(v["timestamps_ordered"], true);
    assert_eq!(v["finite"], true);
    // The preload (2.5 N) and the friction (about 1.9 N) in the sensor frame.
    let m = v["mean_force_magnitude_n"].as_f64().unwrap();
    assert!(m > 2.0 && m < 5.0, "mean force {m} N");

    // The iceoryx2 config `afs iox2-config` writes lets any iceoryx2 program (the upstream
    // iox2 CLI reads ./config/iceoryx2.toml) see this stack's nodes.
    let cfg_dir = dir.join("iox2");
    let w = afs()
        .args(["iox2-config", "--prefix", &p, "--write"])
        .arg(&cfg_dir)
        .output()
        .unwrap();
    assert!(w.status.success(), "{}", String::from_utf8_lossy(&w.stderr));
    let file = cfg_dir.join("config/iceoryx2.toml");
    let printed = afs()
        .args(["iox2-config", "--prefix", &p])
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8_lossy(&printed.stdout).trim_end(),
        std::fs::read_to_string(&file).unwrap().trim_end()
    );
    let seen = nodes_seen_by(&file);
    for board in ["servo", "sensor", "estimator"] {
        assert!(
            seen.iter().any(|n| n.contains(board)),
            "{board} not among the nodes the written config sees: {seen:?}"
        );
    }
    let bad = afs()
        .args(["iox2-config", "--prefix", "no/slash"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("invalid stack prefix"));

    // Same prefix: refused.
    let dup = afs()
        .args(["run", "--duration", "2", "--quiet", "--prefix", &p])
        .output()
        .unwrap();
    assert_eq!(dup.status.code(), Some(2));
    let msg = String::from_utf8_lossy(&dup.stderr);
    assert!(msg.contains("already running"), "{msg}");

    // Another prefix: runs beside it.
    let other = afs()
        .args([
            "run",
            "--scenario",
            "friction-suppression",
            "--duration",
            "2",
        ])
        .args(["--json", "--quiet", "--prefix", &q])
        .output()
        .unwrap();
    let o = run_report(&other);
    assert!(o.finished, "{}", String::from_utf8_lossy(&other.stderr));
    assert!(leftovers(&q).is_empty());

    // Two stacks, a Python client and `afs status` at once are more than this 2-core machine
    // holds at 10 kHz: the servo may see stale force data and go safe for a while, which moves
    // the figures away from the lockstep's; the run itself must complete and clean up.
    let out = finish(run.take(), "afs run");
    let r = run_report(&out);
    assert!(r.finished, "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(r.stack.ticks, 65_000);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
    let rs = r.record.expect("the recording's summary");
    assert_eq!(rs.dropped, 0);
    let plant = rs.messages["/plant"];
    assert!(plant >= 65_000, "{plant} plant samples recorded");

    // The recording plots and exports.
    let svg = dir.join("run.svg");
    let plot = afs()
        .arg("plot")
        .arg(&rec)
        .arg("--out")
        .arg(&svg)
        .output()
        .unwrap();
    assert!(
        plot.status.success(),
        "{}",
        String::from_utf8_lossy(&plot.stderr)
    );
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("normal force (N)") && text.contains("dither"));
    let csv = dir.join("csv");
    let ex = afs()
        .arg("export")
        .arg(&rec)
        .arg("--out")
        .arg(&csv)
        .output()
        .unwrap();
    assert!(
        ex.status.success(),
        "{}",
        String::from_utf8_lossy(&ex.stderr)
    );
    let servo_csv = std::fs::read_to_string(csv.join("servo.csv")).unwrap();
    let mut lines = servo_csv.lines();
    let head = lines.next().unwrap();
    assert!(head.contains("normal_force_n") && head.contains("set_point_m[1]"));
    assert_eq!(lines.count() as u64, rs.messages["/servo"]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The names of the live iceoryx2 nodes a program configured by `file` sees.
fn nodes_seen_by(file: &Path) -> Vec<String> {
    use iceoryx2::node::NodeView;
    use iceoryx2::prelude::*;
    let path = FilePath::new(file.to_str().unwrap().as_bytes()).unwrap();
    let cfg =
        iceoryx2::config::Config::from_file(&path).expect("afs iox2-config is a valid config");
    let mut seen = Vec::new();
    Node::<ipc::Service>::list(&cfg, |state| {
        if let NodeState::Alive(v) = state
            && let Some(d) = v.details()
        {
            seen.push(d.name().to_string());
        }
        CallbackProgression::Continue
    })
    .unwrap();
    seen
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
/// passes, names it and the service it reads, and leaves its files alone.
#[test]
fn an_old_client_is_refused_and_one_attached_at_the_end_is_an_observer() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("obs");
    let _clean = CleanPrefix(p.clone());
    let python = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/python");
    let run = start_run(&p, &["--scenario", "surface-tracking", "--duration", "8"]);
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

/// The estimator board answers over iceoryx2: a probe record of a 3° tangent error gives the
/// error back, a malformed request is refused, and three rotational dithers about known
/// centres give the rotation centre.
#[test]
fn the_estimator_board_answers_requests() {
    use afs::ipc;
    use afs_shared::math::Vec2;
    use afs_shared::msg::{
        self, Outcome, RotationRequestHeader, RotationSample, TangentRequestHeader,
    };
    use afs_shared::tangent::{ProbeModel, TangentParams};
    use iceoryx2::service::port_factory::PortFactory;
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("es");
    let _clean = CleanPrefix(p.clone());
    let est = KillOnDrop(Some(
        Command::new(env!("CARGO_BIN_EXE_afs-estimator"))
            .args(["--prefix", &p])
            .spawn()
            .unwrap(),
    ));
    let node = ipc::node(&p, "test-client").unwrap();
    let tangent_service = ipc::tangent(&node).unwrap();
    let rotation_service = ipc::rotation(&node).unwrap();
    // A request sent before the server's port exists is not delivered: wait for it.
    let t0 = Instant::now();
    while tangent_service.dynamic_config().number_of_servers() == 0
        || rotation_service.dynamic_config().number_of_servers() == 0
    {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "the estimator did not come up"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let client = tangent_service
        .client_builder()
        .initial_max_slice_len(20_000)
        .create()
        .unwrap();

    // A rigid 1 mm stroke against a 1.4 kN/m spring, no noise.
    let params = TangentParams::default();
    let plan = params.first_plan();
    let model = ProbeModel {
        alpha0: 3f64.to_radians(),
        base: 0.3,
        k: 1400.0,
        noise: 0.0,
        friction: 0.0,
        preload: 2.5,
    };
    let (base, alpha0) = (model.base, model.alpha0);
    let rec = model.record(&plan, 0);
    let ask = |header: TangentRequestHeader| {
        let mut req = client.loan_slice_uninit(rec.len()).unwrap();
        *req.user_header_mut() = header;
        let req = req.write_from_slice(&rec);
        let pending = req.send().unwrap();
        let t0 = Instant::now();
        loop {
            if let Some(r) = pending.receive().unwrap() {
                return *r.payload();
            }
            assert!(t0.elapsed() < Duration::from_secs(20), "no answer");
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    let header = TangentRequestHeader {
        version: msg::TangentRequestHeader::VERSION,
        request_id: 7,
        base_angle_rad: base,
        plan: (&plan).into(),
        params: (&params).into(),
        ..Default::default()
    };
    let r = ask(header);
    assert_eq!(Outcome::try_from(r.outcome), Ok(Outcome::Estimate), "{r:?}");
    assert_eq!(r.request_id, 7);
    assert!(
        (r.alpha0_rad - alpha0).abs() < 1e-3,
        "α0 {} vs {alpha0}",
        r.alpha0_rad
    );
    let mut bad = header;
    bad.request_id = 8;
    bad.params.amplitude_m = f64::NAN;
    let r = ask(bad);
    assert_eq!(
        (Outcome::try_from(r.outcome), r.request_id),
        (Ok(Outcome::BadRequest), 8)
    );

    // Rotation centre: responses g(c) = −K J (P − c) with a diagonal K, three dithers.
    let rclient = rotation_service
        .client_builder()
        .initial_max_slice_len(10_000)
        .create()
        .unwrap();
    let centre = Vec2::new(0.02, 0.05);
    let centres = [
        Vec2::new(0.0, 0.0),
        Vec2::new(0.01, 0.01),
        Vec2::new(-0.01, 0.005),
    ];
    let amp = 0.5f64.to_radians();
    let mut samples = Vec::new();
    for (d, c) in centres.iter().enumerate() {
        let dp = centre - c;
        let g = Vec2::new(-3000.0 * -dp.y, -2500.0 * dp.x);
        for i in 0..1000 {
            let phase = std::f64::consts::TAU * i as f64 / 500.0;
            let f = g * (amp * phase.sin()) + Vec2::new(2.0, 2.0);
            samples.push(RotationSample {
                t: i as f64 * 1e-3,
                phase,
                force_n: [f.x, f.y],
                dither: d as u32,
                reserved: 0,
            });
        }
    }
    let mut centre_m = [[0.0; 2]; msg::MAX_CENTRES];
    for (i, c) in centres.iter().enumerate() {
        centre_m[i] = [c.x, c.y];
    }
    let mut req = rclient.loan_slice_uninit(samples.len()).unwrap();
    *req.user_header_mut() = RotationRequestHeader {
        version: msg::RotationRequestHeader::VERSION,
        centres: 3,
        request_id: 1,
        centre_m,
        amplitude_rad: amp,
        ..Default::default()
    };
    let pending = req.write_from_slice(&samples).send().unwrap();
    let t0 = Instant::now();
    let answer = loop {
        if let Some(r) = pending.receive().unwrap() {
            break *r.payload();
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "no rotation answer");
        std::thread::sleep(Duration::from_millis(5));
    };
    assert_eq!(answer.outcome, 0, "{answer:?}");
    let got = Vec2::new(answer.centre_m[0], answer.centre_m[1]);
    assert!((got - centre).norm() < 1e-4, "{got:?} vs {centre:?}");
    let thesis = Vec2::new(answer.thesis_centre_m[0], answer.thesis_centre_m[1]);
    assert!((thesis - centre).norm() < 1e-4, "thesis form {thesis:?}");

    drop(pending);
    drop((rclient, client, tangent_service, rotation_service));
    drop(node);
    // SAFETY: signalling our own child.
    unsafe {
        libc::kill(est.id() as i32, libc::SIGTERM);
    }
    let st = est.take().wait().unwrap();
    assert!(st.success(), "{st:?}");
    // The test's own node was a member of the domain: release it (its node counter goes).
    ipc::release_prefix(&p).unwrap();
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
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
