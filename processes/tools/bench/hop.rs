//! The hop part: ping-pong between this process (CPU 0) and `afs bench-peer` (CPU 1) over every
//! transport in interleaved rounds.

use super::transport::{
    AtomicPage, PING, PONG, QUIT, TRANSPORTS, UPSTREAM, command, initiator_ports, ping,
};
use super::{BenchOptions, PartReport, Series, finish_part, upstream};
use crate::hist::{self, QuantilesUs};
use crate::ipc;
use afs_shared::check::Check;
use anyhow::{Context, Result, bail};
use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};
use std::os::unix::net::{UnixListener, UnixStream};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A ratio measured on the round trip and one way.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct RttOneWay {
    /// Round trip.
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub rtt: f64,
    /// One way.
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub oneway: f64,
}

impl RttOneWay {
    /// Each figure over `other`'s.
    fn over(&self, other: &RttOneWay) -> RttOneWay {
        RttOneWay {
            rtt: self.rtt / other.rtt,
            oneway: self.oneway / other.oneway,
        }
    }

    /// Each figure minus one (a ratio as an overhead).
    fn minus_one(self) -> RttOneWay {
        RttOneWay {
            rtt: self.rtt - 1.0,
            oneway: self.oneway - 1.0,
        }
    }
}

/// The hop part's ratios at the median.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct HopRatios {
    /// afs busy-poll over the atomic floor.
    pub afs_poll_over_atomic_p50: RttOneWay,
    /// Unix socket over afs busy-poll.
    pub unix_socket_over_afs_poll_p50: RttOneWay,
    /// afs busy-poll over bare iceoryx2, minus one.
    pub afs_overhead_over_bare_iceoryx2_p50: RttOneWay,
    /// afs busy-poll one way over iceoryx2's own benchmark's method (two threads).
    #[serde(default)]
    pub afs_poll_over_upstream_method_p50: f64,
    /// Upstream's method across two processes over the same in two threads.
    #[serde(default)]
    pub upstream_processes_over_threads_p50: f64,
    /// The bare iceoryx2 series (per message, timed) over upstream's method across the same
    /// two processes (per batch).
    #[serde(default)]
    pub bare_over_upstream_processes_p50: f64,
}

/// Sizes of the ping and the pong (bytes).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Payload {
    /// The ping (a wrench sample's size).
    pub ping: usize,
    /// The pong (a servo sample's size).
    pub pong: usize,
}

/// Where the two ends ran.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct HopCpus {
    /// This process.
    pub initiator: usize,
    /// `afs bench-peer`.
    pub peer: usize,
}

/// The hop part's report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct HopReport {
    /// Interleaved rounds.
    pub rounds: u32,
    /// Samples in every series.
    pub samples_per_series: u64,
    /// Message sizes.
    pub payload_bytes: Payload,
    /// CPUs.
    pub cpus: HopCpus,
    /// Ratios at the median.
    pub ratios: HopRatios,
    /// Series, targets, files.
    #[serde(flatten)]
    pub part: PartReport,
}

