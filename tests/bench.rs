//! `afs bench all --duration 1`: a smoke run that checks the report's shape (every part, every
//! series with its percentiles, ratios to floors, targets, files written), not its numbers.
//! It starts stacks, so it runs alone in its own test binary with its own prefix.

use serde_json::Value;
use std::process::Command;

#[test]
fn bench_all_reports_every_series() {
    let prefix = format!("tb{}", std::process::id());
    let out = std::env::temp_dir().join(format!("afs-bench-test-{prefix}"));
    let run = Command::new(env!("CARGO_BIN_EXE_afs"))
        .args([
            "bench",
            "all",
            "--duration",
            "1",
            "--json",
            "--prefix",
            &prefix,
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "afs bench failed: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let r: Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(r["bench"], "all");
    assert_eq!(r["interrupted"], false);
    let expect: [(&str, &[&str]); 3] = [
        (
            "hop",
            &[
                "atomic_rtt",
                "atomic_oneway",
                "afs_poll_rtt",
                "afs_poll_oneway",
                "afs_event_rtt",
                "afs_event_oneway",
                "bare_iceoryx2_poll_rtt",
                "bare_iceoryx2_poll_oneway",
                "unix_socket_rtt",
                "unix_socket_oneway",
            ],
        ),
        ("loop", &["bare_loop_wake", "servo_wake"]),
        (
            "stack",
            &["servo_wake", "force_age", "servo_wake_hog", "force_age_hog"],
        ),
    ];
    for (part, names) in expect {
        let series = r[part]["series"]
            .as_object()
            .unwrap_or_else(|| panic!("{part}: no series in {r}"));
        for n in names {
            let s = &series[*n];
            let sum = &s["summary_us"];
            assert!(sum["count"].as_u64().unwrap() > 0, "{part}/{n}: empty");
            for k in ["p50", "p90", "p99", "p99_9", "p99_99", "max"] {
                let v = sum[k].as_f64().unwrap_or(f64::NAN);
                assert!(v.is_finite() && v > 0.0, "{part}/{n}: {k} = {v}");
            }
            if s.get("floor").is_some() {
                assert!(s["ratio_to_floor"]["p99"].as_f64().is_some(), "{part}/{n}");
            }
        }
        let targets = r[part]["targets"].as_array().unwrap();
        assert!(!targets.is_empty(), "{part}: no targets");
        for t in targets {
            assert!(t["met"].is_boolean() && t["value"].is_number(), "{t}");
        }
        for f in r[part]["files"].as_array().unwrap() {
            let p = std::path::Path::new(f.as_str().unwrap());
            assert!(p.is_file(), "{part}: {} not written", p.display());
        }
    }
    let h = &r["hop"];
    assert_eq!(
        h["series"]["afs_poll_rtt"]["summary_us"]["count"],
        h["series"]["unix_socket_rtt"]["summary_us"]["count"],
        "every hop series has the same sample count"
    );
    for p in ["h", "l", "s0", "s1", "s2", "s3"] {
        let left = afs::ipc::leftovers(&format!("{prefix}{p}"));
        assert!(left.is_empty(), "{left:?}");
    }
    let _ = std::fs::remove_dir_all(&out);
}
