//! The real sensor's path, end to end through the real binaries: the sensor board's RDT source
//! reading `afs-netft` (the emulated device) in the full graph, the emulator's faults counted
//! and kept from the servo, and `afs sensor` against the emulator and against what is not a
//! device.
//!
//! Tests run one at a time (a lock), each with its own prefix and UDP port; none asserts a
//! run time. Bounds on the servo's safe state are its force-age limit plus the allowance the
//! fault tests use.

use afs::supervisor::RunReport;
use afs::tools::sensor::SensorToolReport;
use std::net::UdpSocket;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

mod common;
use common::*;

/// The servo's force-age limit (ms) and the allowance over it for going safe (ms).
const FORCE_AGE_LIMIT_MS: f64 = 1.5;
const SAFE_ALLOWANCE_MS: f64 = 10.0;

/// A UDP port for test `k` of this process (loopback only).
fn port(k: u16) -> u16 {
    40_000 + (std::process::id() % 2000) as u16 * 8 + k
}

/// examples/stack-rdt.toml on `port`, the emulator given `netft_args` as well.
fn stack_file(tag: &str, port: u16, netft_args: &[&str]) -> PathBuf {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/stack-rdt.toml"
    ))
    .unwrap();
    let mut extra = String::new();
    for a in netft_args {
        extra += &format!(", \"{a}\"");
    }
    let text = text
        .replace(
            "args = [\"--port\", \"49152\"",
            &format!("args = [\"--port\", \"{port}\"{extra}"),
        )
        .replace("127.0.0.1:49152", &format!("127.0.0.1:{port}"))
        .replace("\"49153\"", &format!("\"{}\"", port + 1000));
    assert!(text.contains(&format!("\"--port\", \"{port}\"")));
    assert!(text.contains(&format!("\"{}\"", port + 1000)));
    let path = std::env::temp_dir().join(format!("afs-test-{}-{tag}.toml", std::process::id()));
    std::fs::write(&path, text).unwrap();
    path
}

/// `afs run --config <stack> --json --quiet --prefix P` with `args`.
fn run_rdt(p: &str, stack: &PathBuf, args: &[&str]) -> (std::process::Output, RunReport) {
    let out = afs()
        .arg("run")
        .arg("--config")
        .arg(stack)
        .args(["--json", "--quiet", "--prefix", p])
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.code().is_some_and(|c| c <= 1),
        "afs run ended with an error: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r = run_report(&out);
    (out, r)
}

/// Surface tracking (the force loop and the estimator's probes) and friction suppression (the
/// dither tuned on the force signal, the scenario the sensor's rate matters most to) on the
/// emulated sensor pass their checks and agree with their lockstep references; the device's
/// stream arrives whole (nothing lost, repeated, reordered or with a bad status) and the
/// servo's gate refuses nothing. The corner and friction-identification scenarios read the
/// force through the same board and gate (tests/stack, on the built-in sensor).
#[test]
fn tracking_and_suppression_pass_on_the_emulated_sensor() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let stack = stack_file("all", port(0), &[]);
    for scenario in ["surface-tracking", "friction-suppression"] {
        let p = prefix(&format!("rdt{}", &scenario[..4]));
        let _clean = CleanPrefix(p.clone());
        // 6 s: long enough for each scenario's checks (a tangent estimate, a friction window).
        let (out, r) = run_rdt(&p, &stack, &["--scenario", scenario, "--duration", "6"]);
        assert!(
            out.status.success() && r.passed,
            "{scenario}: {}\n{}",
            failed(&r),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(r.agreement.agrees, "{scenario}: {:#?}", r.agreement);
        let s = r.sensor.expect("the sensor board's statistics");
        let d = s.rdt.expect("an RDT source");
        assert!(d.records > 30_000, "{scenario}: {d:?}");
        assert_eq!(
            (
                d.lost,
                d.repeated,
                d.reordered,
                d.status_errors,
                d.bad_datagrams
            ),
            (0, 0, 0, 0, 0),
            "{scenario}: {d:?}"
        );
        assert_eq!(s.published, d.records - d.late, "{scenario}: {s:?}");
        let g = r.loop_stats.expect("loop statistics").bad_samples;
        assert_eq!(
            g.non_finite + g.out_of_range + g.seq_repeat + g.seq_backwards + g.future,
            0,
            "{scenario}: {g:?}"
        );
        assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
    }
    let _ = std::fs::remove_file(stack);
}