pub(super) fn hop(opts: &BenchOptions, stop: &AtomicBool) -> Result<HopReport> {
    let prefix = format!("{}h", opts.prefix);
    ipc::claim_prefix(&prefix)?;
    let dir = std::env::temp_dir().join(format!("afs-bench-{prefix}-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let sock_path = dir.join("ctl.sock");
    let listener = UnixListener::bind(&sock_path)
        .with_context(|| format!("binding {}", sock_path.display()))?;
    let result = std::thread::scope(|sc| {
        sc.spawn(|| measure(opts, stop, &prefix, &listener, &sock_path))
            .join()
            .map_err(|_| anyhow::anyhow!("the hop thread panicked"))?
    });
    let _ = std::fs::remove_dir_all(&dir);
    let _ = ipc::release_prefix(&prefix);
    result
}

/// Interleaved rounds of every transport, run from CPU 0 against the peer on CPU 1.
const ROUNDS: u32 = 40;

/// The per-message series, and the upstream method's per batch (one way, ns).
struct Measured {
    rtt: Vec<Histogram<u64>>,
    one: Vec<Histogram<u64>>,
    upstream_threads: Histogram<u64>,
    /// Across the processes, by [`upstream::Extra::LADDER`].
    upstream_processes: Vec<Histogram<u64>>,
    per_round: u32,
}

/// The measurement, from the thread pinned to CPU 0.
fn measure(
    opts: &BenchOptions,
    stop: &AtomicBool,
    prefix: &str,
    listener: &UnixListener,
    sock_path: &std::path::Path,
) -> Result<HopReport> {
    crate::rt::pin_thread(0, "afs bench");
    let page = AtomicPage::open(prefix, true)?;
    let node = ipc::node(prefix, "bench-initiator")?;
    let ports = initiator_ports(&node)?;
    let up = upstream::Services::open(&node)?;
    let mut a = Some(upstream::Participant::open(&up, true)?);
    let mut peer = KillOnDrop(
        Command::new(std::env::current_exe().context("locating afs")?)
            .args(["bench-peer", "--prefix", prefix, "--cpu", "1", "--socket"])
            .arg(sock_path)
            .stdin(Stdio::null())
            .spawn()
            .context("starting the benchmark peer")?,
    );
    let mut sock = accept(listener, &mut peer.0)?;
    sock.set_read_timeout(Some(Duration::from_secs(10)))?;
    // Warm-up and calibration: 300 round trips each; the round trip's mean sets the sample
    // count so that the measurement lasts about the duration asked for.
    let mut seq = 1u64;
    let mut mean_sum = 0.0;
    for t in TRANSPORTS {
        command(&mut sock, t as u32, 300)?;
        let t0 = Instant::now();
        for _ in 0..300 {
            ping(t, seq, &ports, &page, &mut sock)?;
            seq += 1;
        }
        mean_sum += t0.elapsed().as_secs_f64() / 300.0;
    }
    // The upstream method's batches (one in threads, the ladder across the processes) take
    // about as long as as many more transports.
    let batches = TRANSPORTS.len() + 1 + upstream::Extra::LADDER.len();
    mean_sum *= batches as f64 / TRANSPORTS.len() as f64;
    let per_round =
        ((0.9 * opts.duration_s / mean_sum / f64::from(ROUNDS)) as u32).clamp(100, 2_000_000);
    let mut m = Measured {
        rtt: (0..5).map(|_| hist::new()).collect::<Result<_>>()?,
        one: (0..5).map(|_| hist::new()).collect::<Result<_>>()?,
        upstream_threads: hist::new()?,
        upstream_processes: (0..upstream::Extra::LADDER.len())
            .map(|_| hist::new())
            .collect::<Result<_>>()?,
        per_round,
    };
    for _ in 0..ROUNDS {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        for (i, t) in TRANSPORTS.into_iter().enumerate() {
            command(&mut sock, t as u32, per_round)?;
            for _ in 0..per_round {
                let (r, o) = ping(t, seq, &ports, &page, &mut sock)?;
                hist::record(&mut m.rtt[i], r);
                hist::record(&mut m.one[i], o);
                seq += 1;
            }
        }
        for (i, extra) in upstream::Extra::LADDER.into_iter().enumerate() {
            let p = a.take().expect("participant A").with(extra);
            command(&mut sock, UPSTREAM + extra.code(), per_round)?;
            let total = p.run_a(per_round);
            a = Some(p.with(upstream::Extra::default()));
            hist::record(
                &mut m.upstream_processes[i],
                total? / (2 * u64::from(per_round)),
            );
        }
        let p = a.as_ref().expect("participant A");
        let one_way = upstream::threads(&up, p, per_round, 1)?;
        hist::record(&mut m.upstream_threads, one_way.round() as u64);
    }
    command(&mut sock, QUIT, 0)?;
    let st = peer.0.wait()?;
    if !st.success() {
        bail!("the benchmark peer ended with {st}");
    }
    drop((ports, a, up, node));
    report(opts, m)
}

/// The series, their ratios and the targets.
fn report(opts: &BenchOptions, m: Measured) -> Result<HopReport> {
    let names_rtt = [
        "atomic_rtt",
        "afs_poll_rtt",
        "afs_event_rtt",
        "bare_iceoryx2_poll_rtt",
        "unix_socket_rtt",
    ];
    let names_one = [
        "atomic_oneway",
        "afs_poll_oneway",
        "afs_event_oneway",
        "bare_iceoryx2_poll_oneway",
        "unix_socket_oneway",
    ];
    let what = [
        "shared-memory atomic ping-pong, busy-polling (the floor)",
        "afs services and types (WrenchSample → ServoSample), busy-polling, sample gate",
        "the afs services with an iceoryx2 event per sample",
        "bare iceoryx2 publish-subscribe, same sizes, default settings, busy-polling",
        "Unix-domain stream socket, blocking reads",
    ];
    let mut series = Vec::new();
    for (i, (h, o)) in m.rtt.into_iter().zip(m.one).enumerate() {
        series.push(Series {
            name: names_rtt[i],
            what: what[i],
            floor: Some("atomic_rtt"),
            hist: h,
        });
        series.push(Series {
            name: names_one[i],
            what: what[i],
            floor: Some("atomic_oneway"),
            hist: o,
        });
    }
    series.push(Series {
        name: "upstream_threads_oneway",
        what: "iceoryx2's own benchmark's method: two threads of one process, loaned 104-byte slices, buffer 1, back to back, total / 2n per round",
        floor: Some("atomic_oneway"),
        hist: m.upstream_threads,
    });
    let across = [
        (
            "upstream_processes_oneway",
            "the same method across the two processes (this one and the peer)",
        ),
        (
            "upstream_processes_touch_oneway",
            "… writing the whole payload before each send and reading it on receipt",
        ),
        (
            "upstream_processes_touch_clock_oneway",
            "… and reading the clock before each send and after each receipt",
        ),
        (
            "upstream_processes_touch_clock_pause_oneway",
            "… and polling with a spin-loop hint (pause) between attempts, as the per-message series do",
        ),
        (
            "upstream_processes_touch_clock_pause_late_oneway",
            "… and loaning each message when it is sent, not while waiting: the per-message series' order",
        ),
    ];
    for ((name, what), hist) in across.into_iter().zip(m.upstream_processes) {
        series.push(Series {
            name,
            what,
            floor: Some("upstream_threads_oneway"),
            hist,
        });
    }
    let s = |n: &str| QuantilesUs::of(&series.iter().find(|x| x.name == n).expect("series").hist);
    let p50 = |rtt: &str, one: &str| RttOneWay {
        rtt: s(rtt).p50,
        oneway: s(one).p50,
    };
    let (atomic, afs, bare, uds) = (
        p50("atomic_rtt", "atomic_oneway"),
        p50("afs_poll_rtt", "afs_poll_oneway"),
        p50("bare_iceoryx2_poll_rtt", "bare_iceoryx2_poll_oneway"),
        p50("unix_socket_rtt", "unix_socket_oneway"),
    );
    let (up_threads, up_processes) = (
        s("upstream_threads_oneway").p50,
        s("upstream_processes_oneway").p50,
    );
    let ratios = HopRatios {
        afs_poll_over_atomic_p50: afs.over(&atomic),
        unix_socket_over_afs_poll_p50: uds.over(&afs),
        afs_overhead_over_bare_iceoryx2_p50: afs.over(&bare).minus_one(),
        afs_poll_over_upstream_method_p50: afs.oneway / up_threads,
        upstream_processes_over_threads_p50: up_processes / up_threads,
        bare_over_upstream_processes_p50: bare.oneway / up_processes,
    };
    let part = finish_part(
        "hop",
        &series,
        &[],
        targets(&ratios),
        &opts.out,
        "hop: round trip CPU 0 → CPU 1 → CPU 0 and one way",
    )?;
    Ok(HopReport {
        rounds: ROUNDS,
        samples_per_series: u64::from(ROUNDS) * u64::from(m.per_round),
        payload_bytes: Payload {
            ping: PING,
            pong: PONG,
        },
        cpus: HopCpus {
            initiator: 0,
            peer: 1,
        },
        ratios,
        part,
    })
}

/// The hop part's targets (reported, never asserted: the machine's, not afs's).
fn targets(r: &HopRatios) -> Vec<Check> {
    vec![
        Check::at_most(
            "afs_poll_over_atomic_oneway",
            "afs busy-poll p50 / atomic floor p50, one way",
            r.afs_poll_over_atomic_p50.oneway,
            10.0,
        )
        .target(),
        Check::at_most(
            "afs_poll_over_atomic_rtt",
            "afs busy-poll p50 / atomic floor p50, round trip",
            r.afs_poll_over_atomic_p50.rtt,
            10.0,
        )
        .target(),
        Check::at_least(
            "unix_socket_over_afs_poll_oneway",
            "Unix socket p50 / afs busy-poll p50, one way",
            r.unix_socket_over_afs_poll_p50.oneway,
            10.0,
        )
        .target(),
        Check::at_least(
            "unix_socket_over_afs_poll_rtt",
            "Unix socket p50 / afs busy-poll p50, round trip",
            r.unix_socket_over_afs_poll_p50.rtt,
            10.0,
        )
        .target(),
        Check::at_most(
            "afs_over_bare_iceoryx2_oneway",
            "afs overhead over bare iceoryx2 at p50, one way",
            r.afs_overhead_over_bare_iceoryx2_p50.oneway,
            0.10,
        )
        .target(),
        Check::at_most(
            "afs_over_bare_iceoryx2_rtt",
            "afs overhead over bare iceoryx2 at p50, round trip",
            r.afs_overhead_over_bare_iceoryx2_p50.rtt,
            0.10,
        )
        .target(),
        Check::at_most(
            "afs_over_upstream_method_oneway",
            "afs busy-poll one way p50 / iceoryx2's own benchmark's method p50",
            r.afs_poll_over_upstream_method_p50,
            UPSTREAM_TARGET,
        )
        .target(),
    ]
}

/// How far afs's one-way hop may be from iceoryx2's own benchmark's figure (docs/bench.md,
/// *Against upstream's figure*): afs adds a clock read on each side, a copy into the sample,
/// the sample gate and the answer's own message, on a path upstream measures bare.
const UPSTREAM_TARGET: f64 = 1.5;

fn accept(listener: &UnixListener, peer: &mut Child) -> Result<UnixStream> {
    listener.set_nonblocking(true)?;
    let t0 = Instant::now();
    loop {
        match listener.accept() {
            Ok((s, _)) => {
                s.set_nonblocking(false)?;
                return Ok(s);
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                if let Some(st) = peer.try_wait()? {
                    bail!("the benchmark peer exited before connecting ({st})");
                }
                if t0.elapsed() > Duration::from_secs(20) {
                    bail!("the benchmark peer did not connect within 20 s");
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(e) => return Err(e).context("accepting the benchmark peer"),
        }
    }
}

/// A child killed when dropped (an error path unwinding past it).
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}
