//! The sensor board's model source: its own clock (default 7 kHz, like an ATI Net F/T), the
//! latest world sample in, the sensor model ([`SensorModel`]: noise, bias, drift, low-pass, quantization,
//! saturation) applied, one [`WrenchSample`] out per period.
//!
//! At start-up it takes its zero-load reading in free air (as the lockstep does) and sends it
//! with every sample as the tare; when the first world sample arrives it lets its filter settle
//! on it for 10 ms before publishing, as the lockstep does.

use super::{SensorArgs, SensorSummary, StatsOut};
use crate::boards::Startup;
use crate::ipc;
use crate::rt;
use afs_shared::msg::{Board, PlantSample, SensorSource, WrenchFlags, WrenchSample};
use afs_shared::sensor::SensorModel;
use anyhow::{Context, Result};
use std::sync::atomic::{AtomicBool, Ordering};

/// Runs the model source until `stop` is set.
pub fn run(args: &SensorArgs, stop: &AtomicBool) -> Result<SensorSummary> {
    args.params.validate().map_err(anyhow::Error::msg)?;
    let mut startup = Startup::new(Board::Sensor, args.main_ns);
    let node = ipc::node(&args.prefix, Board::Sensor.name())?;
    startup.report.node_ns = Startup::now();
    let plant_sub = ipc::plant(&node)?
        .subscriber_builder()
        .buffer_size(64)
        .create()
        .context("plant subscriber")?;
    let publisher = super::wrench_publisher(&node)?;
    let mut stats = StatsOut::open(&node, SensorSource::Model)?;
    startup.open(&node)?;
    startup.report.ports_ns = Startup::now();
    let mut model = SensorModel::new(args.params, args.seed);
    let tare = afs_shared::sim::tare(&mut model);
    startup.report.prepared_ns = Startup::now();
    super::go_realtime(&mut startup, args);
    let period_ns = (1e9 / args.params.rate_hz).round() as u64;
    let warm = (0.01 * args.params.rate_hz).ceil() as usize;
    let epoch_ns = rt::monotonic_ns();
    let mut latest: Option<PlantSample> = None;
    let mut warmed = false;
    let mut summary = SensorSummary::default();
    let mut seq = 0u64;
    let mut deadline = rt::monotonic_ns() + period_ns;
    let mut connections = rt::Every::new(rt::CONNECTIONS_EVERY_NS, deadline);
    while !stop.load(Ordering::Relaxed) {
        rt::sleep_until(deadline);
        let now = rt::monotonic_ns();
        if now >= deadline + period_ns {
            summary.late += 1;
        }
        if stats.due(now) {
            stats.stats.published = summary.published;
            stats.stats.late_periods = summary.late;
            stats.publish(now);
        }
        while let Ok(Some(s)) = plant_sub.receive() {
            let p = *s.payload();
            if p.version == PlantSample::VERSION && latest.is_none_or(|l| p.seq >= l.seq) {
                latest = Some(p);
            }
        }
        if let Some(p) = latest {
            if !warmed {
                startup.report.input_ns = now;
                for _ in 0..warm {
                    model.sample(p.sensor_wrench());
                }
                warmed = true;
            }
            let r = model.sample(p.sensor_wrench());
            let mut w = WrenchSample {
                version: WrenchSample::VERSION,
                flags: if r.saturated {
                    WrenchFlags::SATURATED
                } else {
                    WrenchFlags::empty()
                },
                seq,
                epoch_ns,
                plant_seq: p.seq,
                plant_tick_ns: p.tick_ns,
                sample_ns: now,
                publish_ns: 0,
                force_n: [r.wrench.force.x, r.wrench.force.y],
                torque_nm: r.wrench.torque,
                tare_force_n: [tare.force.x, tare.force.y],
                tare_torque_nm: tare.torque,
            };
            w.publish_ns = rt::monotonic_ns();
            if publisher.send_copy(w).is_ok() {
                summary.published += 1;
                if summary.published == 1 {
                    startup.report.data_ns = w.publish_ns;
                    startup.send();
                }
            }
            seq += 1;
        }
        if connections.due(now) {
            // The start-up report's publisher sends once, so it drops the connections of
            // subscribers that died only when asked.
            startup.update_connections();
        }
        deadline = rt::next_deadline(deadline, period_ns, rt::monotonic_ns());
    }
    Ok(summary)
}
