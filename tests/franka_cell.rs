//! afs's FCI client on franky-sim's FR3 (examples/python/fr3_cell.py, docs/franka.md, *The
//! FCI loop* and *The servo on the robot*): `afs bench robot` holds the arm through the FCI
//! loop, and `afs run` drives the scenario on it with the cell's wrist sensor over RDT.
//! Skipped, saying why, where franky-sim is not installed
//! (examples/python/requirements-franka.txt; the test command does not install it).

mod common;

use common::{KillOnDrop, afs, say};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// franky-sim's FR3 on a loopback address of this test's own; None (said why) without it.
fn cell() -> Option<(KillOnDrop, String)> {
    let probe = Command::new("python3")
        .args(["-c", "import franky_sim"])
        .stderr(Stdio::null())
        .status();
    if !probe.is_ok_and(|s| s.success()) {
        say(
            "skipped: franky-sim is not installed (pip install -r examples/python/requirements-franka.txt)",
        );
        return None;
    }
    let host = format!("127.0.0.{}", 100 + std::process::id() % 100);
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
        "prefix = \"afs\"",
        &format!("prefix = \"fr3cell{}\"", std::process::id()),
    );
    let dir = std::env::temp_dir().join(format!("afs-franka-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("stack-franka.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Two seconds of the robot's time held through the FCI loop: every packet answered (the
/// robot's time advanced by the cycles afs ran and the ones it missed), the robot took the
/// commands, the tool stayed within 1 mm, the guard never tripped. Then `afs run` drives the
/// scenario for 3 s of the robot's time: every packet a tick, every tick's samples delivered,
/// the sensor's records all received, the tool pressed on the cell's wall, nothing left behind.
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
    drives_the_scenario(&config);
}

fn drives_the_scenario(config: &std::path::Path) {
    let run = afs()
        .args(["run", "--duration", "3", "--json", "--config"])
        .arg(config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    // The run's checks are reported, not asserted: the scenario's surface is not yet the
    // cell's (docs/franka.md, *What is left*).
    assert!(matches!(run.status.code(), Some(0 | 1)), "{err}");
    let s: serde_json::Value = serde_json::from_slice(&run.stdout).expect("the run's JSON");
    assert_eq!(s["end"], "finished", "{err}");
    let ticks = s["loop"]["ticks"].as_u64().unwrap() + s["loop"]["misses"].as_u64().unwrap();
    assert!(ticks.abs_diff(3000) <= 3, "{}", s["loop"]);
    let samples = &s["samples"];
    assert_eq!(samples["servo_lost"], 0, "{samples}");
    assert_eq!(samples["plant_lost"], 0, "{samples}");
    assert_eq!(samples["paired"], s["loop"]["ticks"], "{samples}");
    let rdt = &s["sensor"]["rdt"];
    assert_eq!(rdt["lost"], 0, "{rdt}");
    assert!(rdt["records"].as_u64().unwrap() > 1000, "{rdt}");
    for p in s["processes"].as_array().unwrap() {
        assert_eq!(p["restarts"], 0, "{p}");
    }
    let pressed = s["faults"]["normal_force_max_n"].as_f64().unwrap();
    assert!(
        pressed > 1.25,
        "the tool never pressed the wall: {pressed} N"
    );
    assert_eq!(
        s["cleanup"]["left"],
        serde_json::json!([]),
        "{}",
        s["cleanup"]
    );
}