/// The emulator loses, duplicates and reorders 1 % of its datagrams each, and its sequence
/// numbers wrap at 2^32 three seconds in: the board counts each kind, publishes none of the
/// repeated or reordered records (the servo's gate sees no repeated or backward sample) and
/// the scenario still passes against its lockstep.
#[test]
fn a_lossy_device_is_counted_and_never_feeds_the_servo_old_data() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let stack = stack_file(
        "lossy",
        port(1),
        &[
            "--loss",
            "0.01",
            "--duplicate",
            "0.01",
            "--reorder",
            "0.01",
            "--wrap-in",
            "21000",
        ],
    );
    let p = prefix("rdtlossy");
    let _clean = CleanPrefix(p.clone());
    let (out, r) = run_rdt(&p, &stack, &["--duration", "8"]);
    assert!(
        out.status.success() && r.passed && r.agreement.agrees,
        "{}\n{:#?}",
        failed(&r),
        r.agreement
    );
    let s = r.sensor.expect("the sensor board's statistics");
    let d = s.rdt.expect("an RDT source");
    // Past the wrap: more than 21 000 records, and the wrap itself cost nothing.
    assert!(d.records > 40_000, "{d:?}");
    let sent = (d.records - d.repeated + d.lost) as f64;
    for (what, n) in [
        ("lost", d.lost),
        ("repeated", d.repeated),
        ("reordered", d.reordered),
    ] {
        let f = n as f64 / sent;
        assert!((0.005..0.02).contains(&f), "{what}: {n} of {sent} ({d:?})");
    }
    assert_eq!(
        s.published,
        d.records - d.repeated - d.reordered - d.late,
        "{s:?}"
    );
    let g = r.loop_stats.expect("loop statistics").bad_samples;
    assert_eq!(
        (g.seq_repeat, g.seq_backwards, g.future),
        (0, 0, 0),
        "{g:?}"
    );
    assert!(leftovers(&p).is_empty());
    let _ = std::fs::remove_file(stack);
}

/// Half a second of records with an error status, then a device that goes silent: no record
/// with a bad status is published, the board asks for the stream again, and each time the
/// servo goes safe within its force-age limit of the last good sample.
#[test]
fn a_bad_status_or_a_silent_device_puts_the_servo_in_its_safe_state() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let device = std::env::temp_dir().join(format!("afs-test-{}-netft.json", std::process::id()));
    let device_arg = device.display().to_string();
    let stack = stack_file(
        "silent",
        port(2),
        &[
            "--status-error-at-s",
            "2",
            "--status-error-s",
            "0.5",
            "--silent-at-s",
            "4.6",
            "--summary",
            &device_arg,
        ],
    );
    let p = prefix("rdtsilent");
    let _clean = CleanPrefix(p.clone());
    let (_, r) = run_rdt(&p, &stack, &["--duration", "5"]);
    let s = r.sensor.expect("the sensor board's statistics");
    let d = s.rdt.expect("an RDT source");
    // Every record the device sent with an error status is counted as one, or lost on the
    // way; none is counted that the device did not send.
    let sent: afs::boards::netft::NetftSummary =
        serde_json::from_str(&std::fs::read_to_string(&device).expect("the device's summary"))
            .unwrap();
    assert!(sent.error_records > 0, "{sent:?}");
    assert!(d.status_errors <= sent.error_records, "{d:?} {sent:?}");
    assert!(
        sent.error_records - d.status_errors <= d.lost,
        "error records neither counted nor lost: {d:?} {sent:?}"
    );
    assert_eq!(d.last_status, afs_shared::rdt::STATUS_ERROR);
    assert!(!d.streaming && d.requests >= 2, "{d:?}");
    assert_eq!(s.published + d.status_errors + d.late, d.records, "{s:?}");
    let f = r.faults;
    assert!(f.safe_entries >= 2, "{f:?}");
    assert!(
        f.safe_after_last_good_ms_max <= FORCE_AGE_LIMIT_MS + SAFE_ALLOWANCE_MS,
        "{f:?}"
    );
    assert_eq!(f.controller_non_finite, 0);
    assert_eq!(process(&r, "sensor").restarts, 0);
    assert!(leftovers(&p).is_empty());
    let _ = std::fs::remove_file(stack);
    let _ = std::fs::remove_file(device);
}

