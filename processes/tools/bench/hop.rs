//! The hop part: ping-pong between this process (CPU 0) and `afs bench-peer` (CPU 1) over every
//! transport in interleaved rounds.

use super::transport::{
    AtomicPage, PING, PONG, QUIT, TRANSPORTS, command, initiator_ports, pin_thread, ping,
};
use super::{BenchOptions, PartReport, Series, finish_part};
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

/// The hop part's ratios at the median.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct HopRatios {
    /// afs busy-poll over the atomic floor.
    pub afs_poll_over_atomic_p50: RttOneWay,
    /// Unix socket over afs busy-poll.
    pub unix_socket_over_afs_poll_p50: RttOneWay,
    /// afs busy-poll over bare iceoryx2, minus one.
    pub afs_overhead_over_bare_iceoryx2_p50: RttOneWay,
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
    let duration = opts.duration_s;
    let result = std::thread::scope(|sc| {
        sc.spawn(|| -> Result<HopReport> {
            pin_thread(0);
            let page = AtomicPage::open(&prefix, true)?;
            let node = ipc::node(&prefix, "bench-initiator")?;
            let ports = initiator_ports(&node)?;
            let mut peer = KillOnDrop(
                Command::new(std::env::current_exe().context("locating afs")?)
                    .args(["bench-peer", "--prefix", &prefix, "--cpu", "1", "--socket"])
                    .arg(&sock_path)
                    .stdin(Stdio::null())
                    .spawn()
                    .context("starting the benchmark peer")?,
            );
            let mut sock = accept(&listener, &mut peer.0)?;
            sock.set_read_timeout(Some(Duration::from_secs(10)))?;
            // Warm-up and calibration: 300 round trips each; the round trip's mean sets the
            // sample count so that the measurement lasts about `duration`.
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
            let rounds = 40u32;
            let per_round =
                ((0.9 * duration / mean_sum / f64::from(rounds)) as u32).clamp(100, 2_000_000);
            let mut rtt: Vec<Histogram<u64>> =
                (0..5).map(|_| hist::new()).collect::<Result<_>>()?;
            let mut one: Vec<Histogram<u64>> =
                (0..5).map(|_| hist::new()).collect::<Result<_>>()?;
            for _ in 0..rounds {
                for (i, t) in TRANSPORTS.into_iter().enumerate() {
                    if stop.load(Ordering::Relaxed) {
                        break;
                    }
                    command(&mut sock, t as u32, per_round)?;
                    for _ in 0..per_round {
                        let (r, o) = ping(t, seq, &ports, &page, &mut sock)?;
                        hist::record(&mut rtt[i], r);
                        hist::record(&mut one[i], o);
                        seq += 1;
                    }
                }
            }
            command(&mut sock, QUIT, 0)?;
            let st = peer.0.wait()?;
            if !st.success() {
                bail!("the benchmark peer ended with {st}");
            }
            drop(ports);
            drop(node);
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
            for (i, (h, o)) in rtt.into_iter().zip(one).enumerate() {
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
            let s = |n: &str| {
                QuantilesUs::of(&series.iter().find(|x| x.name == n).expect("series").hist)
            };
            let (atomic, afs, bare, uds) = (
                s("atomic_rtt"),
                s("afs_poll_rtt"),
                s("bare_iceoryx2_poll_rtt"),
                s("unix_socket_rtt"),
            );
            let (atomic1, afs1, bare1, uds1) = (
                s("atomic_oneway"),
                s("afs_poll_oneway"),
                s("bare_iceoryx2_poll_oneway"),
                s("unix_socket_oneway"),
            );
            let ratios = HopRatios {
                afs_poll_over_atomic_p50: RttOneWay {
                    rtt: afs.p50 / atomic.p50,
                    oneway: afs1.p50 / atomic1.p50,
                },
                unix_socket_over_afs_poll_p50: RttOneWay {
                    rtt: uds.p50 / afs.p50,
                    oneway: uds1.p50 / afs1.p50,
                },
                afs_overhead_over_bare_iceoryx2_p50: RttOneWay {
                    rtt: afs.p50 / bare.p50 - 1.0,
                    oneway: afs1.p50 / bare1.p50 - 1.0,
                },
            };
            let targets = vec![
                Check::at_most(
                    "afs_poll_over_atomic_oneway",
                    "afs busy-poll p50 / atomic floor p50, one way",
                    ratios.afs_poll_over_atomic_p50.oneway,
                    10.0,
                )
                .target(),
                Check::at_most(
                    "afs_poll_over_atomic_rtt",
                    "afs busy-poll p50 / atomic floor p50, round trip",
                    ratios.afs_poll_over_atomic_p50.rtt,
                    10.0,
                )
                .target(),
                Check::at_least(
                    "unix_socket_over_afs_poll_oneway",
                    "Unix socket p50 / afs busy-poll p50, one way",
                    ratios.unix_socket_over_afs_poll_p50.oneway,
                    10.0,
                )
                .target(),
                Check::at_least(
                    "unix_socket_over_afs_poll_rtt",
                    "Unix socket p50 / afs busy-poll p50, round trip",
                    ratios.unix_socket_over_afs_poll_p50.rtt,
                    10.0,
                )
                .target(),
                Check::at_most(
                    "afs_over_bare_iceoryx2_oneway",
                    "afs overhead over bare iceoryx2 at p50, one way",
                    ratios.afs_overhead_over_bare_iceoryx2_p50.oneway,
                    0.10,
                )
                .target(),
                Check::at_most(
                    "afs_over_bare_iceoryx2_rtt",
                    "afs overhead over bare iceoryx2 at p50, round trip",
                    ratios.afs_overhead_over_bare_iceoryx2_p50.rtt,
                    0.10,
                )
                .target(),
            ];
            let part = finish_part(
                "hop",
                &series,
                &[],
                targets,
                &opts.out,
                "hop: round trip CPU 0 → CPU 1 → CPU 0 and one way",
            )?;
            Ok(HopReport {
                rounds,
                samples_per_series: u64::from(rounds) * u64::from(per_round),
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
        })
        .join()
        .map_err(|_| anyhow::anyhow!("the hop thread panicked"))?
    });
    let _ = std::fs::remove_dir_all(&dir);
    let _ = ipc::release_prefix(&prefix);
    result
}

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
