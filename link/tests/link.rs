//! Two hosts on one machine through the link board (docs/link.md): `examples/two-hosts.sh`
//! makes host B (a network namespace on a veth pair, with its own /dev/shm and iceoryx2 root)
//! and runs the estimator and a recorder there while host A runs the servo and the sensor. The
//! tests read the script's JSON summary. As root host A is this machine's network; as another
//! user the script runs in a user namespace of its own, and where the kernel gives none the two
//! tests say so in one line and pass. They need the `afs` binaries beside the link board's (the
//! README's test command builds the whole workspace).
//!
//! One stack at a time (a lock), each with its own prefix; no test asserts a run time.

use serde_json::Value;
use std::path::PathBuf;
use std::process::Command;

#[path = "../../tests/common/mod.rs"]
mod common;
use common::*;

/// The directory of the built binaries (the link board's, with the root package's beside it).
fn bin_dir() -> PathBuf {
    let link = PathBuf::from(env!("CARGO_BIN_EXE_afs-link"));
    link.parent()
        .expect("the binaries' directory")
        .to_path_buf()
}

/// Runs the script with `args`; returns its exit status and summary, or None where this
/// machine gives a user who is not root no namespaces (the script then says why, and so does
/// the test, in one line). As root it always runs.
fn two_hosts(prefix: &str, args: &[&str]) -> Option<(i32, Value)> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples/two-hosts.sh");
    let out = Command::new(script)
        .args(["--prefix", prefix, "--bin"])
        .arg(bin_dir())
        .args(args)
        .output()
        .expect("running examples/two-hosts.sh");
    let text = String::from_utf8_lossy(&out.stdout);
    let v: Value = serde_json::from_str(&text).unwrap_or_else(|e| {
        panic!(
            "the script's summary is not JSON ({e}): {text}\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    let code = out.status.code().unwrap_or(-1);
    if let Some(why) = v["skipped"].as_str() {
        // SAFETY: geteuid has no preconditions.
        let root = unsafe { libc::geteuid() } == 0;
        assert!(!root && code == 77, "skipped as root ({code}): {why}");
        say(&format!("two-hosts: skipped: {why}"));
        return None;
    }
    say(&format!(
        "two-hosts: host B ran in a network namespace ({})",
        match v["namespace"].as_str() {
            Some("user") => "inside a user namespace: not root",
            Some("root") => "as root",
            other => panic!("no namespace in the summary ({other:?}): {v:#}"),
        }
    ));
    Some((code, v))
}

/// Surface tracking with the estimator on host B: the run passes and agrees with the lockstep
/// reference, the tangent estimates came from host B through the request and response topics,
/// and host B's recording holds the servo stream to its last tick with no number missing,
/// every batch accounted for; `afs status` and the Python client work on host B; host B's
/// shared memory is left empty.
#[test]
fn the_estimator_on_another_host_serves_the_servo_and_the_record_has_no_gap() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("lk");
    let Some((code, v)) = two_hosts(&p, &["--duration", "20"]) else {
        return;
    };
    assert_eq!(code, 0, "{v:#}");
    assert_eq!(v["passed"], true, "{v:#}");
    assert_eq!(v["run"]["passed"], true);
    assert!(v["run"]["estimates"].as_u64().unwrap() >= 1, "{v:#}");
    assert_eq!(v["run"]["agreement"]["agrees"], true);
    let est = &v["run"]["estimator_link"];
    assert!(est["answers"].as_u64().unwrap() >= 1, "{est}");
    assert_eq!(v["host_b"]["servo_missing"], 0);
    assert_eq!(v["host_b"]["ended"], "stopping");
    let unpacked = &v["host_b"]["link"]["unpacked"];
    assert_eq!(unpacked["batches"]["missing"], 0, "{unpacked}");
    assert_eq!(unpacked["samples"]["missing"], 0, "{unpacked}");
    assert_eq!(unpacked["refused"], 0);
    // What host B's link board published is what its recorder got.
    assert_eq!(
        v["host_b"]["link"]["servo_published"], v["host_b"]["servo_samples"],
        "{v:#}"
    );
    assert_eq!(
        v["host_b"]["recording"]["messages"]["/servo"],
        v["host_b"]["servo_samples"]
    );
    assert!(v["host_b"]["recording"]["messages"]["/supervisor"].as_u64() > Some(0));
    assert!(v["host_b"]["recording"]["messages"]["/loop_stats"].as_u64() > Some(0));
    // Observers on host B half-way through: `afs status` shows host A's processes and servo
    // loop as its supervisor reports them; the Python client reads the servo's stream.
    let st = &v["host_b"]["status"];
    assert!(st["error"].is_null(), "{st}");
    for board in ["servo", "sensor", "link"] {
        assert_eq!(st["processes"][board], "running", "{st}");
    }
    assert_eq!(st["loop_stats"], true, "{st}");
    let py = &v["host_b"]["python"];
    assert_eq!(py["received"], 5000, "{py}");
    assert_eq!(py["versions_ok"], true, "{py}");
    assert_eq!(py["seq_increasing"], true, "{py}");
    assert_eq!(py["finite"], true, "{py}");
    assert_eq!(v["host_b"]["leftover_files"], Value::Array(vec![]));
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// `afs chaos` on host A kills the link board and then cuts the link for 12 s (host A's end of
/// the veth pair down, by the stack file's [chaos] commands): host A's stack stays safe and
/// keeps its own data (every check but the lockstep agreement holds: a request a cut outlasts
/// is given up, as with a dead estimator), the link board is restarted once; host B's
/// recording resumes after each fault, to the run's last tick, and its gaps are reported and
/// lie where the faults were, with the link board's own account agreeing.
#[test]
fn a_killed_and_a_cut_link_show_as_reported_gaps_and_host_a_stays_safe() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("lc");
    let Some((code, v)) = two_hosts(
        &p,
        &[
            "--duration",
            "30",
            "--chaos",
            "kill-link,cut-link",
            "--cut-for",
            "12",
        ],
    ) else {
        return;
    };
    assert_eq!(code, 0, "{v:#}");
    assert_eq!(v["passed"], true, "{v:#}");
    let failed = v["run"]["failed_checks"].as_array().unwrap();
    assert!(
        failed.iter().all(|c| c == "lockstep_agreement"),
        "{failed:?}"
    );
    let faults = v["chaos"]["faults"].as_array().unwrap();
    let kinds: Vec<&str> = faults.iter().map(|f| f["kind"].as_str().unwrap()).collect();
    assert_eq!(kinds, ["kill-link", "cut-link"], "{v:#}");
    assert!(faults[0]["back_ms"].as_f64().is_some(), "{v:#}");
    assert!(
        faults[1]["note"]
            .as_str()
            .unwrap()
            .contains("restored after"),
        "{v:#}"
    );
    assert_eq!(v["run"]["link_board_restarts"], 1);
    assert_eq!(v["chaos"]["link_epochs"], 2);
    assert_eq!(v["chaos"]["gaps_inside"], true, "{v:#}");
    let missing = v["host_b"]["servo_missing"].as_u64().unwrap();
    // Longer than zenoh's 10-s lease: the session closes, and the cut shows.
    assert!(missing > 0, "a cut of 12 s must show: {v:#}");
    let gaps = v["host_b"]["servo_gaps"].as_array().unwrap();
    let listed: u64 = gaps.iter().map(|g| g["missing"].as_u64().unwrap()).sum();
    assert_eq!(listed, missing, "every missing sample is in a reported gap");
    // The link board's own account agrees with the recorder's.
    assert_eq!(
        v["host_b"]["link"]["unpacked"]["samples"]["missing"].as_u64(),
        Some(missing)
    );
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// Bad input is refused with a message that says what to do, before anything starts.
#[test]
fn the_link_board_and_afs_record_refuse_bad_input() {
    let link = bin_dir().join("afs-link");
    let out = Command::new(&link)
        .args(["--prefix", "lkbad", "--side", "remote"])
        .output()
        .unwrap();
    assert_refused(&out, &"no endpoint", "--listen");
    let out = Command::new(&link)
        .args(["--prefix", "bad prefix", "--side", "remote", "--listen"])
        .arg("tcp/127.0.0.1:7999")
        .output()
        .unwrap();
    assert_refused(&out, &"bad prefix", "prefix");
    let out = Command::new(&link)
        .args(["--prefix", "lkbad", "--side", "remote", "--poll-ms", "0"])
        .args(["--listen", "tcp/127.0.0.1:7999"])
        .output()
        .unwrap();
    assert_refused(&out, &"poll 0", "--poll-ms");
    let out = Command::new(&link)
        .args([
            "--prefix",
            "lkbad",
            "--side",
            "remote",
            "--discover-ms",
            "20",
        ])
        .args(["--listen", "tcp/127.0.0.1:7999"])
        .output()
        .unwrap();
    assert_refused(
        &out,
        &"discovery every 20 ms",
        "--discover-ms 20 must be 100 to 10000",
    );
    let out = Command::new(&link)
        .args(["--prefix", "lkbad", "--side", "remote"])
        .args(["--listen", "quic/127.0.0.1:7999"])
        .output()
        .unwrap();
    assert_refused(&out, &"a QUIC endpoint", "over TCP only");
    let out = afs()
        .args(["record", "--prefix", "lknone", "--out", "/tmp/lknone.mcap"])
        .output()
        .unwrap();
    assert_refused(&out, &"no stack", "no stack with prefix 'lknone'");
    // The two-host stack has a link board but no commands to cut it, and no estimator here.
    let two = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/stack-two-hosts.toml"
    );
    for (fault, needle) in [
        ("cut-link", "cut_link and restore_link"),
        ("kill-estimator", "needs a process named 'estimator'"),
    ] {
        let out = afs()
            .args([
                "chaos", "--config", two, "--prefix", "lkbadc", "--faults", fault,
            ])
            .output()
            .unwrap();
        assert_refused(&out, &fault, needle);
    }
}

/// `afs bench link` (short): every series measured, the link's servo stream complete on host
/// B, pings answered across the link once it is up, every run passed. Figures are not judged
/// here (they are the benchmark's targets).
#[test]
fn bench_link_measures_both_paths() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("lb");
    let dir = std::env::temp_dir().join(format!("afs-bench-link-{p}"));
    let out = afs()
        .args([
            "bench",
            "link",
            "--duration",
            "4",
            "--json",
            "--prefix",
            &p,
            "--out",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let l = &v["link"];
    for s in [
        "sample_host_a",
        "sample_link",
        "rtt_host_b",
        "rtt_link",
        "wake_without",
        "wake_with_link",
    ] {
        assert!(
            l["series"][s]["summary_us"]["count"].as_u64() > Some(0),
            "{s}: {l:#}"
        );
    }
    assert_eq!(l["loss"]["servo_host_b"]["missing"], 0, "{l:#}");
    assert!(l["loss"]["pings_link"][1].as_u64() > Some(0), "{l:#}");
    for r in l["runs_with_link"].as_array().unwrap() {
        assert_eq!(r[0], true, "{l:#}");
    }
    for r in l["runs_without_link"].as_array().unwrap() {
        assert_eq!(r, &Value::Bool(true), "{l:#}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    for q in [format!("{p}a"), format!("{p}b")] {
        assert!(leftovers(&q).is_empty(), "{:?}", leftovers(&q));
    }
}
