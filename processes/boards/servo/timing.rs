//! The servo loop's timing: latency histograms allocated before the loop, their percentiles
//! and counters published as [`LoopStats`], saved as `.hdr` files for the benchmarks.

use super::link::EstimatorLink;
use crate::ipc::Svc;
use crate::{hist, rt};
use afs_shared::msg::LoopStats;
use afs_shared::servo::ServoCore;
use afs_shared::watchdog::SampleGate;
use anyhow::{Context, Result};
use hdrhistogram::Histogram;
use hist::quantiles;
use std::path::Path;

/// Latency histograms, allocated before the loop; recording never allocates.
pub(super) struct Timing {
    /// Wake latency (ns).
    pub(super) wake: Histogram<u64>,
    /// Execution time of a tick (ns).
    pub(super) exec: Histogram<u64>,
    /// Age of the force data at use (ns).
    pub(super) age: Histogram<u64>,
}

impl Timing {
    pub(super) fn new() -> Result<Self> {
        Ok(Self {
            wake: hist::new()?,
            exec: hist::new()?,
            age: hist::new()?,
        })
    }

    /// Saves the histograms (V2 format) as `wake.hdr`, `exec.hdr` and `force_age.hdr` in `dir`.
    pub(super) fn save(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        hist::save(&self.wake, &dir.join("wake.hdr"))?;
        hist::save(&self.exec, &dir.join("exec.hdr"))?;
        hist::save(&self.age, &dir.join("force_age.hdr"))
    }
}

/// Publishes the loop's statistics (percentiles, gate counters, estimator requests).
pub(super) fn publish_stats(
    stats: &mut LoopStats,
    timing: &Timing,
    gate: &SampleGate,
    link: &EstimatorLink,
    servo: &ServoCore,
    publisher: &iceoryx2::port::publisher::Publisher<Svc, LoopStats, ()>,
) {
    stats.seq += 1;
    stats.wake_latency = quantiles(&timing.wake);
    stats.exec = quantiles(&timing.exec);
    stats.force_age = quantiles(&timing.age);
    stats.gate = gate.counters();
    stats.safe_entries = servo.counters().safe_entries as u64;
    stats.requests = link.requests;
    stats.retries = link.retries;
    stats.answers = link.answers;
    stats.publish_ns = rt::monotonic_ns();
    if publisher.send_copy(*stats).is_err() {
        stats.publish_failures += 1;
    }
}
