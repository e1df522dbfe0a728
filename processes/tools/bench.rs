//! `afs bench`: latency and jitter against the machine's floor and the usual alternatives.
//!
//! * **hop**: ping-pong between this process (CPU 0) and a peer (`afs bench-peer`, CPU 1),
//!   both at normal priority (busy-polling at SCHED_FIFO would starve a 2-core machine), over
//!   five transports in interleaved rounds with the same sample count each: a shared-memory
//!   atomic ping-pong (the floor), afs's own services and message types through iceoryx2
//!   busy-polling (`WrenchSample` out, `ServoSample` back, the servo's sample gate on
//!   receipt), the same with iceoryx2 event wake-up, a bare iceoryx2 publish-subscribe pair of
//!   the same sizes with default settings, and a Unix-domain socket. Round trip measured by
//!   the initiator; one way (initiator → peer) from the timestamp in the ping, both processes
//!   reading the same `CLOCK_MONOTONIC`.
//! * **loop**: a stack runs surface-tracking while a bare absolute-time sleep loop runs beside
//!   its servo at the same SCHED_FIFO priority on the same core, half a period out of phase:
//!   both see the same machine at the same time.
//! * **stack**: the full graph's force-data age at use, servo wake latency and misses, without
//!   and with a CPU hog on the other core, in four alternating stack runs of half the duration.
//!
//! Each part writes one `.hgrm` per series (HdrHistogram's percentile distribution) and a
//! percentile plot into `--out`, and reports p50 … max per series with its ratio to its floor,
//! every ratio from series measured in the same invocation.

use crate::hist::{self, Summary};
use crate::ipc::{self, Svc};
use crate::rt;
use crate::supervisor::{DEFAULT_STACK, StackFile};
use afs_shared::msg::{ServoSample, VERSION, WrenchSample};
use afs_shared::watchdog::{GateParams, SampleGate};
use anyhow::{Context, Result, bail};
use hdrhistogram::Histogram;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use serde::Serialize;
use serde_json::{Value, json};
use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Which part to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Part {
    /// Message hop latency between two processes.
    Hop,
    /// Servo wake jitter against a bare loop.
    Loop,
    /// The full graph, without and with a CPU hog.
    Stack,
    /// All three.
    All,
}

/// What `afs bench` was asked.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Part(s) to run.
    pub part: Part,
    /// Seconds of measurement per part (the stack part runs twice this: without and with hog).
    pub duration_s: f64,
    /// Directory for histograms and plots.
    pub out: PathBuf,
    /// Prefix for the shared memory of the benchmark's stacks and services.
    pub prefix: String,
}

/// A measured series.
struct Series {
    name: &'static str,
    what: &'static str,
    floor: Option<&'static str>,
    hist: Histogram<u64>,
}

/// A fixed floor (e.g. the sensor period) a series is compared with.
struct ConstFloor {
    name: &'static str,
    value_us: f64,
}

/// One target of the issue and whether this run met it.
#[derive(Debug, Clone, Serialize)]
struct Target {
    name: String,
    value: f64,
    limit: f64,
    relation: &'static str,
    met: bool,
}

fn target(name: &str, value: f64, relation: &'static str, limit: f64) -> Target {
    let met = match relation {
        "<=" => value <= limit,
        _ => value >= limit,
    };
    Target {
        name: name.into(),
        value,
        limit,
        relation,
        met,
    }
}

/// Runs the benchmark; returns the JSON report.
pub fn run(opts: &BenchOptions, stop: &AtomicBool) -> Result<Value> {
    if !(opts.duration_s.is_finite() && opts.duration_s > 0.0 && opts.duration_s <= 3600.0) {
        bail!(
            "--duration {} must be a number of seconds in (0, 3600]",
            opts.duration_s
        );
    }
    ipc::check_prefix(&opts.prefix)?;
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("creating {}", opts.out.display()))?;
    let t0 = Instant::now();
    let mut report = serde_json::Map::new();
    report.insert("bench".into(), json!(part_name(opts.part)));
    report.insert("duration_s".into(), json!(opts.duration_s));
    report.insert(
        "machine".into(),
        json!({ "cpus": rt::available_cpus(), "kernel": kernel() }),
    );
    let all = opts.part == Part::All;
    if all || opts.part == Part::Hop {
        report.insert("hop".into(), hop(opts, stop)?);
    }
    if (all || opts.part == Part::Loop) && !stop.load(Ordering::Relaxed) {
        report.insert("loop".into(), jitter(opts, stop)?);
    }
    if (all || opts.part == Part::Stack) && !stop.load(Ordering::Relaxed) {
        report.insert("stack".into(), stack(opts, stop)?);
    }
    report.insert("wall_s".into(), json!(t0.elapsed().as_secs_f64()));
    report.insert("interrupted".into(), json!(stop.load(Ordering::Relaxed)));
    Ok(Value::Object(report))
}

fn part_name(p: Part) -> &'static str {
    match p {
        Part::Hop => "hop",
        Part::Loop => "loop",
        Part::Stack => "stack",
        Part::All => "all",
    }
}

