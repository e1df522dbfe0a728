//! The multi-process stack, started through the real binaries: `afs run` launches servo,
//! sensor and estimator over iceoryx2, reports figures that agree with the lockstep
//! reference, serves a client in another language, refuses a second stack on its prefix, and
//! leaves no shared memory behind.
//!
//! Stack tests run one at a time (a lock) with their own prefixes; none asserts a run time.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

static SERIAL: Mutex<()> = Mutex::new(());

fn afs() -> Command {
    Command::new(env!("CARGO_BIN_EXE_afs"))
}

/// A prefix no other test or run uses.
fn prefix(tag: &str) -> String {
    format!("t{}{tag}", std::process::id())
}

/// Files of a prefix in /dev/shm and the iceoryx2 root.
fn leftovers(prefix: &str) -> Vec<PathBuf> {
    afs::ipc::leftovers(prefix)
}

fn json_of(out: &Output) -> Value {
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout is not JSON ({e}); stderr:\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

/// Waits (with a watchdog) until `afs status` sees the stack's servo loop running.
fn wait_running(prefix: &str, limit: Duration) -> Value {
    let t0 = Instant::now();
    loop {
        let out = afs()
            .args(["status", "--json", "--prefix", prefix])
            .output()
            .unwrap();
        if out.status.success() {
            let v = json_of(&out);
            if v["loop"]["ticks"].as_u64().unwrap_or(0) > 1000 {
                return v;
            }
        }
        assert!(
            t0.elapsed() < limit,
            "the stack '{prefix}' did not come up: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn finish(child: Child, what: &str) -> Output {
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.code().is_some(),
        "{what} was killed by a signal: {:?}",
        out.status
    );
    out
}

/// `afs run --scenario surface-tracking --duration 10 --json`: one JSON object whose tangent
/// error and force regulation agree with the lockstep reference, with the servo's loop
/// statistics (wake jitter and force age percentiles), every tick of 10 s run at 10 kHz and
/// joined, and nothing of the prefix left in /dev/shm or the iceoryx2 root.
#[test]
fn surface_tracking_across_processes_agrees_with_the_lockstep() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("st");
    let out = afs()
        .args(["run", "--scenario", "surface-tracking", "--duration", "10"])
        .args(["--json", "--quiet", "--prefix", &p])
        .output()
        .unwrap();
    let r = json_of(&out);
    assert!(
        out.status.success(),
        "afs run failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        serde_json::to_string_pretty(&r["checks"]).unwrap()
    );
    assert_eq!(r["passed"], true);
    assert_eq!(r["finished"], true);
    assert_eq!(r["agreement"]["agrees"], true, "{}", r["agreement"]);
    assert_eq!(r["stack"]["ticks"].as_u64(), Some(100_000));
    assert_eq!(r["samples"]["plant_lost"].as_u64(), Some(0));
    assert_eq!(r["samples"]["reordered"].as_u64(), Some(0));
    let l = &r["loop"];
    for k in ["p50", "p99", "p99_9", "max"] {
        assert!(l["wake_jitter_us"][k].as_f64().is_some(), "wake jitter {k}");
    }
    for k in ["p50", "p99", "p99_9"] {
        let age = l["force_age_us"][k].as_f64().unwrap();
        assert!(age > 0.0 && age < 2000.0, "force age {k} = {age} µs");
    }
    assert!(l["misses"].as_u64().is_some());
    assert!(
        r["stack"]["tracking"]["tangent_error_rms_deg"]
            .as_f64()
            .unwrap()
            < 1.0
    );
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
    let run = afs()
        .args([
            "run",
            "--scenario",
            "friction-suppression",
            "--json",
            "--quiet",
        ])
        .args(["--prefix", &p, "--record"])
        .arg(&rec)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let status = wait_running(&p, Duration::from_secs(20));
    let names: Vec<&str> = status["processes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["servo", "sensor", "estimator"]);
    assert!(
        status["processes"]
            .as_array()
            .unwrap()
            .iter()
            .all(|x| x["state"] == "running")
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
    let o = json_of(&other);
    assert_eq!(
        o["finished"],
        true,
        "{}",
        String::from_utf8_lossy(&other.stderr)
    );
    assert!(leftovers(&q).is_empty());

    // Two stacks, a Python client and `afs status` at once are more than this 2-core machine
    // holds at 10 kHz: the servo may see stale force data and go safe for a while, which moves
    // the figures away from the lockstep's; the run itself must complete and clean up.
    let out = finish(run, "afs run");
    let r = json_of(&out);
    assert_eq!(
        r["finished"],
        true,
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(r["stack"]["ticks"].as_u64(), Some(65_000));
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
    let rs = &r["record"];
    assert_eq!(rs["dropped"], 0);
    let plant = rs["messages"]["/plant"].as_u64().unwrap();
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
    assert_eq!(
        lines.count() as u64,
        rs["messages"]["/servo"].as_u64().unwrap()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Ctrl-C (SIGINT to the supervisor) stops the stack in order, reports what ran, and leaves
/// no file of the prefix behind.
#[test]
fn ctrl_c_stops_the_stack_and_cleans_up() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("cc");
    let run = afs()
        .args([
            "run",
            "--duration",
            "60",
            "--json",
            "--quiet",
            "--prefix",
            &p,
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_running(&p, Duration::from_secs(20));
    // SAFETY: signalling our own child.
    unsafe {
        libc::kill(run.id() as i32, libc::SIGINT);
    }
    let out = finish(run, "afs run");
    let r = json_of(&out);
    assert_eq!(r["interrupted"], true);
    assert_eq!(
        out.status.code(),
        Some(1),
        "an interrupted scenario is not a pass"
    );
    assert!(r["stack"]["ticks"].as_u64().unwrap() > 1000);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
    assert_eq!(r["cleanup"]["left"].as_array().map(Vec::len), Some(0));
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
        afs::supervisor::DEFAULT_STACK.replace("name = \"sensor\"", "name = \"servo\""),
    )
    .unwrap();
    let missing_bin = dir.join("missing.toml");
    std::fs::write(
        &missing_bin,
        afs::supervisor::DEFAULT_STACK.replace("binary = \"afs-sensor\"", "binary = \"afs-nope\""),
    )
    .unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["run".into(), "--scenario".into(), "nope".into()],
            "unknown scenario",
        ),
        (vec!["run".into(), "--duration=-3".into()], "must be"),
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
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains(needle),
            "{args:?}: expected '{needle}' in: {err}"
        );
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
