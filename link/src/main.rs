//! `afs-link`: the link board. It carries a stack's services to and from another host through
//! iceoryx2's own tunnel over zenoh (the crates behind upstream's `iox2 link tunnel zenoh`),
//! admitting only the services that are meant to cross, and packs the servo's per-tick stream
//! into batches for the way (docs/link.md).
//!
//! ```text
//! # the controller's host (A), started by `afs run` from the stack file:
//! afs-link --prefix P --side controller --listen tcp/10.0.0.1:7447
//! # the remote host (B), with the estimator and observers:
//! afs-link --prefix P --side remote --listen tcp/10.0.0.2:7447 --connect tcp/10.0.0.1:7447
//! ```
//!
//! On the controller's side it reads `afs/servo/state` and publishes `afs/link/servo`
//! batches; on the remote side it unpacks them onto the remote host's own `afs/servo/state`,
//! checking every batch and sample number, so that observers there read the stream as they
//! would on host A and every loss is counted and placed. Nothing on host A waits on it: its
//! ports discard on overflow, and the tunnel runs in this process, at normal priority.

use afs::boards::{Common, stop_flag};
use afs::ipc;
use afs_shared::batch::{Packer, SeqGaps, Unpacker};
use afs_shared::msg;
use anyhow::{Context, Result, bail};
use clap::Parser;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use iceoryx2_integrations_zenoh_link_carrier::ZenohCarrier;
use iceoryx2_link::Link;
use iceoryx2_link_backend::AllowList;
use iceoryx2_link_tunnel::Tunnel;
use serde::Serialize;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// The services that cross by default: the servo's stream as batches, the low-rate status
/// streams, and the estimator's services in their topic form (docs/link.md, *What crosses*).
pub const CROSSING: [&str; 9] = [
    msg::service::LINK_SERVO,
    msg::service::SUPERVISOR,
    msg::service::LOOP_STATS,
    msg::service::SENSOR_STATS,
    msg::service::FRICTION,
    msg::service::TANGENT_REQUEST,
    msg::service::TANGENT_RESPONSE,
    msg::service::ROTATION_REQUEST,
    msg::service::ROTATION_RESPONSE,
];

/// Which end of the link this board is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
enum Side {
    /// The controller's host: packs the servo's stream.
    Controller,
    /// Another host: unpacks it onto its own `afs/servo/state`.
    Remote,
}

/// The link board.
#[derive(Parser)]
#[command(name = "afs-link", version)]
struct Cli {
    #[command(flatten)]
    common: Common,
    /// Which end of the link this is.
    #[arg(long, value_enum)]
    side: Side,
    /// zenoh endpoint to listen on (e.g. tcp/10.0.0.1:7447); repeatable.
    #[arg(long)]
    listen: Vec<String>,
    /// zenoh endpoint of the other host's link board to connect to; repeatable.
    #[arg(long)]
    connect: Vec<String>,
    /// A zenoh config file (JSON5) used instead of the one --listen and --connect make.
    #[arg(long)]
    zenoh_config: Option<PathBuf>,
    /// Services to carry instead of the default set (wildcards `*` and `?`); repeatable.
    #[arg(long)]
    allow: Vec<String>,
    /// Longest wait between two rounds when nothing arrives from the other host (ms).
    #[arg(long, default_value_t = 1)]
    poll_ms: u64,
    /// How often the board looks for services that appeared or left on either host, once its
    /// first seconds are over (ms; every 100 ms before that). Each look reads every local
    /// service's description (docs/link.md, *Discovery*).
    #[arg(long, default_value_t = 500)]
    discover_ms: u64,
    /// Write the board's summary (JSON) here when it stops.
    #[arg(long)]
    summary: Option<PathBuf>,
}

/// What the board did, written at the end.
#[derive(Debug, Default, Serialize)]
struct Summary {
    side: Option<Side>,
    /// Servo samples read on this host (controller side).
    servo_read: u64,
    /// Their numbers (a gap: the packer fell behind the servo).
    servo_seen: SeqGaps,
    /// Batches published on `afs/link/servo` (controller side).
    batches_sent: u64,
    /// What arrived from the other host (remote side).
    unpacked: Unpacker,
    /// Servo samples republished on this host (remote side).
    servo_published: u64,
    /// From the servo's publication on host A to the republication here (µs; remote side):
    /// the batching wait, the tunnel both ways of zenoh, and this board's wake-up. Only
    /// meaningful when both hosts share a clock (two hosts on one machine).
    sample_latency_us: Option<afs::hist::QuantilesUs>,
    /// From a batch's publication on host A to its arrival here (µs; remote side).
    batch_latency_us: Option<afs::hist::QuantilesUs>,
    /// Rounds of discovery and propagation.
    rounds: u64,
    /// Failed discoveries and propagations (each leaves the link usable).
    discovery_errors: u64,
    propagation_errors: u64,
    /// Time spent in discovery, propagation and waiting (s).
    discovery_s: f64,
    propagation_s: f64,
    waiting_s: f64,
    /// Whether any service was bridged at the end.
    bridged: bool,
}

