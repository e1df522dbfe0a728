//! The live view: a Foxglove WebSocket server (the `foxglove` crate) publishing a running
//! stack's topics, the same topics and JSON schemas as the MCAP recording, at a rate a person
//! can watch.
//!
//! It lives on the observer's side only: the supervisor (`afs run --foxglove`) or `afs view`
//! (attached to a running stack) hands it the samples it already reads. The hand-over is a
//! bounded channel that drops when full, the server keeps a bounded backlog per client and
//! drops the oldest message when a client falls behind; nothing here can block a board, and
//! the boards do not know the view exists. High-rate streams (world, controller, force and the
//! derived `/live` record) are decimated to `rate_hz` before the hand-over (the world and
//! controller at the same ticks, so the two stay paired); the low-rate streams pass whole.
//! Nothing is encoded while no client subscribes to a topic.

use super::follow::{Ended, Follower};
use super::topics::{Rec, TOPICS, json_schema};
use crate::rt;
use anyhow::{Context, Result, bail};
use foxglove::{ChannelBuilder, Context as FoxContext, PartialMetadata, RawChannel, Schema};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::Duration;

/// Foxglove's usual port.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";

/// Samples the hand-over holds before dropping (a second of the decimated streams at the
/// highest rate allowed).
const QUEUE: usize = 65_536;

/// Messages a client's backlog holds before the server drops its oldest.
const CLIENT_BACKLOG: usize = 4_096;

/// How long clients get to answer the close when the view ends.
const CLOSE_GRACE: Duration = Duration::from_secs(2);

/// The highest rate the view publishes a stream at (Hz).
pub const MAX_RATE_HZ: f64 = 10_000.0;

/// Where and how fast the view publishes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSettings {
    /// Address to listen on (port 0: any free port).
    pub addr: SocketAddr,
    /// Rate of each high-rate stream (Hz).
    pub rate_hz: f64,
}

impl ViewSettings {
    /// Checks the settings; `addr` is `HOST:PORT`.
    pub fn parse(addr: &str, rate_hz: f64) -> Result<Self> {
        let addr: SocketAddr = addr.parse().with_context(|| {
            format!(
                "--foxglove '{addr}' is not an address; give it as HOST:PORT, e.g. {DEFAULT_ADDR}"
            )
        })?;
        if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= MAX_RATE_HZ) {
            bail!("--foxglove-hz must be in (0, {MAX_RATE_HZ}] Hz, got {rate_hz}");
        }
        Ok(Self { addr, rate_hz })
    }
}

/// What the view did.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ViewSummary {
    /// The address clients connect to (`ws://HOST:PORT`).
    pub url: String,
    /// Rate of each high-rate stream (Hz).
    pub rate_hz: f64,
    /// Messages handed to the server per topic (to every subscribed client).
    pub published: BTreeMap<String, u64>,
    /// Decimated samples no client was subscribed to (not encoded).
    pub unwatched: u64,
    /// Samples dropped because the view's thread fell behind.
    pub dropped: u64,
    /// Samples kept by the decimation and offered to the view: every one is published,
    /// unwatched or dropped.
    #[serde(default)]
    pub offered: u64,
    /// Most clients connected at once (as seen every 1024 samples).
    pub max_clients: u64,
}

impl std::fmt::Display for ViewSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "live view {}: {} messages published, {} dropped, at most {} clients",
            self.url,
            self.published.values().sum::<u64>(),
            self.dropped,
            self.max_clients
        )
    }
}

/// Keeps every `stride`-th tick, and force samples `every_ns` apart.
#[doc(hidden)]
#[derive(Debug, Clone, Copy)]
pub struct Decimator {
    rate_hz: f64,
    /// Ticks between kept world/controller samples (None: not known yet).
    stride: Option<u64>,
    /// A first world sample, to learn the tick period from when it is not given.
    first: Option<(u64, f64)>,
    every_ns: u64,
    last_bucket: Option<u64>,
}

