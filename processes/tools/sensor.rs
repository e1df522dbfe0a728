//! `afs sensor`: connect to an RDT force/torque sensor (or `afs-netft`), publish its samples on
//! the wrench topic of a prefix for any client, and report rate, loss, reordering and receive
//! jitter. The same receiver as the sensor board's RDT source (`boards::sensor::rdt`).

use crate::boards::sensor::rdt::{Poll, RdtSettings, Receiver, copy_counters};
use crate::boards::sensor::{RdtReport, SensorReport};
use crate::observe::record::{RecordSummary, Recorder};
use crate::observe::topics::Rec;
use crate::{ipc, rt};
use afs_shared::msg::SensorStats;
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

/// What `afs sensor` was asked.
#[derive(Debug, Clone)]
pub struct SensorOptions {
    /// The device and how to read it.
    pub rdt: RdtSettings,
    /// Prefix whose wrench topic gets the samples.
    pub prefix: String,
    /// Seconds to stream (0: until Ctrl-C).
    pub duration_s: f64,
    /// Record the samples to this MCAP file.
    pub record: Option<PathBuf>,
    /// Seconds to wait for the device's first record.
    pub answer_within_s: f64,
}

/// What `afs sensor` measured.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SensorToolReport {
    /// The device.
    pub address: String,
    /// The prefix published on.
    pub prefix: String,
    /// Seconds from the first record to the end.
    pub duration_s: f64,
    /// Fresh records per second (published samples / duration).
    pub rate_hz: f64,
    /// Samples published.
    pub published: u64,
    /// Lost records as a fraction of the records expected (received fresh + lost).
    pub loss_fraction: f64,
    /// What the device sent.
    pub rdt: RdtReport,
    /// The recording, if asked for.
    pub record: Option<RecordSummary>,
    /// Stopped by Ctrl-C.
    pub interrupted: bool,
}

impl fmt::Display for SensorToolReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "sensor at {} on prefix '{}': {} samples in {:.1} s ({:.0} Hz), {:.3} % lost",
            self.address,
            self.prefix,
            self.published,
            self.duration_s,
            self.rate_hz,
            100.0 * self.loss_fraction
        )?;
        writeln!(f, "  {}", self.rdt)?;
        if let Some(r) = &self.record {
            writeln!(
                f,
                "  recorded {} samples to {} ({} dropped)",
                r.messages.values().sum::<u64>(),
                r.path.display(),
                r.dropped
            )?;
        }
        Ok(())
    }
}

/// Streams until the duration is over or `stop` is set; then releases the prefix if nothing
/// else uses it (iceoryx2 keeps the domain's node counter, `ipc::release_prefix`).
pub fn run(opts: &SensorOptions, stop: &AtomicBool) -> Result<SensorToolReport> {
    let r = stream(opts, stop);
    let _ = ipc::release_prefix(&opts.prefix);
    r
}

fn stream(opts: &SensorOptions, stop: &AtomicBool) -> Result<SensorToolReport> {
    if !(opts.duration_s.is_finite() && opts.duration_s >= 0.0) {
        bail!(
            "--duration {} must be a number of seconds >= 0 (0: until Ctrl-C)",
            opts.duration_s
        );
    }
    let node = ipc::node(&opts.prefix, "sensor-cli")?;
    let publisher = crate::boards::sensor::wrench_publisher(&node)
        .context("is a stack with this prefix running its own sensor?")?;
    let mut recorder = opts.record.as_deref().map(Recorder::start).transpose()?;
    let mut rx = Receiver::connect(&opts.rdt)?;
    let addr = opts.rdt.address;
    rx.request_stream();
    let t0 = rt::monotonic_ns();
    let mut first_ns = None;
    let mut refused = false;
    let mut published = 0u64;
    let mut last_ns = t0;
    while !stop.load(Ordering::Relaxed) {
        let got = rx.poll(|mut w| {
            w.publish_ns = rt::monotonic_ns();
            if publisher.send_copy(w).is_ok() {
                published += 1;
            }
            if let Some(r) = recorder.as_mut() {
                r.push(Rec::Wrench(w));
            }
        });
        let now = rt::monotonic_ns();
        refused |= got == Poll::Refused;
        if published > 0 && first_ns.is_none() {
            first_ns = Some(now);
        }
        if first_ns.is_none() && (now - t0) as f64 * 1e-9 >= opts.answer_within_s {
            rx.stop_stream();
            return Err(no_answer(&rx, addr, refused, opts.answer_within_s));
        }
        last_ns = now;
        if let Some(f) = first_ns
            && opts.duration_s > 0.0
            && (now - f) as f64 * 1e-9 >= opts.duration_s
        {
            break;
        }
    }
    rx.stop_stream();
    let mut stats = SensorStats::default();
    copy_counters(&rx, &mut stats, published);
    let rdt = SensorReport::from(&stats).rdt.unwrap_or_default();
    let duration_s = first_ns.map_or(0.0, |f| (last_ns - f) as f64 * 1e-9);
    let fresh = rdt.records - rdt.repeated - rdt.reordered;
    Ok(SensorToolReport {
        address: addr.to_string(),
        prefix: opts.prefix.clone(),
        duration_s,
        rate_hz: if duration_s > 0.0 {
            published as f64 / duration_s
        } else {
            0.0
        },
        published,
        loss_fraction: if fresh + rdt.lost > 0 {
            rdt.lost as f64 / (fresh + rdt.lost) as f64
        } else {
            0.0
        },
        rdt,
        record: recorder.map(|r| r.finish()).transpose()?,
        interrupted: stop.load(Ordering::Relaxed),
    })
}

/// Why no record came, as precisely as the socket tells.
fn no_answer(
    rx: &Receiver,
    addr: std::net::SocketAddr,
    refused: bool,
    within_s: f64,
) -> anyhow::Error {
    let s = &rx.stats;
    if s.rdt_bad_datagrams > 0 && s.rdt_records == 0 {
        anyhow::anyhow!(
            "{addr} answers with {}-byte datagrams, which are not RDT records (36 bytes each, or a multiple): is this the sensor's RDT port (49152)?",
            rx.last_bad_size
        )
    } else if s.rdt_records > 0 {
        anyhow::anyhow!(
            "{addr} sent {} records but none usable within {within_s} s (status errors {}, last status word {:#010x}; late {}): check the device's status page",
            s.rdt_records,
            s.rdt_status_errors,
            s.rdt_last_status,
            s.rdt_late
        )
    } else if refused {
        anyhow::anyhow!(
            "nothing listens for RDT at {addr} (connection refused): check the address and port, and that the device's RDT interface is on"
        )
    } else {
        anyhow::anyhow!(
            "no answer from {addr} within {within_s} s: the device is off or unreachable, or it is streaming to another client (an RDT device serves one client at a time: stop that client, or power-cycle the device)"
        )
    }
}