/// The keys the tunnel's frames cross on (iceoryx2's zenoh carrier, version 0.10).
const TUNNEL_KEYS: &str = "iox2/v1/channel/**";

fn zenoh_config(cli: &Cli) -> Result<zenoh::Config> {
    if let Some(p) = &cli.zenoh_config {
        return zenoh::Config::from_file(p)
            .map_err(|e| anyhow::anyhow!("reading zenoh config {}: {e}", p.display()));
    }
    if cli.listen.is_empty() && cli.connect.is_empty() {
        bail!(
            "give --listen and/or --connect endpoints (e.g. --listen tcp/127.0.0.1:7447), or --zenoh-config"
        );
    }
    // This build's zenoh has its TCP transport only (docs/link.md, *Build cost*).
    for (flag, e) in cli
        .listen
        .iter()
        .map(|e| ("--listen", e))
        .chain(cli.connect.iter().map(|e| ("--connect", e)))
    {
        if !e.starts_with("tcp/") {
            bail!(
                "{flag} {e}: afs's link speaks zenoh over TCP only; give a tcp/HOST:PORT endpoint (docs/link.md, *Build cost*)"
            );
        }
    }
    let list = |v: &[String]| {
        v.iter()
            .map(|e| serde_json::to_string(e).unwrap_or_default())
            .collect::<Vec<_>>()
            .join(", ")
    };
    // Peers on the given endpoints only: no multicast or gossip scouting, so nothing is sent
    // anywhere but to the addresses named. The tunnel's frames block when zenoh's send queue
    // is full instead of being dropped after 1 ms (zenoh's default for a put): on a loaded
    // machine a batch went missing that way (docs/link.md); the board waiting a moment is
    // what the servo stream's 1.3-s buffer is for.
    let text = format!(
        r#"{{ mode: "peer",
             listen: {{ endpoints: [{}] }},
             connect: {{ endpoints: [{}] }},
             scouting: {{ multicast: {{ enabled: false }}, gossip: {{ enabled: false }} }},
             qos: {{ publication: [{{ key_exprs: ["{TUNNEL_KEYS}"],
                                      config: {{ congestion_control: "block" }} }}] }} }}"#,
        list(&cli.listen),
        list(&cli.connect)
    );
    zenoh::Config::from_json5(&text).map_err(|e| anyhow::anyhow!("zenoh config {text}: {e}"))
}