/// The sensor board killed twice mid-stream (it never says stop): each successor asks from the
/// same local port, the device takes it as the same client, and the data flows again; the
/// run passes `afs chaos`'s checks.
#[test]
fn a_killed_sensor_board_gets_its_device_back() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let stack = stack_file("kill", port(4), &[]);
    let p = prefix("rdtkill");
    let _clean = CleanPrefix(p.clone());
    let out = afs()
        .arg("chaos")
        .arg("--config")
        .arg(&stack)
        .args(["--json", "--quiet", "--prefix", &p, "--duration", "10"])
        .args(["--kills", "2", "--faults", "kill-sensor"])
        .output()
        .unwrap();
    let r = run_report(&out);
    // The agreement's figures with the failure. A lockstep disagreement here failed three CI
    // runs: the tracker's slope trigger fires on each run's own noise after the kill, and with
    // no estimate completed the tangent error is now reported, not compared (docs/stack.md,
    // *Agreement with the lockstep*). The timing targets are reported, not asserted: at normal
    // priority a late tick puts the safe state past the 2-ms target.
    assert!(
        correct(&out, &r),
        "{}\n{:#?}\n{}",
        failed(&r),
        r.agreement,
        String::from_utf8_lossy(&out.stderr)
    );
    let sensor = process(&r, "sensor");
    assert_eq!(sensor.restarts, 2, "{sensor:?}");
    for e in &sensor.exits {
        assert!(e.back_ms.is_some(), "the device never came back: {e:?}");
    }
    assert!(r.sensor.and_then(|s| s.rdt).is_some_and(|d| d.records > 0));
    assert!(leftovers(&p).is_empty());
    let _ = std::fs::remove_file(stack);
}

fn netft(p: &str, port: u16, args: &[&str]) -> KillOnDrop {
    KillOnDrop(Some(
        Command::new(env!("CARGO_BIN_EXE_afs-netft"))
            .args(["--prefix", p, "--port", &port.to_string()])
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    ))
}

fn sensor_cli(p: &str, address: &str, args: &[&str]) -> Command {
    let mut c = afs();
    c.args(["sensor", "--address", address, "--prefix", p])
        .args(args);
    c
}

/// `afs sensor` against the emulator losing 2 % of its datagrams: every record published or
/// counted late, the loss counted, the samples recorded; a second client is refused while the first streams; a
/// closed port and a port that answers with something else are each named.
#[test]
fn afs_sensor_streams_a_device_and_names_what_is_wrong() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("cli");
    let _clean = CleanPrefix(p.clone());
    let port = port(3);
    let addr = format!("127.0.0.1:{port}");
    let dev = netft(&p, port, &["--loss", "0.02"]);
    let rec = std::env::temp_dir().join(format!("afs-test-{}-sensor.mcap", std::process::id()));
    let out = sensor_cli(&p, &addr, &["--duration", "2", "--json"])
        .arg("--record")
        .arg(&rec)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: SensorToolReport = report_of(&out);
    // Every record that arrived is published or counted late (the rate is reported, not
    // judged here: it is the machine's).
    assert!(r.rdt.records > 0, "{r:?}");
    assert_eq!(r.published + r.rdt.late, r.rdt.records, "{r:?}");
    assert!((0.01..0.035).contains(&r.loss_fraction), "{r:?}");
    let recorded = r.record.as_ref().expect("a recording");
    assert_eq!(recorded.messages.get("/wrench").copied(), Some(r.published));
    assert_eq!(recorded.dropped, 0);
    let _ = std::fs::remove_file(&rec);

    // One client at a time.
    let first = KillOnDrop(Some(
        sensor_cli(&format!("{p}b"), &addr, &["--duration", "4"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    ));
    std::thread::sleep(Duration::from_millis(500));
    let busy = sensor_cli(&format!("{p}c"), &addr, &["--duration", "1"])
        .output()
        .unwrap();
    assert_refused(&busy, &"a second client", "streaming to another client");
    assert!(finish(first.take(), "the first client").status.success());
    // SIGTERM: the emulator stops in order and releases its prefix.
    let dev = dev.take();
    unsafe { libc::kill(dev.id() as i32, libc::SIGTERM) };
    assert!(finish(dev, "afs-netft").status.success());

    // Nothing listening.
    let closed = sensor_cli(&format!("{p}d"), &format!("127.0.0.1:{}", port + 4), &[])
        .output()
        .unwrap();
    assert_refused(&closed, &"a closed port", "nothing listens");

    // Something that is not RDT: 20-byte answers.
    let fake = UdpSocket::bind("127.0.0.1:0").unwrap();
    let fake_addr = fake.local_addr().unwrap().to_string();
    fake.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let responder = std::thread::spawn(move || {
        let mut buf = [0u8; 64];
        for _ in 0..50 {
            let Ok((_, from)) = fake.recv_from(&mut buf) else {
                break;
            };
            for _ in 0..5 {
                let _ = fake.send_to(&[7u8; 20], from);
            }
        }
    });
    let wrong = sensor_cli(&format!("{p}e"), &fake_addr, &[])
        .output()
        .unwrap();
    assert_refused(
        &wrong,
        &"a port answering 20-byte datagrams",
        "20-byte datagrams",
    );
    // Not joined: the responder waits out its 5-s read timeout once the client has gone (the
    // test's process ends it).
    drop(responder);
    for q in ["", "b", "c", "d", "e"] {
        let q = format!("{p}{q}");
        assert!(leftovers(&q).is_empty(), "{q}: {:?}", leftovers(&q));
    }
}
