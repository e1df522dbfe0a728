//! `afs bench link`: what the link board costs and carries, in one invocation.
//!
//! Two "hosts" on one machine without namespaces: host A is the stack's prefix, host B a second
//! prefix (iceoryx2 keeps prefixes apart as it would keep machines apart; only the link board
//! joins them), the two link boards talking zenoh over loopback. Host B runs the estimator and
//! the far link board; host A runs `afs run` with `examples/stack-two-hosts.toml`'s graph. Both
//! prefixes read the same `CLOCK_MONOTONIC`, so one-way latencies are a subtraction.
//!
//! Series: the servo sample's age on arrival at a subscriber on host A (the same path on one
//! host) and at one on host B (across the link, batching included); the round trip of an
//! estimator request through the topic form, from host A across the link and on host B alone
//! (a ping the estimator refuses at once: version 0, so the figure is transport, not
//! estimation); the servo's wake latency in a run with the link and in a run of the plain stack
//! (estimator local) just before it.

use super::stack::{StackRun, run_stack};
use super::{BenchOptions, Series, finish_part};
use crate::hist;
use crate::ipc;
use crate::stack::{DEFAULT_STACK, resolve_binary};
use afs_shared::batch::SeqGaps;
use afs_shared::check::Check;
use afs_shared::msg::{TangentRequestHeader, TangentResponse};
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The stack file of host A.
const TWO_HOSTS_STACK: &str = include_str!("../../../examples/stack-two-hosts.toml");

/// Request ids of the pings (far above any the servo uses): across the link, on host B.
const PING_LINK: u64 = 1 << 63;
const PING_LOCAL: u64 = PING_LINK | (1 << 62);

/// Time between pings.
const PING_EVERY: Duration = Duration::from_millis(20);

/// What crossed and what did not.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct LinkLoss {
    /// Servo numbers read on host A (the same stream before the link).
    pub servo_host_a: SeqGaps,
    /// Servo numbers read on host B.
    pub servo_host_b: SeqGaps,
    /// Pings sent and answered across the link, from its first answer on (before it the
    /// tunnel is still discovering the services: counted in `pings_before_link_up`).
    pub pings_link: (u64, u64),
    /// Pings sent across the link before it first answered.
    pub pings_before_link_up: u64,
    /// Pings sent and answered on host B alone.
    pub pings_local: (u64, u64),
}

/// The link part's report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LinkPart {
    /// Series, targets, files.
    #[serde(flatten)]
    pub part: super::PartReport,
    /// What crossed.
    pub loss: LinkLoss,
    /// Each run with the link: passed its checks, and its tangent estimates (from host B).
    pub runs_with_link: Vec<(bool, u64)>,
    /// Each plain run passed.
    pub runs_without_link: Vec<bool>,
    /// Host B's link board's own summary of the last run (JSON), if it wrote one.
    pub link_board_b: Option<serde_json::Value>,
}

/// A child process stopped with SIGTERM (then SIGKILL) when dropped.
struct Board(Child);

