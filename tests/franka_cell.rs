//! afs's FCI client on franky-sim's FR3 (examples/python/fr3_cell.py, docs/franka.md, *The
//! FCI loop*): `afs bench robot` holds the arm through the FCI loop, and `afs run` reaches the
//! robot before it refuses to drive it. Skipped, saying why, where franky-sim is not installed
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
        .args([script, "--hostname", &host, "--seconds", "120"])
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

/// examples/stack-franka.toml with the cell's address.
fn stack_file(host: &str) -> std::path::PathBuf {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/stack-franka.toml"
    ))
    .unwrap()
    .replace("address = \"127.0.0.21\"", &format!("address = \"{host}\""));
    let dir = std::env::temp_dir().join(format!("afs-franka-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("stack-franka.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Two seconds of the robot's time held through the FCI loop: every packet answered (the
/// robot's time advanced by the cycles afs ran and the ones it missed), the robot took the
/// commands, the tool stayed within 1 mm, the guard never tripped. Then `afs run` reaches the
/// robot and names its FCI version before it refuses to drive it.
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
    let run = afs()
        .arg("run")
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{err}");
    assert!(
        err.contains("the robot answered (FCI server version 10)"),
        "{err}"
    );
}