fn kernel() -> String {
    crate::procfs::kernel_release().unwrap_or_default()
}

/// Writes every series' `.hgrm`, the percentile plot, and returns the series' JSON.
fn finish_part(
    part: &str,
    series: &[Series],
    consts: &[ConstFloor],
    out: &Path,
    title: &str,
) -> Result<(serde_json::Map<String, Value>, Vec<String>)> {
    let mut files = Vec::new();
    let mut map = serde_json::Map::new();
    for s in series {
        let f = out.join(format!("{part}_{}.hgrm", s.name));
        hist::write_hgrm(&s.hist, &f)?;
        files.push(f.display().to_string());
        let sum = Summary::of(&s.hist);
        let mut v = json!({ "what": s.what, "summary_us": sum });
        if let Some(fl) = s.floor {
            if let Some(f) = series.iter().find(|x| x.name == fl) {
                v["floor"] = json!(fl);
                v["ratio_to_floor"] = json!(sum.ratio_to(&Summary::of(&f.hist)));
            } else if let Some(c) = consts.iter().find(|c| c.name == fl) {
                v["floor"] = json!(format!("{} ({:.3} µs)", c.name, c.value_us));
                v["ratio_to_floor"] = json!(sum.ratio_to(&Summary::constant(c.value_us)));
            }
        }
        map.insert(s.name.into(), v);
    }
    let plot = out.join(format!("{part}.svg"));
    percentile_plot(series, &plot, title)?;
    files.push(plot.display().to_string());
    Ok((map, files))
}

/// Latency against percentile ("nines" on the x axis), log scale, one line per series.
fn percentile_plot(series: &[Series], path: &Path, title: &str) -> Result<()> {
    use plotters::prelude::*;
    let lines: Vec<(&str, Vec<(f64, f64)>)> = series
        .iter()
        .filter(|s| !s.hist.is_empty())
        .map(|s| {
            let pts = (0..=50)
                .map(|k| {
                    let nines = k as f64 / 10.0;
                    let q = 1.0 - 10f64.powf(-nines);
                    (nines, (s.hist.value_at_quantile(q) as f64 / 1e3).max(0.01))
                })
                .collect();
            (s.name, pts)
        })
        .collect();
    let lo = lines
        .iter()
        .flat_map(|l| l.1.iter().map(|p| p.1))
        .fold(f64::INFINITY, f64::min)
        .max(0.01);
    let hi = lines
        .iter()
        .flat_map(|l| l.1.iter().map(|p| p.1))
        .fold(0.0, f64::max)
        .max(lo * 10.0);
    let root = SVGBackend::new(path, (900, 560)).into_drawing_area();
    let draw = || -> std::result::Result<(), Box<dyn std::error::Error>> {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(0f64..5f64, (lo * 0.8..hi * 1.25).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("percentile (nines: 1 = p90, 2 = p99, 3 = p99.9, 4 = p99.99)")
            .y_desc("latency (µs)")
            .draw()?;
        for (i, (name, pts)) in lines.iter().enumerate() {
            let c = Palette99::pick(i).to_rgba();
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))?
                .label(*name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))
}

// ---------------------------------------------------------------------------------------------
// hop

/// Transports of the hop benchmark, in round order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
enum Transport {
    Atomic = 0,
    AfsPoll = 1,
    AfsEvent = 2,
    BarePoll = 3,
    Uds = 4,
}

const TRANSPORTS: [Transport; 5] = [
    Transport::Atomic,
    Transport::AfsPoll,
    Transport::AfsEvent,
    Transport::BarePoll,
    Transport::Uds,
];

/// Control command that ends the peer.
const QUIT: u32 = u32::MAX;

/// Size of the ping (the wrench sample's) and of the pong (the servo sample's).
const PING: usize = std::mem::size_of::<WrenchSample>();
const PONG: usize = std::mem::size_of::<ServoSample>();

/// Longest wait for the peer's answer before the benchmark gives up.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(2);

const BARE_PING: &str = "afs/bench/bare_ping";
const BARE_PONG: &str = "afs/bench/bare_pong";
const EVENT_PING: &str = "afs/bench/ping_event";
const EVENT_PONG: &str = "afs/bench/pong_event";

/// The shared-memory page of the atomic ping-pong: a sequence number and a payload each way,
/// on separate cache lines.
struct AtomicPage {
    ptr: *mut u8,
    path: PathBuf,
    owner: bool,
}

const PAGE: usize = 4096;
const PING_SEQ: usize = 0;
const PING_DATA: usize = 64;
const PONG_SEQ: usize = 512;
const PONG_DATA: usize = 576;

impl AtomicPage {
    fn path(prefix: &str) -> PathBuf {
        PathBuf::from(format!("/dev/shm/{}bench_atomic", ipc::file_prefix(prefix)))
    }