impl Decimator {
    /// Keeps `rate_hz` of each stream (the ticks' rate, when known, `tick_hz`).
    pub fn new(rate_hz: f64, tick_hz: Option<f64>) -> Self {
        Self {
            rate_hz,
            stride: tick_hz.map(|t| Self::stride_of(t, rate_hz)),
            first: None,
            every_ns: (1e9 / rate_hz) as u64,
            last_bucket: None,
        }
    }

    fn stride_of(tick_hz: f64, rate_hz: f64) -> u64 {
        (tick_hz / rate_hz).round().max(1.0) as u64
    }

    fn tick(&mut self, seq: u64, time_s: f64) -> bool {
        if self.stride.is_none() {
            match self.first {
                Some((s0, t0)) if seq > s0 && time_s > t0 => {
                    let tick_hz = (seq - s0) as f64 / (time_s - t0);
                    self.stride = Some(Self::stride_of(tick_hz, self.rate_hz));
                }
                _ => self.first = Some((seq, time_s)),
            }
        }
        self.stride.is_some_and(|k| seq.is_multiple_of(k))
    }

    #[doc(hidden)]
    pub fn keep(&mut self, r: &Rec) -> bool {
        match r {
            Rec::Plant(p) => self.tick(p.seq, p.time_s),
            // The world sample of the tick came first and taught the stride.
            Rec::Servo(s) => self.stride.is_some_and(|k| s.seq.is_multiple_of(k)),
            Rec::Live(l) => self.stride.is_some_and(|k| l.seq.is_multiple_of(k)),
            Rec::Insertion(l) => self.stride.is_some_and(|k| l.seq.is_multiple_of(k)),
            // The first sample of each period of the rate.
            Rec::Wrench(w) => {
                let bucket = w.sample_ns / self.every_ns.max(1);
                let keep = self.last_bucket != Some(bucket);
                self.last_bucket = Some(bucket);
                keep
            }
            _ => true,
        }
    }
}

/// A live view being served.
pub struct LiveView {
    tx: SyncSender<Rec>,
    dropped: u64,
    offered: u64,
    decimator: Decimator,
    url: String,
    handle: JoinHandle<ViewSummary>,
}

impl LiveView {
    /// Starts the server on `settings.addr`; `tick_hz` is the servo's tick rate (None: learnt
    /// from the world stream). `name` is what clients show. The view's thread and the server's
    /// runtime (created from it, so inheriting its CPUs) keep off the CPUs `avoid` (the
    /// real-time boards'): their network system calls then never run on a board's core.
    pub fn start(
        settings: ViewSettings,
        tick_hz: Option<f64>,
        name: &str,
        avoid: &[usize],
    ) -> Result<Self> {
        let (tx, rx) = sync_channel(QUEUE);
        let (started_tx, started_rx) = sync_channel(1);
        let (name, avoid) = (name.to_string(), avoid.to_vec());
        let handle = std::thread::Builder::new()
            .name("afs-view".into())
            .spawn(move || {
                if let Some(w) = rt::avoid_cpus(&avoid) {
                    eprintln!("afs: warning: {w}");
                }
                match open_server(settings, &name) {
                    Ok((server, channels, ctx, url)) => {
                        let _ = started_tx.send(Ok(url.clone()));
                        let summary = ViewSummary {
                            url,
                            rate_hz: settings.rate_hz,
                            ..Default::default()
                        };
                        serve(rx, server, channels, ctx, summary)
                    }
                    Err(e) => {
                        let _ = started_tx.send(Err(e));
                        ViewSummary::default()
                    }
                }
            })
            .context("starting the live view's thread")?;
        let url = started_rx
            .recv()
            .map_err(|_| anyhow::anyhow!("the live view's thread ended before it started"))??;
        Ok(Self {
            tx,
            dropped: 0,
            offered: 0,
            decimator: Decimator::new(settings.rate_hz, tick_hz),
            url,
            handle,
        })
    }

    /// The address clients connect to.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// Offers a sample; never blocks.
    pub fn push(&mut self, r: Rec) {
        if !self.decimator.keep(&r) {
            return;
        }
        self.offered += 1;
        match self.tx.try_send(r) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => self.dropped += 1,
        }
    }

    /// Closes the server (clients see the connection end).
    pub fn finish(self) -> ViewSummary {
        drop(self.tx);
        let mut s = self.handle.join().unwrap_or_default();
        s.dropped += self.dropped;
        s.offered = self.offered;
        s
    }
}

