//! `afs-netft`, an emulator of an RDT force/torque sensor (an ATI Net F/T) on the simulated
//! world: on its own clock it samples the latest world sample through the sensor model (the
//! same model and seed as the sensor board's model source, so the same readings), turns the
//! planar wrench into the sensor's six axes (its mounting) and counts (its calibration), and
//! serves it as the device does ([`Device`]: one client, `rdt_sequence` from 1 per request,
//! `ft_sequence` free-running, bias, stop, sample counts, buffered datagrams), with the faults
//! of [`Impairments`] on the way out.
//!
//! Before the world's first sample (or with no stack on its prefix) it samples free air, with a
//! noise stream of its own, so it also serves on its own and the world's samples still meet the
//! model source's noise.
//!
//! It starts as a device its operator biased in free air before the run: its zero is the
//! sensor model's free-air reading, as the model source's tare (`--no-power-up-bias`: raw).

use crate::{ipc, rt};
use afs_shared::msg::{self, PlantSample};
use afs_shared::rdt::{
    Answer, Calibration, Device, Impairments, MAX_RECORDS_PER_PACKET, Mounting, Outgoing,
    RECORD_LEN, Shaper,
};
use afs_shared::sensor::{SensorModel, SensorParams, Wrench};
use anyhow::{Context, Result};
use std::io::ErrorKind;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};

/// How the emulator runs.
#[derive(Debug, Clone)]
pub struct NetftArgs {
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
    /// Address and port to serve on.
    pub bind: SocketAddr,
    /// Counts per N and N·m.
    pub calibration: Calibration,
    /// Which of its planes is afs's plane.
    pub mounting: Mounting,
    /// Records per datagram of a buffered stream.
    pub records_per_packet: usize,
    /// Faults on the stream.
    pub impairments: Impairments,
    /// Seed of the faults.
    pub fault_seed: u64,
    /// Start biased at the free-air reading.
    pub power_up_bias: bool,
    /// Take no sample before the world's first (in a stack: the scenario starts in contact,
    /// and the servo's first force must be of it, as with the model source).
    pub wait_for_world: bool,
}

/// What the emulator did.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct NetftSummary {
    /// Internal samples taken.
    pub samples: u64,
    /// Datagrams sent.
    pub datagrams: u64,
    /// Records the device streamed to its client (before the loss, duplication and reordering
    /// of the impairments, and not while silent).
    pub records: u64,
    /// Of those, records with a non-zero status word (`--status-error-at-s`).
    pub error_records: u64,
    /// Requests received (valid or not).
    pub requests: u64,
    /// Requests ignored: from another client while streaming, or not RDT.
    pub ignored: u64,
}

/// Serves until `stop` is set; then releases the prefix if nothing else uses it (when it ran
/// on its own).
pub fn run(args: &NetftArgs, stop: &AtomicBool) -> Result<NetftSummary> {
    let r = serve(args, stop);
    let _ = ipc::release_prefix(&args.prefix);
    r
}

