//! The force-sensor board: one [`WrenchSample`](afs_shared::msg::WrenchSample) per sample on
//! `afs/sensor/wrench`, and its statistics on `afs/sensor/stats` at 10 Hz. The samples come
//! from one of two sources:
//! - [`model`]: the sensor model applied to the simulated world, on the board's own clock;
//! - [`rdt`]: a force/torque sensor (or its emulator, `afs-netft`) speaking ATI's RDT over UDP.

pub mod model;
pub mod rdt;

use crate::boards::Startup;
use crate::ipc::{self, Svc};
use crate::rt;
use afs_shared::msg::{self, SensorSource, SensorStats, WrenchSample};
use afs_shared::sensor::SensorParams;
use anyhow::{Context, Result};
use iceoryx2::node::Node;
use iceoryx2::port::publisher::Publisher;
use std::sync::atomic::AtomicBool;

/// The wrench publisher every source (and `afs sensor`) publishes on: a slow subscriber loses
/// its oldest samples, it never blocks the board.
pub fn wrench_publisher(node: &Node<Svc>) -> Result<Publisher<Svc, WrenchSample, ()>> {
    ipc::wrench(node)?
        .publisher_builder()
        .backpressure_strategy(ipc::BACKPRESSURE)
        .create()
        .context("wrench publisher")
}

/// The board's real-time set-up (SCHED_FIFO, mlockall, pinning), stamped in its start-up
/// report; what could not be had is printed as a warning.
pub fn go_realtime(startup: &mut Startup, args: &SensorArgs) {
    let rtr = rt::setup(args.priority, true, args.cpu);
    startup.report.rt_ns = Startup::now();
    for w in &rtr.warnings {
        eprintln!("afs-sensor: warning: {w}");
    }
}

/// Publishes the board's statistics every 0.1 s.
pub struct StatsOut {
    publisher: Publisher<Svc, SensorStats, ()>,
    next_ns: u64,
    /// The statistics so far (the board updates the counters).
    pub stats: SensorStats,
}

impl StatsOut {
    /// Opens the statistics publisher on `node`.
    pub fn open(node: &Node<Svc>, source: SensorSource) -> Result<Self> {
        Ok(Self {
            publisher: ipc::sensor_stats(node)?
                .publisher_builder()
                .backpressure_strategy(ipc::BACKPRESSURE)
                .create()
                .context("sensor statistics publisher")?,
            next_ns: 0,
            stats: SensorStats {
                version: msg::VERSION,
                source: source.into(),
                ..Default::default()
            },
        })
    }

    /// Whether the next publication is due at `now_ns`.
    pub fn due(&self, now_ns: u64) -> bool {
        now_ns >= self.next_ns
    }

    /// Publishes the statistics now (a failed send is only a lost status).
    pub fn publish(&mut self, now_ns: u64) {
        self.stats.publish_ns = now_ns;
        let _ = self.publisher.send_copy(self.stats);
        self.stats.seq += 1;
        self.next_ns = now_ns + 100_000_000;
    }

    /// Publishes if due.
    pub fn tick(&mut self) {
        let now = rt::monotonic_ns();
        if self.due(now) {
            self.publish(now);
        }
    }
}

/// Where the samples come from.
#[derive(Debug, Clone)]
pub enum Source {
    /// The sensor model on the simulated world.
    Model,
    /// An RDT device.
    Rdt(rdt::RdtSettings),
}

/// How the sensor runs.
#[derive(Debug, Clone)]
pub struct SensorArgs {
    /// Stack prefix.
    pub prefix: String,
    /// The sensor model.
    pub params: SensorParams,
    /// Noise seed.
    pub seed: u64,
    /// CPU to pin to.
    pub cpu: Option<usize>,
    /// SCHED_FIFO priority (0: normal).
    pub priority: u8,
    /// Where the samples come from.
    pub source: Source,
    /// Monotonic time `main` was entered (ns), for the start-up report.
    pub main_ns: u64,
}

/// What the board did.
#[derive(Debug, Clone, Copy, Default)]
pub struct SensorSummary {
    /// Samples published.
    pub published: u64,
    /// Periods that woke a whole period late.
    pub late: u64,
}

/// Runs the board until `stop` is set.
pub fn run(args: &SensorArgs, stop: &AtomicBool) -> Result<SensorSummary> {
    match &args.source {
        Source::Model => model::run(args, stop),
        Source::Rdt(settings) => rdt::run_board(args, settings, stop),
    }
}