    fn open(prefix: &str, create: bool) -> Result<Self> {
        let path = Self::path(prefix);
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(create)
            .truncate(create)
            .open(&path)
            .with_context(|| format!("opening {}", path.display()))?;
        if create {
            f.set_len(PAGE as u64)
                .with_context(|| format!("sizing {}", path.display()))?;
        }
        use std::os::fd::AsRawFd;
        // SAFETY: maps PAGE bytes of a file we hold open and sized; checked for MAP_FAILED.
        let ptr = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                PAGE,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                f.as_raw_fd(),
                0,
            )
        };
        if ptr == libc::MAP_FAILED {
            bail!(
                "mapping {}: {}",
                path.display(),
                std::io::Error::last_os_error()
            );
        }
        Ok(Self {
            ptr: ptr.cast(),
            path,
            owner: create,
        })
    }

    fn seq(&self, at: usize) -> &AtomicU64 {
        // SAFETY: `at` is 8-byte aligned inside the page-aligned mapping, which lives as long
        // as self; both processes access it only through atomics.
        unsafe { &*(self.ptr.add(at) as *const AtomicU64) }
    }

    fn write(&self, at: usize, data: &[u8]) {
        // SAFETY: in bounds (at + len ≤ PAGE); the reader reads only after the Release store
        // of the sequence number that follows.
        unsafe { std::ptr::copy_nonoverlapping(data.as_ptr(), self.ptr.add(at), data.len()) }
    }

    fn read(&self, at: usize, data: &mut [u8]) {
        // SAFETY: in bounds; read after the Acquire load that saw the writer's sequence number.
        unsafe { std::ptr::copy_nonoverlapping(self.ptr.add(at), data.as_mut_ptr(), data.len()) }
    }
}