fn serve(args: &NetftArgs, stop: &AtomicBool) -> Result<NetftSummary> {
    args.params.validate()?;
    args.calibration.validate()?;
    args.impairments.validate()?;
    let node = ipc::node(&args.prefix, "netft")?;
    let plant_sub = ipc::plant(&node)?
        .subscriber_builder()
        .buffer_size(64)
        .create()
        .context("plant subscriber")?;
    let socket = UdpSocket::bind(args.bind).with_context(|| {
        format!(
            "serving RDT on {}: is another emulator or program using that port? (choose one with --port)",
            args.bind
        )
    })?;
    socket
        .set_nonblocking(true)
        .context("making the socket non-blocking")?;
    let mut model = SensorModel::new(args.params, args.seed);
    let tare = afs_shared::sim::tare(&mut model);
    let mut idle = SensorModel::new(args.params, args.seed ^ 0x1d1e_a1f0_f1ee_a1f0);
    let (ft0, rdt0) = args.impairments.first_sequences();
    let mut device: Device<SocketAddr> = Device::new(ft0, rdt0, args.records_per_packet);
    if args.power_up_bias {
        let (bias, _) = args.calibration.to_counts(&args.mounting.six(tare));
        device.set_bias(bias);
    }
    let mut shaper = Shaper::new(args.impairments, args.fault_seed);
    let rtr = rt::setup(args.priority, true, args.cpu);
    for w in &rtr.warnings {
        eprintln!("afs-netft: warning: {w}");
    }
    let period_ns = (1e9 / args.params.rate_hz).round() as u64;
    let warm = (0.01 * args.params.rate_hz).ceil() as usize;
    let mut summary = NetftSummary::default();
    let mut latest: Option<PlantSample> = None;
    let mut first_ns: Option<u64> = None;
    let mut warmed = false;
    let mut req = [0u8; 64];
    let mut out = [0u8; RECORD_LEN * MAX_RECORDS_PER_PACKET];
    let mut held = [0u8; RECORD_LEN * MAX_RECORDS_PER_PACKET];
    let mut held_len = 0;
    let mut deadline = rt::monotonic_ns() + period_ns;
    while !stop.load(Ordering::Relaxed) {
        rt::sleep_until(deadline);
        let now = rt::monotonic_ns();
        loop {
            match socket.recv_from(&mut req) {
                Ok((n, from)) => {
                    summary.requests += 1;
                    if matches!(
                        device.request(from, &req[..n]),
                        Answer::Busy | Answer::Invalid(_)
                    ) {
                        summary.ignored += 1;
                    }
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                // A client's port that went away (ICMP): nothing to do.
                Err(_) => break,
            }
        }
        while let Ok(Some(s)) = plant_sub.receive() {
            let p = *s.payload();
            if p.version == msg::PlantSample::VERSION && latest.is_none_or(|l| p.seq >= l.seq) {
                latest = Some(p);
            }
        }
        if args.wait_for_world && latest.is_none() {
            deadline += period_ns;
            continue;
        }
        // Before the world's first sample (or without a stack) the sensor is in free air.
        let truth = match latest {
            Some(p) => {
                if !warmed {
                    for _ in 0..warm {
                        model.sample(p.sensor_wrench());
                    }
                    warmed = true;
                }
                p.sensor_wrench()
            }
            None => Wrench::default(),
        };
        // Free air before the world comes from a noise stream of its own: the world's samples
        // then meet the same noise, drift and filter as the model source's and the lockstep's.
        let model = if warmed { &mut model } else { &mut idle };
        let t0 = *first_ns.get_or_insert(now);
        let t_s = (now - t0) as f64 * 1e-9;
        let r = model.sample(truth);
        let (counts, _) = args.calibration.to_counts(&args.mounting.six(r.wrench));
        summary.samples += 1;
        if let Some((to, recs)) = device.sample(counts, shaper.status(t_s))
            && !shaper.silent(t_s)
        {
            summary.records += recs.len() as u64;
            summary.error_records += recs.iter().filter(|r| r.status != 0).count() as u64;
            let len = recs.len() * RECORD_LEN;
            for (i, rec) in recs.iter().enumerate() {
                out[i * RECORD_LEN..(i + 1) * RECORD_LEN].copy_from_slice(&rec.encode());
            }
            let (sends, hold) = shaper.datagram();
            for s in sends.order.into_iter().flatten() {
                let bytes = match s {
                    Outgoing::Held => &held[..held_len],
                    Outgoing::This => &out[..len],
                };
                if socket.send_to(bytes, to).is_ok() {
                    summary.datagrams += 1;
                }
            }
            if hold {
                held[..len].copy_from_slice(&out[..len]);
                held_len = len;
            }
        }
        deadline += period_ns;
        let now2 = rt::monotonic_ns();
        if now2 > deadline + 100 * period_ns {
            // More than 100 samples behind (the host stalled): skip them, and let the sample
            // counter move on as a device's would, so that ft_sequence keeps time.
            let behind = (now2 - deadline) / period_ns;
            device.skip(behind as u32);
            deadline += behind * period_ns + period_ns;
        }
    }
    Ok(summary)
}
