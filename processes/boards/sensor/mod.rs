//! The force-sensor board: one [`WrenchSample`](afs_shared::msg::WrenchSample) per sample on
//! `afs/sensor/wrench`, and its statistics on `afs/sensor/stats` at 10 Hz. The samples come
//! from one of two sources:
//! - [`model`]: the sensor model applied to the simulated world, on the board's own clock;
//! - [`rdt`]: a force/torque sensor (or its emulator, `afs-netft`) speaking ATI's RDT over UDP.

pub mod model;
pub mod rdt;

use crate::boards::Startup;
use crate::hist::QuantilesUs;
use crate::ipc::{self, Svc};
use crate::rt;
use afs_shared::msg::{SensorSource, SensorStats, WrenchSample};
use afs_shared::sensor::SensorParams;
use anyhow::{Context, Result};
use iceoryx2::node::Node;
use iceoryx2::port::publisher::Publisher;
use serde::{Deserialize, Serialize};
use std::fmt;
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
                version: SensorStats::VERSION,
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

/// What an RDT device sent (`SensorStats`' `rdt_*` fields, times in µs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RdtReport {
    /// Datagrams received.
    pub datagrams: u64,
    /// Datagrams that were not whole records.
    pub bad_datagrams: u64,
    /// Records received.
    pub records: u64,
    /// Records missing from the stream.
    pub lost: u64,
    /// Records received twice.
    pub repeated: u64,
    /// Records older than one received before.
    pub reordered: u64,
    /// Records later than the late limit.
    pub late: u64,
    /// Records with a non-zero status word.
    pub status_errors: u64,
    /// The last non-zero status word.
    pub last_status: u32,
    /// Records arriving when last reported.
    pub streaming: bool,
    /// Streaming requests sent.
    pub requests: u64,
    /// Time between datagrams (µs).
    pub interval_us: QuantilesUs,
    /// Excess delay of the records over the least-delayed one (µs).
    pub excess_delay_us: QuantilesUs,
}

/// The sensor board's statistics (`SensorStats`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorReport {
    /// Where its samples came from.
    pub source: SensorSource,
    /// Samples published.
    pub published: u64,
    /// Model: periods that woke a whole period late.
    pub late_periods: u64,
    /// RDT: what the device sent (None for the model).
    pub rdt: Option<RdtReport>,
}

impl From<&SensorStats> for SensorReport {
    fn from(s: &SensorStats) -> Self {
        let source = SensorSource::try_from(s.source).unwrap_or(SensorSource::Model);
        Self {
            source,
            published: s.published,
            late_periods: s.late_periods,
            rdt: (source == SensorSource::Rdt).then(|| RdtReport {
                datagrams: s.rdt_datagrams,
                bad_datagrams: s.rdt_bad_datagrams,
                records: s.rdt_records,
                lost: s.rdt_lost,
                repeated: s.rdt_repeated,
                reordered: s.rdt_reordered,
                late: s.rdt_late,
                status_errors: s.rdt_status_errors,
                last_status: s.rdt_last_status,
                streaming: s.rdt_streaming != 0,
                requests: s.rdt_requests,
                interval_us: (&s.rdt_interval).into(),
                excess_delay_us: (&s.rdt_excess_delay).into(),
            }),
        }
    }
}

impl fmt::Display for RdtReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} records in {} datagrams ({} not RDT); lost {}, repeated {}, reordered {}, late {}, bad status {}; {} requests; interval p50/p99/max {:.1}/{:.1}/{:.1} µs; excess delay p99/max {:.1}/{:.1} µs",
            self.records,
            self.datagrams,
            self.bad_datagrams,
            self.lost,
            self.repeated,
            self.reordered,
            self.late,
            self.status_errors,
            self.requests,
            self.interval_us.p50,
            self.interval_us.p99,
            self.interval_us.max,
            self.excess_delay_us.p99,
            self.excess_delay_us.max,
        )
    }
}
