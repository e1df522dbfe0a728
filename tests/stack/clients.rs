//! A running stack's clients: the Python client, `afs status`, a second stack on its prefix,
//! and its recording.

use super::*;

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
    the_graph_is_the_stacks(&p);

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

/// The picture of `afs graph` (its table, `afs::ipc::graph::EDGES`) against a running stack:
/// every service the stack has is in the table, every board on it is one the table draws
/// writing or reading it, and every service the table has in every stack is there.
fn the_graph_is_the_stacks(prefix: &str) {
    use afs::ipc::graph::{EDGES, Party, edge_of};
    let running = afs::ipc::service_nodes(prefix).unwrap();
    for (service, nodes) in &running {
        let e = edge_of(service).unwrap_or_else(|| panic!("{service} is not in the graph"));
        for node in nodes {
            let Some(party) = Party::ALL.iter().find(|p| p.node() == Some(node.as_str())) else {
                continue; // a client (afs status), not a board
            };
            assert!(
                e.from.contains(party) || e.to.contains(party),
                "{node} is on {service}, which the graph does not draw it on"
            );
        }
    }
    for e in EDGES.iter().filter(|e| !e.optional) {
        assert!(
            running.contains_key(e.service),
            "{} is not in the stack",
            e.service
        );
    }
}
