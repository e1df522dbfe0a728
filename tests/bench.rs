//! `afs bench all --duration 1`: a smoke run that checks the report's shape (every part, every
//! series with its percentiles, ratios to floors, targets, files written), read back as the typed report, not its numbers.
//! It starts stacks, so it runs alone in its own test binary with its own prefix.

use afs::tools::bench::BenchReport;
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
    let r: BenchReport = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(r.bench, "all");
    assert!(!r.interrupted);
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
                "upstream_threads_oneway",
                "upstream_processes_oneway",
                "upstream_processes_touch_oneway",
                "upstream_processes_touch_clock_oneway",
                "upstream_processes_touch_clock_pause_oneway",
                "upstream_processes_touch_clock_pause_late_oneway",
            ],
        ),
        ("loop", &["bare_loop_wake", "servo_wake"]),
        (
            "stack",
            &[
                "servo_wake",
                "force_age",
                "servo_wake_hog",
                "force_age_hog",
                "servo_wake_viewer",
                "force_age_viewer",
            ],
        ),
    ];
    let parts = r.parts();
    assert_eq!(
        parts.iter().map(|p| p.0).collect::<Vec<_>>(),
        ["hop", "loop", "stack"]
    );
    for ((part, names), (name, report)) in expect.into_iter().zip(parts) {
        assert_eq!(part, name);
        assert_eq!(report.series.len(), names.len(), "{part}: series");
        for n in names {
            let s = report
                .series
                .get(*n)
                .unwrap_or_else(|| panic!("{part}: no series {n}"));
            assert!(s.summary_us.count > 0, "{part}/{n}: empty");
            let q = &s.summary_us.quantiles;
            for v in [q.p50, q.p90, q.p99, q.p99_9, q.p99_99, q.max] {
                assert!(v.is_finite() && v > 0.0, "{part}/{n}: {q:?}");
            }
            assert_eq!(s.floor.is_some(), s.ratio_to_floor.is_some(), "{part}/{n}");
        }
        assert!(!report.targets.is_empty(), "{part}: no targets");
        for t in &report.targets {
            assert!(t.is_target() && t.value.is_finite(), "{t:?}");
        }
        for f in &report.files {
            let p = std::path::Path::new(f);
            assert!(p.is_file(), "{part}: {} not written", p.display());
        }
    }
    let h = &r.hop.as_ref().unwrap().part.series;
    assert_eq!(
        h["afs_poll_rtt"].summary_us.count, h["unix_socket_rtt"].summary_us.count,
        "every hop series has the same sample count"
    );
    // Upstream's method: one figure per round (a batch's total / 2n), as many in each.
    let rounds = r.hop.as_ref().unwrap().rounds as u64;
    assert!(rounds > 0);
    for n in h.keys().filter(|n| n.starts_with("upstream_")) {
        assert_eq!(h[n].summary_us.count, rounds, "{n}");
    }
    let s = r.stack.as_ref().unwrap();
    assert!(s.runs.with_viewer.viewer && s.runs.with_viewer.stack_runs == 2);
    assert!(
        s.runs.viewer_messages > 0,
        "the bench's Foxglove client received nothing"
    );
    assert!(
        s.part
            .targets
            .iter()
            .any(|t| t.id == "servo_wake_p99_with_viewer_over_without")
    );
    for p in ["h", "l", "s0", "s1", "s2", "s3", "s4", "s5"] {
        let left = afs::ipc::leftovers(&format!("{prefix}{p}"));
        assert!(left.is_empty(), "{left:?}");
    }
    let _ = std::fs::remove_dir_all(&out);
}
