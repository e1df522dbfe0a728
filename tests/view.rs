//! The live view, through the real binaries and a client speaking the Foxglove WebSocket
//! protocol: what a viewer receives is what the recording of the same run holds (sequence
//! numbers and values), a client that stops reading disturbs nothing, `afs view` attaches to
//! a running stack and ends with it, and bad input is refused.
//!
//! Stack tests run one at a time (a lock) with their own prefixes; none asserts a run time.

use afs::observe::record;
use afs::observe::topics::{TOPICS, json_schema};
use afs::observe::view::ViewSummary;
use afs::observe::view_client::{Received, ViewClient};
use serde_json::Value;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

mod common;
use common::*;

/// A port nobody listens on now.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Reads `c` until the server closes the connection (the stack ended) or `limit` passes.
fn read_to_end(c: &mut ViewClient, limit: Duration) -> Vec<Received> {
    let t0 = Instant::now();
    let mut got = Vec::new();
    while t0.elapsed() < limit {
        match c.next_message() {
            Ok(Some(m)) => got.push(m),
            Ok(None) => {}
            Err(_) => break,
        }
    }
    got
}

/// The recording's messages of `topic`, by the key `key` gives.
fn recorded_by<K: Ord>(
    rec: &BTreeMap<String, Vec<Value>>,
    topic: &str,
    key: impl Fn(&Value) -> K,
) -> BTreeMap<K, Value> {
    rec[topic].iter().map(|v| (key(v), v.clone())).collect()
}