/// The server and its channels (one per topic, with the recording's schema).
type Opened = (
    foxglove::WebSocketServerHandle,
    Vec<Arc<RawChannel>>,
    Arc<FoxContext>,
    String,
);

fn open_server(settings: ViewSettings, name: &str) -> Result<Opened> {
    let ctx = FoxContext::new();
    let mut channels = Vec::new();
    for (topic, ty) in TOPICS {
        let ch = ChannelBuilder::new(topic)
            .context(&ctx)
            .message_encoding("json")
            .schema(Schema::new(ty, "jsonschema", json_schema(ty).into_bytes()))
            .build_raw()
            .with_context(|| format!("creating the live view's channel {topic}"))?;
        channels.push(ch);
    }
    let server = foxglove::WebSocketServer::new()
        .name(name)
        .context(&ctx)
        .bind(settings.addr.ip().to_string(), settings.addr.port())
        .message_backlog_size(CLIENT_BACKLOG)
        .start_blocking()
        .map_err(|e| {
            anyhow::anyhow!(
                "the live view cannot listen on {}: {e}; give another --foxglove HOST:PORT (port 0 picks a free one)",
                settings.addr
            )
        })?;
    let url = format!("ws://{}:{}", settings.addr.ip(), server.port());
    Ok((server, channels, ctx, url))
}

fn serve(
    rx: Receiver<Rec>,
    server: foxglove::WebSocketServerHandle,
    channels: Vec<Arc<RawChannel>>,
    ctx: Arc<FoxContext>,
    mut summary: ViewSummary,
) -> ViewSummary {
    let mut counts = [0u64; TOPICS.len()];
    let mut seen = 0u64;
    for r in rx {
        seen += 1;
        if seen % 1024 == 1 {
            summary.max_clients = summary.max_clients.max(server.client_count() as u64);
        }
        let c = r.channel();
        if !channels[c].has_sinks() {
            summary.unwatched += 1;
            continue;
        }
        let Ok(data) = r.json() else {
            summary.dropped += 1;
            continue;
        };
        channels[c].log_with_meta(
            &data,
            PartialMetadata {
                log_time: Some(r.publish_ns()),
            },
        );
        counts[c] += 1;
    }
    summary.max_clients = summary.max_clients.max(server.client_count() as u64);
    for (i, (topic, _)) in TOPICS.iter().enumerate() {
        summary.published.insert((*topic).into(), counts[i]);
    }
    // Clients get a close frame; one that does not read may never answer it, so the
    // graceful close gets a bounded wait and is then left to the process's exit.
    let closing = server.stop();
    let (done_tx, done_rx) = std::sync::mpsc::channel();
    let _ = std::thread::Builder::new()
        .name("afs-view-close".into())
        .spawn(move || {
            closing.wait_blocking();
            let _ = done_tx.send(());
        });
    let _ = done_rx.recv_timeout(CLOSE_GRACE);
    drop(ctx);
    summary
}

/// `afs view`: serves a live view of the running stack `prefix` until it ends or `stop` is
/// set. Reads its streams as one more subscriber (history 1 on the status streams, so the
/// latest statistics show at once).
pub fn attach(prefix: &str, settings: ViewSettings, stop: &AtomicBool) -> Result<ViewSummary> {
    let mut follower = Follower::open(prefix, "view")?;
    // Keep off the cores the stack's boards are pinned to.
    let avoid = follower.pinned_cpus()?;
    let mut view = LiveView::start(settings, None, &format!("afs {prefix}"), &avoid)?;
    eprintln!("afs: live view of stack '{prefix}' at {}", view.url());
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(5));
        match follower.poll(|r| view.push(r))? {
            Some(Ended::Stopping) => {
                eprintln!("afs: stack '{prefix}' is stopping");
                break;
            }
            Some(Ended::Gone) => {
                eprintln!("afs: stack '{prefix}' ended");
                break;
            }
            None => {}
        }
    }
    follower.close();
    Ok(view.finish())
}