impl Drop for AtomicPage {
    fn drop(&mut self) {
        // SAFETY: unmaps the mapping made in open.
        unsafe {
            libc::munmap(self.ptr.cast(), PAGE);
        }
        if self.owner {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Ports of one side of the hop benchmark.
struct Ports {
    afs_wrench_pub: Publisher<Svc, WrenchSample, ()>,
    afs_servo_sub: Subscriber<Svc, ServoSample, ()>,
    bare_pub: Publisher<Svc, [u8; PING], ()>,
    bare_sub: Subscriber<Svc, [u8; PONG], ()>,
    notifier: Notifier<Svc>,
    listener: Listener<Svc>,
}

fn bare_ping(
    node: &Node<Svc>,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, [u8; PING], ()>> {
    node.service_builder(&ipc::name(BARE_PING)?)
        .publish_subscribe::<[u8; PING]>()
        .open_or_create()
        .map_err(|e| anyhow::anyhow!("bare ping service: {e:?}"))
}

fn bare_pong(
    node: &Node<Svc>,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, [u8; PONG], ()>> {
    node.service_builder(&ipc::name(BARE_PONG)?)
        .publish_subscribe::<[u8; PONG]>()
        .open_or_create()
        .map_err(|e| anyhow::anyhow!("bare pong service: {e:?}"))
}

fn event(
    node: &Node<Svc>,
    name: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>> {
    node.service_builder(&ipc::name(name)?)
        .event()
        .open_or_create()
        .map_err(|e| anyhow::anyhow!("event service {name}: {e:?}"))
}

/// The initiator's ports (ping publishers, pong subscribers).
fn initiator_ports(node: &Node<Svc>) -> Result<Ports> {
    Ok(Ports {
        afs_wrench_pub: ipc::wrench(node)?
            .publisher_builder()
            .create()
            .map_err(|x| ice("wrench publisher", x))?,
        afs_servo_sub: ipc::servo(node)?
            .subscriber_builder()
            .create()
            .map_err(|x| ice("servo subscriber", x))?,
        bare_pub: bare_ping(node)?
            .publisher_builder()
            .create()
            .map_err(|x| ice("bare publisher", x))?,
        bare_sub: bare_pong(node)?
            .subscriber_builder()
            .create()
            .map_err(|x| ice("bare subscriber", x))?,
        notifier: event(node, EVENT_PING)?
            .notifier_builder()
            .create()
            .map_err(|x| ice("notifier", x))?,
        listener: event(node, EVENT_PONG)?
            .listener_builder()
            .create()
            .map_err(|x| ice("listener", x))?,
    })
}

/// An iceoryx2 error, with what failed.
fn ice(what: &str, e: impl std::fmt::Debug) -> anyhow::Error {
    anyhow::anyhow!("{what}: {e:?}")
}

/// Spins until `f` gives a value, or fails after [`ANSWER_TIMEOUT`] (the peer died).
fn spin<T>(mut f: impl FnMut() -> Result<Option<T>>) -> Result<T> {
    let t0 = Instant::now();
    let mut n = 0u32;
    loop {
        if let Some(v) = f()? {
            return Ok(v);
        }
        n = n.wrapping_add(1);
        if n.is_multiple_of(1024) && t0.elapsed() > ANSWER_TIMEOUT {
            bail!("the peer did not answer within {ANSWER_TIMEOUT:?}");
        }
        std::hint::spin_loop();
    }
}

fn put(buf: &mut [u8], at: usize, v: u64) {
    buf[at..at + 8].copy_from_slice(&v.to_ne_bytes());
}

fn get(buf: &[u8], at: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&buf[at..at + 8]);
    u64::from_ne_bytes(b)
}

/// One round trip from the initiator; returns (round trip, one way) in ns.
fn ping(
    t: Transport,
    seq: u64,
    ports: &Ports,
    page: &AtomicPage,
    sock: &mut UnixStream,
) -> Result<(u64, u64)> {
    let t0 = rt::monotonic_ns();
    let oneway = match t {
        Transport::Atomic => {
            let mut b = [0u8; PING];
            put(&mut b, 0, seq);
            put(&mut b, 8, t0);
            page.write(PING_DATA, &b);
            page.seq(PING_SEQ).store(seq, Ordering::Release);
            spin(|| Ok((page.seq(PONG_SEQ).load(Ordering::Acquire) == seq).then_some(())))?;
            let mut r = [0u8; PONG];
            page.read(PONG_DATA, &mut r);
            get(&r, 16)
        }
        Transport::AfsPoll | Transport::AfsEvent => {
            let w = WrenchSample {
                version: VERSION,
                seq,
                sample_ns: t0,
                publish_ns: t0,
                epoch_ns: 1,
                ..Default::default()
            };
            ports
                .afs_wrench_pub
                .send_copy(w)
                .map_err(|e| anyhow::anyhow!("sending a wrench sample: {e:?}"))?;
            if t == Transport::AfsEvent {
                ports
                    .notifier
                    .notify()
                    .map_err(|e| anyhow::anyhow!("notify: {e:?}"))?;
            }
            let sub = &ports.afs_servo_sub;
            let s = if t == Transport::AfsEvent {
                wait_event(&ports.listener, || receive_seq(sub, seq))?
            } else {
                spin(|| receive_seq(sub, seq))?
            };
            s.force_age_ns
        }
        Transport::BarePoll => {
            let mut b = [0u8; PING];
            put(&mut b, 0, seq);
            put(&mut b, 8, t0);
            ports
                .bare_pub
                .send_copy(b)
                .map_err(|e| anyhow::anyhow!("bare send: {e:?}"))?;
            let r = spin(|| {
                Ok(ports
                    .bare_sub
                    .receive()
                    .map_err(|e| anyhow::anyhow!("bare receive: {e:?}"))?
                    .map(|s| *s.payload()))
            })?;
            get(&r, 16)
        }
        Transport::Uds => {
            let mut b = [0u8; PING];
            put(&mut b, 0, seq);
            put(&mut b, 8, t0);
            sock.write_all(&b).context("socket write")?;
            let mut r = [0u8; PONG];
            sock.read_exact(&mut r).context("socket read")?;
            get(&r, 16)
        }
    };
    let t1 = rt::monotonic_ns();
    Ok((t1.saturating_sub(t0), oneway))
}

fn receive_seq(sub: &Subscriber<Svc, ServoSample, ()>, seq: u64) -> Result<Option<ServoSample>> {
    while let Some(s) = sub
        .receive()
        .map_err(|e| anyhow::anyhow!("receive: {e:?}"))?
    {
        if s.seq == seq {
            return Ok(Some(*s.payload()));
        }
    }
    Ok(None)
}

/// Blocks on the listener until `f` gives a value (a notification may arrive before or after
/// the sample is visible: check first, then wait).
fn wait_event<T>(l: &Listener<Svc>, mut f: impl FnMut() -> Result<Option<T>>) -> Result<T> {
    let t0 = Instant::now();
    loop {
        if let Some(v) = f()? {
            return Ok(v);
        }
        l.timed_wait(|_| {}, Duration::from_millis(100))
            .map_err(|e| anyhow::anyhow!("listener wait: {e:?}"))?;
        if t0.elapsed() > ANSWER_TIMEOUT {
            bail!("the peer did not answer within {ANSWER_TIMEOUT:?}");
        }
    }
}

fn command(sock: &mut UnixStream, t: u32, count: u32) -> Result<()> {
    let mut b = [0u8; 8];
    b[..4].copy_from_slice(&t.to_ne_bytes());
    b[4..].copy_from_slice(&count.to_ne_bytes());
    sock.write_all(&b)
        .context("writing a command to the peer")?;
    let mut ack = [0u8; 4];
    sock.read_exact(&mut ack)
        .context("the peer did not acknowledge (did it die? see its error above)")?;
    Ok(())
}

/// Pins the calling thread to `cpu` when it exists (a warning otherwise).
fn pin_thread(cpu: usize) {
    let r = rt::setup(0, false, Some(cpu));
    for w in r.warnings {
        eprintln!("afs bench: warning: {w}");
    }
}

fn hop(opts: &BenchOptions, stop: &AtomicBool) -> Result<Value> {
    let prefix = format!("{}h", opts.prefix);
    ipc::claim_prefix(&prefix)?;
    let dir = std::env::temp_dir().join(format!("afs-bench-{prefix}-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let sock_path = dir.join("ctl.sock");
    let listener = UnixListener::bind(&sock_path)
        .with_context(|| format!("binding {}", sock_path.display()))?;
    let duration = opts.duration_s;
    let result = std::thread::scope(|sc| {
        sc.spawn(|| -> Result<Value> {
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
            let per_round = ((0.9 * duration / mean_sum / f64::from(rounds)) as u32).clamp(100, 2_000_000);
            let mut rtt: Vec<Histogram<u64>> = (0..5).map(|_| hist::new()).collect::<Result<_>>()?;
            let mut one: Vec<Histogram<u64>> = (0..5).map(|_| hist::new()).collect::<Result<_>>()?;
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
            let names_rtt = ["atomic_rtt", "afs_poll_rtt", "afs_event_rtt", "bare_iceoryx2_poll_rtt", "unix_socket_rtt"];
            let names_one = ["atomic_oneway", "afs_poll_oneway", "afs_event_oneway", "bare_iceoryx2_poll_oneway", "unix_socket_oneway"];
            let what = [
                "shared-memory atomic ping-pong, busy-polling (the floor)",
                "afs services and types (WrenchSample → ServoSample), busy-polling, sample gate",
                "the afs services with an iceoryx2 event per sample",
                "bare iceoryx2 publish-subscribe, same sizes, default settings, busy-polling",
                "Unix-domain stream socket, blocking reads",
            ];
            let mut series = Vec::new();
            for (i, (h, o)) in rtt.into_iter().zip(one).enumerate() {
                series.push(Series { name: names_rtt[i], what: what[i], floor: Some("atomic_rtt"), hist: h });
                series.push(Series { name: names_one[i], what: what[i], floor: Some("atomic_oneway"), hist: o });
            }
            let (map, files) = finish_part(
                "hop",
                &series,
                &[],
                &opts.out,
                "hop: round trip CPU 0 → CPU 1 → CPU 0 and one way",
            )?;
            let s = |n: &str| Summary::of(&series.iter().find(|x| x.name == n).expect("series").hist);
            let (atomic, afs, bare, uds) = (s("atomic_rtt"), s("afs_poll_rtt"), s("bare_iceoryx2_poll_rtt"), s("unix_socket_rtt"));
            let (atomic1, afs1, bare1, uds1) = (s("atomic_oneway"), s("afs_poll_oneway"), s("bare_iceoryx2_poll_oneway"), s("unix_socket_oneway"));
            let ratios = json!({
                "afs_poll_over_atomic_p50": {"rtt": afs.p50 / atomic.p50, "oneway": afs1.p50 / atomic1.p50},
                "unix_socket_over_afs_poll_p50": {"rtt": uds.p50 / afs.p50, "oneway": uds1.p50 / afs1.p50},
                "afs_overhead_over_bare_iceoryx2_p50": {"rtt": afs.p50 / bare.p50 - 1.0, "oneway": afs1.p50 / bare1.p50 - 1.0},
            });
            let targets = vec![
                target("afs busy-poll p50 / atomic floor p50, one way", afs1.p50 / atomic1.p50, "<=", 10.0),
                target("afs busy-poll p50 / atomic floor p50, round trip", afs.p50 / atomic.p50, "<=", 10.0),
                target("Unix socket p50 / afs busy-poll p50, one way", uds1.p50 / afs1.p50, ">=", 10.0),
                target("Unix socket p50 / afs busy-poll p50, round trip", uds.p50 / afs.p50, ">=", 10.0),
                target("afs overhead over bare iceoryx2 at p50, one way", afs1.p50 / bare1.p50 - 1.0, "<=", 0.10),
                target("afs overhead over bare iceoryx2 at p50, round trip", afs.p50 / bare.p50 - 1.0, "<=", 0.10),
            ];
            Ok(json!({
                "rounds": rounds,
                "samples_per_series": u64::from(rounds) * u64::from(per_round),
                "payload_bytes": {"ping": PING, "pong": PONG},
                "cpus": {"initiator": 0, "peer": 1},
                "series": map,
                "ratios": ratios,
                "targets": targets,
                "files": files,
            }))
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

/// The peer of the hop benchmark (`afs bench-peer`): answers every ping on the transport the
/// initiator names, until told to quit.
pub fn peer(prefix: &str, socket: &Path, cpu: Option<usize>) -> Result<()> {
    if let Some(c) = cpu {
        pin_thread(c);
    }
    let node = ipc::node(prefix, "bench-peer")?;
    let wrench_sub = ipc::wrench(&node)?
        .subscriber_builder()
        .create()
        .map_err(|x| ice("wrench subscriber", x))?;
    let servo_pub = ipc::servo(&node)?
        .publisher_builder()
        .create()
        .map_err(|x| ice("servo publisher", x))?;
    let bare_sub = bare_ping(&node)?
        .subscriber_builder()
        .create()
        .map_err(|x| ice("bare subscriber", x))?;
    let bare_pub = bare_pong(&node)?
        .publisher_builder()
        .create()
        .map_err(|x| ice("bare publisher", x))?;
    let listener = event(&node, EVENT_PING)?
        .listener_builder()
        .create()
        .map_err(|x| ice("listener", x))?;
    let notifier = event(&node, EVENT_PONG)?
        .notifier_builder()
        .create()
        .map_err(|x| ice("notifier", x))?;
    let page = AtomicPage::open(prefix, false)?;
    let mut sock = UnixStream::connect(socket)
        .with_context(|| format!("connecting to {}", socket.display()))?;
    let mut gate = SampleGate::new(GateParams {
        future_tolerance_ns: u64::MAX / 4,
        ..GateParams::default()
    });
    loop {
        let mut cmd = [0u8; 8];
        sock.read_exact(&mut cmd).context("reading a command")?;
        let t = u32::from_ne_bytes(cmd[..4].try_into().expect("4 bytes"));
        let n = u32::from_ne_bytes(cmd[4..].try_into().expect("4 bytes"));
        sock.write_all(&[0; 4])?;
        if t == QUIT {
            return Ok(());
        }
        let Some(&t) = TRANSPORTS.get(t as usize) else {
            bail!("unknown transport {t}");
        };
        for _ in 0..n {
            match t {
                Transport::Atomic => {
                    let last = page.seq(PONG_SEQ).load(Ordering::Relaxed);
                    spin(|| Ok((page.seq(PING_SEQ).load(Ordering::Acquire) > last).then_some(())))?;
                    let now = rt::monotonic_ns();
                    let mut b = [0u8; PING];
                    page.read(PING_DATA, &mut b);
                    let seq = get(&b, 0);
                    let mut r = [0u8; PONG];
                    put(&mut r, 0, seq);
                    put(&mut r, 16, now.saturating_sub(get(&b, 8)));
                    page.write(PONG_DATA, &r);
                    page.seq(PONG_SEQ).store(seq, Ordering::Release);
                }
                Transport::AfsPoll | Transport::AfsEvent => {
                    let recv = || -> Result<Option<WrenchSample>> {
                        Ok(wrench_sub
                            .receive()
                            .map_err(|x| ice("receive", x))?
                            .map(|s| *s.payload()))
                    };
                    let w = if t == Transport::AfsEvent {
                        wait_event(&listener, recv)?
                    } else {
                        spin(recv)?
                    };
                    let now = rt::monotonic_ns();
                    // What the servo does with a sample on receipt.
                    let _ = gate.offer(&w, now);
                    let s = ServoSample {
                        version: VERSION,
                        seq: w.seq,
                        force_age_ns: now.saturating_sub(w.publish_ns),
                        ..Default::default()
                    };
                    servo_pub.send_copy(s).map_err(|x| ice("send", x))?;
                    if t == Transport::AfsEvent {
                        notifier.notify().map_err(|x| ice("notify", x))?;
                    }
                }
                Transport::BarePoll => {
                    let b = spin(|| {
                        Ok(bare_sub
                            .receive()
                            .map_err(|x| ice("receive", x))?
                            .map(|s| *s.payload()))
                    })?;
                    let now = rt::monotonic_ns();
                    let mut r = [0u8; PONG];
                    put(&mut r, 0, get(&b, 0));
                    put(&mut r, 16, now.saturating_sub(get(&b, 8)));
                    bare_pub.send_copy(r).map_err(|x| ice("send", x))?;
                }
                Transport::Uds => {
                    let mut b = [0u8; PING];
                    sock.read_exact(&mut b).context("socket read")?;
                    let now = rt::monotonic_ns();
                    let mut r = [0u8; PONG];
                    put(&mut r, 0, get(&b, 0));
                    put(&mut r, 16, now.saturating_sub(get(&b, 8)));
                    sock.write_all(&r).context("socket write")?;
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// loop and stack

/// A stack run for the benchmark: `afs run` with the servo saving its histograms.
struct StackRun {
    report: Value,
    wake: Histogram<u64>,
    age: Histogram<u64>,
}

/// Runs a stack (`afs run` refuses a prefix in use) while `during` runs beside it; `during`
/// is told through its flag when the stack has ended.
fn run_stack<T: Send>(
    prefix: &str,
    duration_s: f64,
    dir: &Path,
    stop: &AtomicBool,
    during: impl FnOnce(&AtomicBool) -> T + Send,
) -> Result<(StackRun, T)> {
    let mut stack = StackFile::parse(DEFAULT_STACK, "(built-in)")?;
    stack.prefix = prefix.into();
    stack.scenario = "surface-tracking".into();
    stack.duration_s = duration_s;
    let hist_dir = dir.join(format!("{prefix}-servo"));
    let _ = std::fs::remove_dir_all(&hist_dir);
    for p in stack.process.iter_mut().filter(|p| p.name == "servo") {
        p.args
            .extend(["--histograms".to_string(), hist_dir.display().to_string()]);
    }
    let file = dir.join(format!("{prefix}.toml"));
    std::fs::write(
        &file,
        toml::to_string(&stack).context("writing the stack file")?,
    )?;
    let child = Command::new(std::env::current_exe().context("locating afs")?)
        .args(["run", "--json", "--quiet", "--config"])
        .arg(&file)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("starting afs run")?;
    let running = AtomicBool::new(true);
    let (out, beside) = std::thread::scope(|sc| {
        let h = sc.spawn(|| during(&running));
        let pid = child.id();
        // Forward a Ctrl-C to the stack.
        let running = &running;
        let watcher = sc.spawn(move || {
            while running.load(Ordering::Relaxed) {
                if stop.load(Ordering::Relaxed) {
                    // SAFETY: signalling our own child.
                    unsafe {
                        libc::kill(pid as i32, libc::SIGINT);
                    }
                    return;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        });
        let out = child.wait_with_output();
        running.store(false, Ordering::Relaxed);
        let _ = watcher.join();
        let beside = h.join();
        (out, beside)
    });
    let out = out.context("waiting for afs run")?;
    let beside = beside.map_err(|_| anyhow::anyhow!("the thread beside the stack panicked"))?;
    let report: Value = serde_json::from_slice(&out.stdout).with_context(|| {
        format!(
            "afs run gave no report; its stderr:\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    })?;
    let wake = hist::load(&hist_dir.join("wake.hdr"))
        .context("the servo saved no histograms (did it run?)")?;
    let age = hist::load(&hist_dir.join("force_age.hdr"))?;
    let _ = std::fs::remove_dir_all(&hist_dir);
    let _ = std::fs::remove_file(&file);
    Ok((StackRun { report, wake, age }, beside))
}

/// The bare absolute-time loop at the servo's priority and core, half a period out of phase
/// with the servo's ticks (read from its samples), while `running`.
fn bare_loop(
    prefix: &str,
    cpu: usize,
    priority: u8,
    duration_s: f64,
    running: &AtomicBool,
) -> Result<Histogram<u64>> {
    let mut h = hist::new()?;
    // Join the stack once its servo is up (a node of ours before that would make `afs run`
    // refuse the prefix as taken), then find the servo's tick phase from its samples.
    let t0 = Instant::now();
    loop {
        if !running.load(Ordering::Relaxed) {
            return Ok(h);
        }
        if ipc::census(prefix, false).is_ok_and(|c| c.alive.iter().any(|(n, _)| n == "servo")) {
            break;
        }
        if t0.elapsed() > Duration::from_secs(30) {
            bail!("the servo did not start within 30 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let node = ipc::node(prefix, "bench-loop")?;
    let sub = ipc::servo(&node)?
        .subscriber_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("servo subscriber: {e:?}"))?;
    let period = 100_000u64;
    let t0 = Instant::now();
    let (phase, seq0, tick0) = loop {
        if !running.load(Ordering::Relaxed) {
            return Ok(h);
        }
        if let Some(s) = sub.receive().map_err(|e| anyhow::anyhow!("{e:?}"))?
            && s.seq > 100
        {
            break (s.tick_ns % period, s.seq, s.tick_ns);
        }
        if t0.elapsed() > Duration::from_secs(30) {
            bail!("the servo did not start within 30 s");
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    drop(sub);
    drop(node);
    let r = rt::setup(priority, true, Some(cpu));
    for w in &r.warnings {
        eprintln!("afs bench: warning: {w}");
    }
    let now = rt::monotonic_ns();
    // Until 5 ms before the servo's last tick (its ticks are 100 µs of simulated and wall
    // time): the servo's exit (unmapping its locked memory on this core) is not part of the
    // comparison.
    let end = (tick0 + ((duration_s * 1e9) as u64).saturating_sub(seq0 * period))
        .saturating_sub(5_000_000);
    let mut deadline = now - now % period + phase + period / 2 + period;
    while running.load(Ordering::Relaxed) && deadline < end {
        rt::sleep_until(deadline);
        let late = rt::monotonic_ns().saturating_sub(deadline);
        hist::record(&mut h, late);
        deadline += period;
        let now = rt::monotonic_ns();
        if now > deadline + 100 * period {
            deadline = now - now % period + phase + period / 2 + period;
        }
    }
    Ok(h)
}

/// The built-in stack's servo CPU and priority.
fn servo_spec() -> Result<(usize, u8)> {
    let s = StackFile::parse(DEFAULT_STACK, "(built-in)")?;
    let p = s
        .process
        .iter()
        .find(|p| p.name == "servo")
        .context("the built-in stack has no servo")?;
    Ok((
        p.cpu
            .unwrap_or(1)
            .min(rt::available_cpus().saturating_sub(1)),
        p.priority,
    ))
}

fn jitter(opts: &BenchOptions, stop: &AtomicBool) -> Result<Value> {
    let prefix = format!("{}l", opts.prefix);
    let dir = scratch(&prefix)?;
    let (cpu, prio) = servo_spec()?;
    let (run, bare) = run_stack(&prefix, opts.duration_s, &dir, stop, |running| {
        bare_loop(&prefix, cpu, prio, opts.duration_s, running)
    })?;
    let _ = std::fs::remove_dir_all(&dir);
    let bare = bare.context("the bare loop")?;
    let series = vec![
        Series {
            name: "bare_loop_wake",
            what: "bare clock_nanosleep loop, SCHED_FIFO, servo's core and priority (the floor)",
            floor: None,
            hist: bare,
        },
        Series {
            name: "servo_wake",
            what: "afs servo's wake latency (running surface-tracking with every board)",
            floor: Some("bare_loop_wake"),
            hist: run.wake,
        },
    ];
    let (map, files) = finish_part(
        "loop",
        &series,
        &[],
        &opts.out,
        "loop: wake latency, servo vs bare loop (same core, priority and time)",
    )?;
    let servo = Summary::of(&series[1].hist);
    let floor = Summary::of(&series[0].hist);
    Ok(json!({
        "cpu": cpu,
        "priority": prio,
        "period_us": 100.0,
        "series": map,
        "servo_misses": run.report["loop"]["misses"],
        "targets": [target("servo wake p99 / bare loop p99", servo.p99 / floor.p99, "<=", 1.2)],
        "files": files,
    }))
}

fn scratch(prefix: &str) -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("afs-bench-{prefix}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok(dir)
}

/// A busy loop on `cpu` at normal priority while `running`.
fn hog(cpu: usize, running: &AtomicBool) {
    pin_thread(cpu);
    let mut x = 0u64;
    while running.load(Ordering::Relaxed) {
        for _ in 0..10_000 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
    }
}

/// Sums of the stack runs of one kind (without or with the hog).
struct StackSums {
    wake: Histogram<u64>,
    age: Histogram<u64>,
    runs: u64,
    misses: u64,
    ticks: u64,
    safe_entries: u64,
    stale_ticks: u64,
    passed: bool,
}

fn stack(opts: &BenchOptions, stop: &AtomicBool) -> Result<Value> {
    let (cpu, _) = servo_spec()?;
    let other = if cpu == 0 { 1 } else { 0 };
    let can_hog = rt::available_cpus() > 1;
    // Alternating halves (A B A B) so that a noisy stretch of the machine falls on both kinds.
    let mut sums: Vec<StackSums> = (0..2)
        .map(|_| {
            Ok(StackSums {
                wake: hist::new()?,
                age: hist::new()?,
                runs: 0,
                misses: 0,
                ticks: 0,
                safe_entries: 0,
                stale_ticks: 0,
                passed: true,
            })
        })
        .collect::<Result<_>>()?;
    for (i, with_hog) in [false, true, false, true].into_iter().enumerate() {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let prefix = format!("{}s{i}", opts.prefix);
        let dir = scratch(&prefix)?;
        let (r, ()) = run_stack(&prefix, opts.duration_s / 2.0, &dir, stop, |running| {
            if with_hog && can_hog {
                hog(other, running);
            }
        })?;
        let _ = std::fs::remove_dir_all(&dir);
        let k = &mut sums[usize::from(with_hog)];
        k.wake.add(&r.wake).context("adding histograms")?;
        k.age.add(&r.age).context("adding histograms")?;
        let n = |key: &str| r.report["loop"][key].as_u64().unwrap_or(0);
        k.runs += 1;
        k.misses += n("misses");
        k.ticks += n("ticks");
        k.safe_entries += n("safe_entries");
        k.stale_ticks += n("stale_ticks");
        k.passed &= r.report["passed"] == true;
    }
    let sensor_period_us = 1e6 / afs_shared::sim::SimConfig::default().sensor.rate_hz;
    let mut series = Vec::new();
    let mut loops = serde_json::Map::new();
    for (hogged, k) in sums.into_iter().enumerate() {
        let hogged = hogged == 1;
        let (wake, age, key) = if hogged {
            ("servo_wake_hog", "force_age_hog", "with_hog")
        } else {
            ("servo_wake", "force_age", "without_hog")
        };
        loops.insert(
            key.into(),
            json!({
                "stack_runs": k.runs,
                "hog_running": hogged && can_hog,
                "misses": k.misses,
                "ticks": k.ticks,
                "safe_entries": k.safe_entries,
                "stale_ticks": k.stale_ticks,
                "passed": k.passed,
            }),
        );
        series.push(Series {
            name: wake,
            what: if hogged {
                "servo wake latency, CPU hog on the other core"
            } else {
                "servo wake latency"
            },
            floor: if hogged { Some("servo_wake") } else { None },
            hist: k.wake,
        });
        series.push(Series {
            name: age,
            what: if hogged {
                "force data age at use, CPU hog on the other core"
            } else {
                "force data age at use (sensor sample to servo tick)"
            },
            floor: Some("sensor period"),
            hist: k.age,
        });
    }
    let consts = [ConstFloor {
        name: "sensor period",
        value_us: sensor_period_us,
    }];
    let (map, files) = finish_part(
        "stack",
        &series,
        &consts,
        &opts.out,
        "stack: servo wake latency and force age at use, without and with a CPU hog",
    )?;
    let mut targets = Vec::new();
    if let Some(s) = series.iter().find(|s| s.name == "force_age") {
        targets.push(target(
            "force age p99 without hog (µs) ≤ sensor period + 20 µs",
            Summary::of(&s.hist).p99,
            "<=",
            sensor_period_us + 20.0,
        ));
    }
    Ok(json!({
        "scenario": "surface-tracking",
        "hog_cpu": other,
        "sensor_period_us": sensor_period_us,
        "series": map,
        "runs": loops,
        "targets": targets,
        "files": files,
    }))
}