/// `afs run --foxglove --record`: a client subscribed to the controller, force, live and
/// statistics topics receives messages whose every field equals the recording's message of
/// the same sequence number, the world and controller at the same ticks (every tenth at
/// 1 kHz), with the recording's publication time as log time; a second client that
/// subscribes to everything and never reads leaves the run passing, agreeing with its
/// lockstep and losing nothing.
#[test]
fn a_foxglove_client_receives_what_the_recording_holds_and_a_stalled_one_disturbs_nothing() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("fox");
    let _clean = CleanPrefix(p.clone());
    let dir = std::env::temp_dir().join(format!("afs-view-{p}"));
    std::fs::create_dir_all(&dir).unwrap();
    let rec = dir.join("run.mcap");
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let run = start_run(
        &p,
        &[
            "--scenario",
            "surface-tracking",
            "--duration",
            "5",
            "--record",
            rec.to_str().unwrap(),
            "--foxglove",
            &addr,
            "--foxglove-hz",
            "1000",
        ],
    );
    let url = format!("ws://{addr}");
    let all: Vec<&str> = TOPICS.iter().map(|t| t.0).collect();
    let mut stalled = ViewClient::connect(&url, Duration::from_secs(60)).unwrap();
    stalled.wait_for(&all, Duration::from_secs(30)).unwrap();
    stalled.subscribe(&all).unwrap();

    let mut c = ViewClient::connect(&url, Duration::from_secs(30)).unwrap();
    c.wait_for(&all, Duration::from_secs(30)).unwrap();
    assert_eq!(c.server_name, format!("afs {p}"));
    for (topic, ty) in TOPICS {
        let a = &c.channels[topic];
        assert_eq!(
            (
                a.encoding.as_str(),
                a.schema_encoding.as_str(),
                a.schema_name.as_str()
            ),
            ("json", "jsonschema", ty),
            "{topic}"
        );
        assert_eq!(a.schema, json_schema(ty), "{topic}: the recording's schema");
    }
    let wanted = ["/servo", "/plant", "/wrench", "/live", "/loop_stats"];
    c.subscribe(&wanted).unwrap();
    let got = read_to_end(&mut c, Duration::from_secs(120));
    let out = finish(run.take(), "afs run");
    let r = run_report(&out);
    assert!(
        out.status.success() && r.passed,
        "{}\n{}",
        failed(&r),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(r.agreement.agrees, "{:#?}", r.agreement);
    assert_eq!((r.samples.plant_lost, r.samples.servo_lost), (0, 0));
    // Every sample offered to the recording and to the view is accounted for: written or
    // dropped (the recording), published, unwatched or dropped (the view). Drops are the
    // machine's speed, reported and not judged here.
    let rs = r.record.as_ref().expect("the recording's summary");
    assert_eq!(
        rs.messages.values().sum::<u64>() + rs.dropped,
        rs.offered,
        "{rs:?}"
    );
    if rs.dropped == 0 {
        assert_eq!(rs.messages["/live"], rs.messages["/servo"]);
    }
    let v: &ViewSummary = r.view.as_ref().expect("the view's summary");
    assert_eq!(v.url, url);
    assert_eq!(v.max_clients, 2);
    assert_eq!(
        v.published.values().sum::<u64>() + v.unwatched + v.dropped,
        v.offered,
        "{v:?}"
    );
    assert!(v.offered > 0, "{v:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains(&url));
    drop(stalled);

    // Everything received is in the recording, field for field.
    let recording = record::read(&rec).unwrap();
    let seq = |v: &Value| v["seq"].as_u64().unwrap();
    let by_topic: BTreeMap<&str, BTreeMap<(u64, u64), Value>> = wanted
        .iter()
        .map(|t| {
            let key = |v: &Value| (v["epoch_ns"].as_u64().unwrap_or(0), seq(v));
            (*t, recorded_by(&recording, t, key))
        })
        .collect();
    let mut counts: BTreeMap<&str, u64> = BTreeMap::new();
    let mut ticks: BTreeMap<&str, Vec<u64>> = BTreeMap::new();
    let mut not_recorded = 0;
    for m in &got {
        let v: Value = serde_json::from_slice(&m.payload).unwrap();
        let key = (v["epoch_ns"].as_u64().unwrap_or(0), seq(&v));
        let t = m.topic.as_str();
        // A sample the recording dropped (counted in its summary) is the only one missing.
        let Some(want) = by_topic[t].get(&key) else {
            not_recorded += 1;
            assert!(
                not_recorded <= rs.dropped,
                "{t} {key:?} is not in the recording ({} dropped)",
                rs.dropped
            );
            continue;
        };
        assert_eq!(&v, want, "{t} {key:?}");
        assert_eq!(m.log_time_ns, v["publish_ns"].as_u64().unwrap(), "{t}");
        *counts.entry(t).or_default() += 1;
        if matches!(t, "/servo" | "/plant" | "/live") {
            ticks.entry(t).or_default().push(seq(&v));
        }
    }
    // 8 s at 1 kHz of each tick stream; the client subscribed some time into the run.
    for t in ["/servo", "/plant", "/live", "/wrench"] {
        let n = counts.get(t).copied().unwrap_or(0);
        assert!(n >= 1000, "{t}: {n} messages ({counts:?})");
        assert!(
            n <= v.published[t],
            "{t}: {n} > {} published",
            v.published[t]
        );
    }
    assert!(
        counts.get("/loop_stats").copied().unwrap_or(0) >= 10,
        "{counts:?}"
    );
    // The same ticks on the three tick topics, every tenth.
    assert!(ticks["/servo"].iter().all(|s| s % 10 == 0));
    let common = |a: &str, b: &str| {
        let x: std::collections::BTreeSet<_> = ticks[a].iter().collect();
        ticks[b].iter().filter(|s| x.contains(s)).count()
    };
    assert!(common("/servo", "/live") * 10 >= ticks["/live"].len() * 9);
    assert!(common("/servo", "/plant") * 10 >= ticks["/plant"].len() * 9);
    // `/contact`, what the servo knows of its contact, about ten times a second from its
    // snapshots: the default contact, never re-learnt, with the fit beside it.
    let contact = &recording["/contact"];
    assert!(contact.len() >= 20, "{} /contact records", contact.len());
    let last = contact.last().unwrap();
    assert_eq!(last["stiffness_in_use_n_per_m"], 10e3, "{last}");
    assert_eq!(
        (last["adoptions"].as_u64(), last["provisional"].as_bool()),
        (Some(0), Some(false))
    );
    // To the run's end (5 s at 10 kHz): within its last half second.
    assert!(last["seq"].as_u64().unwrap() >= 45_000, "{last}");
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `afs view --prefix P` attaches to a running stack, serves its topics to a client, and
/// ends by itself when the stack ends, with a summary of what it published; the run, the
/// friction-identification scenario, passes.
#[test]
fn afs_view_attaches_to_a_running_stack_and_ends_with_it() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("att");
    let _clean = CleanPrefix(p.clone());
    let run = start_run(&p, &["--scenario", "friction-id", "--duration", "8"]);
    wait_running(&p, Duration::from_secs(60));
    let addr = format!("127.0.0.1:{}", free_port());
    let view = KillOnDrop(Some(
        afs()
            .args(["view", "--json", "--prefix", &p, "--foxglove", &addr])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    ));
    let mut c = ViewClient::connect(&format!("ws://{addr}"), Duration::from_secs(30)).unwrap();
    c.wait_for(&["/live", "/supervisor"], Duration::from_secs(30))
        .unwrap();
    c.subscribe(&["/live", "/supervisor"]).unwrap();
    let got = read_to_end(&mut c, Duration::from_secs(120));
    let out = finish(run.take(), "afs run");
    let r = run_report(&out);
    assert!(r.finished && r.passed, "{}", failed(&r));
    let vout = finish(view.take(), "afs view");
    assert!(
        vout.status.success(),
        "{}",
        String::from_utf8_lossy(&vout.stderr)
    );
    let s: ViewSummary = report_of(&vout);
    let live = got.iter().filter(|m| m.topic == "/live").count() as u64;
    assert!(live >= 100, "{live} /live messages");
    assert!(live <= s.published["/live"], "{s:?}");
    assert!(got.iter().any(|m| m.topic == "/supervisor"));
    for m in got.iter().filter(|m| m.topic == "/live") {
        let v: Value = serde_json::from_slice(&m.payload).unwrap();
        assert!(v["normal_force_n"].as_f64().is_some_and(f64::is_finite));
        assert!(v["safe"].is_boolean());
    }
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// A bad address or rate, or a prefix with no stack, is refused with what to do.
#[test]
fn bad_view_input_is_refused_clearly() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("none");
    let out = afs()
        .args(["view", "--prefix", &p, "--foxglove", "127.0.0.1:0"])
        .output()
        .unwrap();
    assert_refused(&out, &"no stack", "no stack with prefix");
    let out = afs()
        .args(["run", "--prefix", &p, "--foxglove", "nowhere"])
        .output()
        .unwrap();
    assert_refused(&out, &"bad address", "HOST:PORT");
    let out = afs()
        .args(["run", "--prefix", &p, "--foxglove", "--foxglove-hz", "0"])
        .output()
        .unwrap();
    assert_refused(&out, &"bad rate", "--foxglove-hz");
    // A port in use.
    let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = busy.local_addr().unwrap().to_string();
    let out = afs()
        .args([
            "run",
            "--prefix",
            &p,
            "--duration",
            "1",
            "--foxglove",
            &addr,
        ])
        .output()
        .unwrap();
    assert_refused(&out, &"port in use", "cannot listen");
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}