fn run(cli: &Cli) -> Result<Summary> {
    let prefix = &cli.common.prefix;
    ipc::check_prefix(prefix)?;
    if cli.poll_ms == 0 || cli.poll_ms > 1000 {
        bail!("--poll-ms {} must be 1 to 1000", cli.poll_ms);
    }
    if !(FIRST_DISCOVERY_MS..=10_000).contains(&cli.discover_ms) {
        bail!(
            "--discover-ms {} must be {FIRST_DISCOVERY_MS} to 10000",
            cli.discover_ms
        );
    }
    let r = afs::rt::setup(cli.common.priority, false, cli.common.cpu);
    for w in &r.warnings {
        eprintln!("afs-link: warning: {w}");
    }
    if cli.common.priority == 0
        && let Some(n) = afs::rt::make_way_for_realtime()
    {
        eprintln!("afs-link: note: {n}");
    }
    let stop = stop_flag()?;
    let zenoh = zenoh_config(cli)?;
    let allow: Vec<String> = if cli.allow.is_empty() {
        CROSSING.iter().map(|s| s.to_string()).collect()
    } else {
        cli.allow.clone()
    };
    // The board's own ports on one node, the tunnel on another: the tunnel passes over what
    // its own node published, and the batches must cross.
    let node = ipc::node(prefix, "link")?;
    let cfg = ipc::config(prefix)?;
    let tunnel_node = NodeBuilder::new()
        .name(&"link-tunnel".try_into().context("node name")?)
        .config(&cfg)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Svc>()
        .context("creating the tunnel's node")?;
    let carrier = ZenohCarrier::create(zenoh).map_err(|e| {
        anyhow::anyhow!("starting zenoh (are the endpoints free and yours?): {e:?}")
    })?;
    let list = AllowList::new(&allow);
    let mut link = Link::new(tunnel_node, Tunnel::new(carrier, &cfg))
        .with_filter(move |n: &ServiceName| list.admits(n.as_str()));
    let listener = link
        .listener()
        .map_err(|e| anyhow::anyhow!("creating the tunnel's wake-up listener: {e:?}"))?;
    // Wakes when something arrives from the other host, and every `poll` for what this host
    // published (a WaitSet: the listener's own timed wait rounds up to the kernel's tick).
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<iceoryx2_link_backend::WakeService>()
        .map_err(|e| anyhow::anyhow!("creating the link's wait set: {e:?}"))?;
    let _arrivals = waitset
        .attach_notification(&listener)
        .map_err(|e| anyhow::anyhow!("attaching the tunnel's listener: {e:?}"))?;
    let _tick = waitset
        .attach_interval(Duration::from_millis(cli.poll_ms))
        .map_err(|e| anyhow::anyhow!("attaching the link's poll interval: {e:?}"))?;

    let mut sum = Summary {
        side: Some(cli.side),
        ..Default::default()
    };
    let mut ends = Ends::open(&node, cli.side)?;
    let started = Instant::now();
    let mut last_discovery = started - Duration::from_secs(1);
    let mut last_warning = Instant::now() - Duration::from_secs(10);
    let mut warn = |what: &str, e: &dyn std::fmt::Debug| {
        if last_warning.elapsed() > Duration::from_secs(5) {
            eprintln!("afs-link: warning: {what} failed: {e:?} (the link carries on)");
            last_warning = Instant::now();
        }
    };
    while !stop.load(Ordering::Relaxed) {
        let t = Instant::now();
        match waitset.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest) => break,
            // Interrupted by a signal: the loop's condition decides.
            Ok(WaitSetRunResult::Interrupt) | Err(_) => continue,
            Ok(_) => {}
        }
        let _ = listener.try_wait(|_| {});
        sum.waiting_s += t.elapsed().as_secs_f64();
        ends.pack(&mut sum);
        let period = if started.elapsed() < FIRST_SECONDS {
            FIRST_DISCOVERY_MS
        } else {
            cli.discover_ms
        };
        if last_discovery.elapsed() >= Duration::from_millis(period) {
            last_discovery = Instant::now();
            if let Err(e) = link.discover() {
                sum.discovery_errors += 1;
                warn("discovery", &e);
            }
            sum.discovery_s += last_discovery.elapsed().as_secs_f64();
            ends.update_connections();
        }
        let t = Instant::now();
        if let Err(e) = link.propagate() {
            sum.propagation_errors += 1;
            warn("propagation", &e);
        }
        sum.propagation_s += t.elapsed().as_secs_f64();
        sum.rounds += 1;
        ends.unpack(&mut sum);
    }
    // Stopping: take the servo's samples still waiting in the subscriber (the stack stops the
    // link board right after the servo's last tick, possibly before a round has read it), send
    // what is packed, and give the tunnel a moment to carry it.
    ends.pack(&mut sum);
    if ends.flush(&mut sum) {
        for _ in 0..STOP_PROPAGATE_ROUNDS {
            let _ = link.propagate();
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    sum.servo_seen = ends.packer.seen().clone();
    if !ends.sample_latency.is_empty() {
        sum.sample_latency_us = Some(afs::hist::QuantilesUs::of(&ends.sample_latency));
        sum.batch_latency_us = Some(afs::hist::QuantilesUs::of(&ends.batch_latency));
    }
    sum.bridged = !link.bridges().empty();
    Ok(sum)
}

/// Discovery every 100 ms in the board's first seconds, while the stack's services appear.
const FIRST_DISCOVERY_MS: u64 = 100;
const FIRST_SECONDS: Duration = Duration::from_secs(5);

/// Rounds of the tunnel (2 ms apart) a stopping board runs to carry its last batch: 0.3 s,
/// four times the worst batch latency seen on a loaded CI machine (76 ms).
const STOP_PROPAGATE_ROUNDS: usize = 150;

type Pub<T> = iceoryx2::port::publisher::Publisher<ipc::Svc, T, ()>;
type Sub<T> = iceoryx2::port::subscriber::Subscriber<ipc::Svc, T, ()>;

/// The board's own ends of the servo stream: on the controller's side the servo's samples in
/// and the batches out, on the remote side the batches in and the samples out.
struct Ends {
    servo_sub: Option<Sub<msg::ServoSample>>,
    batch_pub: Option<Pub<msg::ServoBatch>>,
    batch_sub: Option<Sub<msg::ServoBatch>>,
    servo_pub: Option<Pub<msg::ServoSample>>,
    packer: Packer,
    sample_latency: afs::hist::Histogram<u64>,
    batch_latency: afs::hist::Histogram<u64>,
}

impl Ends {
    fn open(node: &Node<ipc::Svc>, side: Side) -> Result<Self> {
        let controller = side == Side::Controller;
        Ok(Self {
            servo_sub: controller
                .then(|| {
                    ipc::servo(node)?
                        .subscriber_builder()
                        .buffer_size(ipc::TICK_BUFFER)
                        .create()
                        .context("servo subscriber")
                })
                .transpose()?,
            batch_pub: controller
                .then(|| {
                    ipc::link_servo(node)?
                        .publisher_builder()
                        .backpressure_strategy(ipc::BACKPRESSURE)
                        .create()
                        .context("batch publisher")
                })
                .transpose()?,
            batch_sub: (!controller)
                .then(|| {
                    ipc::link_servo(node)?
                        .subscriber_builder()
                        .create()
                        .context("batch subscriber")
                })
                .transpose()?,
            servo_pub: (!controller)
                .then(|| {
                    ipc::servo(node)?
                        .publisher_builder()
                        .backpressure_strategy(ipc::BACKPRESSURE)
                        .create()
                        .context("servo publisher")
                })
                .transpose()?,
            packer: Packer::new(afs::rt::monotonic_ns()),
            sample_latency: afs::hist::new()?,
            batch_latency: afs::hist::new()?,
        })
    }

    /// Controller's side: the servo's new samples into batches; a paused (or ended) stream
    /// sends what is packed.
    fn pack(&mut self, sum: &mut Summary) {
        let (Some(sub), Some(publ)) = (&self.servo_sub, &self.batch_pub) else {
            return;
        };
        let mut got = false;
        while let Ok(Some(s)) = sub.receive() {
            got = true;
            sum.servo_read += 1;
            self.packer
                .push(s.payload(), |b| send_batch(publ, b, &mut sum.batches_sent));
        }
        if !got {
            self.packer
                .flush(|b| send_batch(publ, b, &mut sum.batches_sent));
        }
    }

    /// Controller's side: sends what is packed; false on the remote side.
    fn flush(&mut self, sum: &mut Summary) -> bool {
        let Some(publ) = &self.batch_pub else {
            return false;
        };
        self.packer
            .flush(|b| send_batch(publ, b, &mut sum.batches_sent));
        true
    }

    /// Remote side: every batch from the other host unpacked onto this host's stream, each
    /// number checked.
    fn unpack(&mut self, sum: &mut Summary) {
        let (Some(sub), Some(publ)) = (&self.batch_sub, &self.servo_pub) else {
            return;
        };
        while let Ok(Some(b)) = sub.receive() {
            let now = afs::rt::monotonic_ns();
            afs::hist::record(
                &mut self.batch_latency,
                now.saturating_sub(b.payload().publish_ns),
            );
            let latency = &mut self.sample_latency;
            let published = &mut sum.servo_published;
            sum.unpacked.push(b.payload(), |s| {
                if publ.send_copy(*s).is_ok() {
                    *published += 1;
                    afs::hist::record(latency, now.saturating_sub(s.publish_ns));
                }
            });
        }
    }

    /// The publishers send rarely or in bursts: drop their dead subscribers' connections.
    fn update_connections(&self) {
        if let Some(p) = &self.batch_pub {
            let _ = p.update_connections();
        }
        if let Some(p) = &self.servo_pub {
            let _ = p.update_connections();
        }
    }
}

/// Stamps a packed batch with its publication time and sends it, counting it in `sent`.
fn send_batch(
    publ: &iceoryx2::port::publisher::Publisher<ipc::Svc, msg::ServoBatch, ()>,
    b: &msg::ServoBatch,
    sent: &mut u64,
) {
    let mut b = *b;
    b.publish_ns = afs::rt::monotonic_ns();
    if publ.send_copy(b).is_ok() {
        *sent += 1;
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // The tunnel's own account of its bridges, for a user tracing the link: IOX2_LOG_LEVEL=trace.
    set_log_level_from_env_or(LogLevel::Info);
    let result = run(&cli);
    // The last node of the prefix on this host leaves it clean (on a remote host there is no
    // supervisor to do it): iceoryx2 keeps the node counter, removed by name.
    if ipc::census(&cli.common.prefix, false).is_ok_and(|c| c.alive.is_empty()) {
        let _ = ipc::release_prefix(&cli.common.prefix);
    }
    match result {
        Ok(sum) => {
            let text = serde_json::to_string(&sum).unwrap_or_default();
            eprintln!("afs-link: {text}");
            if let Some(p) = &cli.summary
                && let Err(e) = std::fs::write(p, &text)
            {
                eprintln!("afs-link: error: writing {}: {e}", p.display());
                return ExitCode::from(2);
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("afs-link: error: {e:#}");
            ExitCode::from(2)
        }
    }
}