impl Drop for Board {
    fn drop(&mut self) {
        // SAFETY: signalling our own child.
        unsafe {
            libc::kill(self.0.id() as i32, libc::SIGTERM);
        }
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(5) {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A TCP port on loopback that was free a moment ago.
fn free_port() -> Result<u16> {
    let l = std::net::TcpListener::bind("127.0.0.1:0").context("finding a free port")?;
    Ok(l.local_addr()?.port())
}

/// Runs the part.
pub fn link(opts: &BenchOptions, stop: &AtomicBool) -> Result<LinkPart> {
    let link_bin = resolve_binary("afs-link").context(
        "afs bench link needs the link board: build it with `cargo build --release --workspace`",
    )?;
    let est_bin = resolve_binary("afs-estimator")?;
    let a = format!("{}a", opts.prefix);
    let b = format!("{}b", opts.prefix);
    // Two rounds, each a plain run (estimator on host A) then a run with the link, so that
    // the wake latencies with and without it see the machine at about the same times.
    let mut wake_without = hist::new()?;
    let mut wake_with = hist::new()?;
    let mut measured: Option<Measured> = None;
    let mut runs_with = Vec::new();
    let mut runs_without = Vec::new();
    let mut link_board_b = None;
    let half = opts.duration_s / 2.0;
    for _ in 0..2 {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        ipc::claim_prefix(&a)?;
        let (without, _) = run_stack(DEFAULT_STACK, &a, half, &opts.out, &[], stop, |_| ())?;
        let _ = wake_without.add(&without.wake);
        runs_without.push(without.report.passed);
        if stop.load(Ordering::Relaxed) {
            break;
        }
        ipc::claim_prefix(&a)?;
        let (with, m, b_sum) = linked_run(opts, &a, &b, half, &link_bin, &est_bin, stop)?;
        let _ = wake_with.add(&with.wake);
        runs_with.push((
            with.report.passed,
            with.report.stack.tracking.estimations.estimates as u64,
        ));
        link_board_b = b_sum;
        measured = Some(match measured.take() {
            None => m,
            Some(mut acc) => {
                acc.merge(m);
                acc
            }
        });
    }
    let measured = measured.context("interrupted before a run with the link")?;
    let p99 = |h: &hdrhistogram::Histogram<u64>| h.value_at_quantile(0.99) as f64;
    let wake_ratio = p99(&wake_with) / p99(&wake_without);
    let targets = vec![
        Check::at_most(
            "servo_wake_p99_with_link_over_without",
            "servo wake p99 with the link / without",
            wake_ratio,
            1.1,
        )
        .target(),
        Check::at_most(
            "servo_samples_missing_on_host_b",
            "servo samples missing on host B",
            measured.loss.servo_host_b.missing as f64,
            0.0,
        ),
    ];
    let series = vec![
        Series {
            name: "sample_host_a",
            what: "servo sample's age on arrival, subscriber on host A (same host)",
            floor: None,
            hist: measured.sample_a,
        },
        Series {
            name: "sample_link",
            what: "servo sample's age on arrival, subscriber on host B (across the link, batching included)",
            floor: Some("sample_host_a"),
            hist: measured.sample_b,
        },
        Series {
            name: "rtt_host_b",
            what: "estimator request round trip, topic form, on host B alone",
            floor: None,
            hist: measured.rtt_local,
        },
        Series {
            name: "rtt_link",
            what: "estimator request round trip, topic form, from host A across the link",
            floor: Some("rtt_host_b"),
            hist: measured.rtt_link,
        },
        Series {
            name: "wake_without",
            what: "servo wake latency, plain stack (estimator on host A)",
            floor: None,
            hist: wake_without,
        },
        Series {
            name: "wake_with_link",
            what: "servo wake latency, estimator on host B through the link",
            floor: Some("wake_without"),
            hist: wake_with,
        },
    ];
    let part = finish_part(
        "link",
        &series,
        &[],
        targets,
        &opts.out,
        "afs bench link: latency (µs) against percentile",
    )?;
    Ok(LinkPart {
        part,
        loss: measured.loss,
        runs_with_link: runs_with,
        runs_without_link: runs_without,
        link_board_b,
    })
}

/// One run of host A's stack (prefix `a`) with host B (estimator and link board, prefix `b`);
/// returns the run, what was measured beside it, and host B's link board's summary.
fn linked_run(
    opts: &BenchOptions,
    a: &str,
    b: &str,
    duration_s: f64,
    link_bin: &std::path::Path,
    est_bin: &std::path::Path,
    stop: &AtomicBool,
) -> Result<(StackRun, Measured, Option<serde_json::Value>)> {
    ipc::claim_prefix(b)?;
    let (port_a, port_b) = (free_port()?, free_port()?);
    let b_summary = opts.out.join("link_board_b.json");
    let _ = std::fs::remove_file(&b_summary);
    let quiet = |c: &mut Command| {
        c.stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null());
    };
    let mut est = Command::new(est_bin);
    est.args(["--prefix", b]);
    quiet(&mut est);
    let estimator = Board(est.spawn().context("starting host B's estimator")?);
    let mut lk = Command::new(link_bin);
    lk.args(["--prefix", b, "--side", "remote"])
        .args(["--listen", &format!("tcp/127.0.0.1:{port_b}")])
        .args(["--connect", &format!("tcp/127.0.0.1:{port_a}")])
        .arg("--summary")
        .arg(&b_summary);
    quiet(&mut lk);
    let link_b = Board(lk.spawn().context("starting host B's link board")?);
    let stack_a = TWO_HOSTS_STACK.replace("tcp/127.0.0.1:7447", &format!("tcp/127.0.0.1:{port_a}"));
    let (with, measured) = run_stack(&stack_a, a, duration_s, &opts.out, &[], stop, |running| {
        measure(a, b, running)
    })?;
    let measured = measured?;
    drop(estimator);
    drop(link_b);
    let _ = ipc::release_prefix(b);
    let summary = std::fs::read_to_string(&b_summary)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    Ok((with, measured, summary))
}

/// What the thread beside the linked stack measured.
struct Measured {
    sample_a: hdrhistogram::Histogram<u64>,
    sample_b: hdrhistogram::Histogram<u64>,
    rtt_link: hdrhistogram::Histogram<u64>,
    rtt_local: hdrhistogram::Histogram<u64>,
    loss: LinkLoss,
}

impl Measured {
    /// Adds another run's measurements.
    fn merge(&mut self, o: Measured) {
        let _ = self.sample_a.add(&o.sample_a);
        let _ = self.sample_b.add(&o.sample_b);
        let _ = self.rtt_link.add(&o.rtt_link);
        let _ = self.rtt_local.add(&o.rtt_local);
        let (x, y) = (&mut self.loss, o.loss);
        for (acc, g) in [
            (&mut x.servo_host_a, y.servo_host_a),
            (&mut x.servo_host_b, y.servo_host_b),
        ] {
            acc.received += g.received;
            acc.missing += g.missing;
            acc.gaps += g.gaps;
            acc.backwards += g.backwards;
            acc.first_gaps.extend(g.first_gaps);
        }
        x.pings_link.0 += y.pings_link.0;
        x.pings_link.1 += y.pings_link.1;
        x.pings_local.0 += y.pings_local.0;
        x.pings_local.1 += y.pings_local.1;
        x.pings_before_link_up += y.pings_before_link_up;
    }
}

/// Reads the servo's stream on both hosts and pings the estimator both ways while `running`.
fn measure(a: &str, b: &str, running: &AtomicBool) -> Result<Measured> {
    let mut m = Measured {
        sample_a: hist::new()?,
        sample_b: hist::new()?,
        rtt_link: hist::new()?,
        rtt_local: hist::new()?,
        loss: LinkLoss::default(),
    };
    // Join host A once its servo is up (a node of ours before that would make `afs run`
    // refuse the prefix as taken).
    let t0 = Instant::now();
    loop {
        if !running.load(Ordering::Relaxed) {
            return Ok(m);
        }
        if ipc::census(a, false).is_ok_and(|c| c.alive.iter().any(|(n, _)| n == "servo")) {
            break;
        }
        if t0.elapsed() > Duration::from_secs(30) {
            bail!("host A's servo did not start within 30 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let na = ipc::node(a, "bench-link")?;
    let nb = ipc::node(b, "bench-link")?;
    let servo_a = ipc::servo(&na)?.subscriber_builder().create()?;
    let servo_b = ipc::servo(&nb)?.subscriber_builder().create()?;
    let req_a = ipc::tangent_requests(&na)?
        .publisher_builder()
        .initial_max_slice_len(1)
        .create()?;
    let req_b = ipc::tangent_requests(&nb)?
        .publisher_builder()
        .initial_max_slice_len(1)
        .create()?;
    let resp_a = ipc::tangent_responses(&na)?.subscriber_builder().create()?;
    let resp_b = ipc::tangent_responses(&nb)?.subscriber_builder().create()?;
    // Ping id → (time sent, counted: sent after the link first answered).
    let mut sent: BTreeMap<u64, (u64, bool)> = BTreeMap::new();
    let mut link_up = false;
    let mut servo_check = Instant::now();
    let mut k = 0u64;
    let mut next_ping = Instant::now();
    let ping = |id: u64,
                p: &iceoryx2::port::publisher::Publisher<
        ipc::Svc,
        [afs_shared::tangent::ProbeSample],
        TangentRequestHeader,
    >|
     -> bool {
        let Ok(mut s) = p.loan_slice(1) else {
            return false;
        };
        // Version 0: the estimator refuses it at once, so the round trip is the transport's.
        *s.user_header_mut() = TangentRequestHeader {
            request_id: id,
            publish_ns: crate::rt::monotonic_ns(),
            ..Default::default()
        };
        s.send().is_ok()
    };
    while running.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(1));
        while let Ok(Some(s)) = servo_a.receive() {
            let now = crate::rt::monotonic_ns();
            hist::record(&mut m.sample_a, now.saturating_sub(s.payload().publish_ns));
            m.loss.servo_host_a.push(s.payload().seq);
        }
        while let Ok(Some(s)) = servo_b.receive() {
            let now = crate::rt::monotonic_ns();
            hist::record(&mut m.sample_b, now.saturating_sub(s.payload().publish_ns));
            m.loss.servo_host_b.push(s.payload().seq);
        }
        if Instant::now() >= next_ping {
            next_ping += PING_EVERY;
            k += 1;
            let now = crate::rt::monotonic_ns();
            if ping(PING_LINK | k, &req_a) {
                sent.insert(PING_LINK | k, (now, link_up));
                if link_up {
                    m.loss.pings_link.0 += 1;
                } else {
                    m.loss.pings_before_link_up += 1;
                }
            }
            if ping(PING_LOCAL | k, &req_b) {
                sent.insert(PING_LOCAL | k, (now, true));
                m.loss.pings_local.0 += 1;
            }
        }
        let mut answers = |r: &TangentResponse, from_a: bool| {
            let id = r.request_id;
            // Host A hears the pings across the link; host B hears its own.
            let mine = if from_a {
                id & PING_LOCAL == PING_LINK
            } else {
                id & PING_LOCAL == PING_LOCAL
            };
            if mine && let Some((t, counted)) = sent.remove(&id) {
                let now = crate::rt::monotonic_ns();
                if from_a {
                    hist::record(&mut m.rtt_link, now.saturating_sub(t));
                    link_up = true;
                    if counted {
                        m.loss.pings_link.1 += 1;
                    }
                } else {
                    hist::record(&mut m.rtt_local, now.saturating_sub(t));
                    m.loss.pings_local.1 += 1;
                }
            }
        };
        while let Ok(Some(r)) = resp_a.receive() {
            answers(r.payload(), true);
        }
        while let Ok(Some(r)) = resp_b.receive() {
            answers(r.payload(), false);
        }
        // Pings unanswered for 5 s are lost.
        let old = crate::rt::monotonic_ns().saturating_sub(5_000_000_000);
        sent.retain(|_, (t, _)| *t > old);
        // Leave once host A's servo has finished: the supervisor then checks the prefix for
        // leftovers, and this thread's node would be one.
        if servo_check.elapsed() > Duration::from_millis(100) {
            servo_check = Instant::now();
            if ipc::census(a, false).is_ok_and(|c| !c.alive.iter().any(|(n, _)| n == "servo")) {
                break;
            }
        }
    }
    Ok(m)
}
