//! `afs-netft`: an emulator of an RDT force/torque sensor (ATI Net F/T) on the simulated world,
//! for the sensor board's RDT source and `afs sensor` to be tested without hardware.
//!
//! ```text
//! afs-netft --prefix afs --port 49152 --loss 0.01 --reorder 0.001
//! ```

use afs::boards::netft::{NetftArgs, run};
use afs::boards::{Common, stop_flag};
use afs_shared::rdt::{Calibration, Impairments, Mounting, Plane};
use anyhow::Context;
use clap::Parser;
use std::net::SocketAddr;
use std::process::ExitCode;

/// An emulated RDT force/torque sensor.
#[derive(Parser)]
#[command(name = "afs-netft", version)]
struct Cli {
    #[command(flatten)]
    common: Common,
    /// Address to serve on.
    #[arg(long, default_value = "127.0.0.1")]
    bind: std::net::IpAddr,
    /// UDP port to serve on.
    #[arg(long, default_value_t = afs_shared::rdt::PORT)]
    port: u16,
    /// Internal sample rate (Hz), overriding the set-up's sensor rate.
    #[arg(long)]
    rate_hz: Option<f64>,
    /// Counts per newton.
    #[arg(long, default_value_t = afs_shared::rdt::DEFAULT_COUNTS_PER_FORCE)]
    counts_per_force: f64,
    /// Counts per newton-metre.
    #[arg(long, default_value_t = afs_shared::rdt::DEFAULT_COUNTS_PER_TORQUE)]
    counts_per_torque: f64,
    /// The sensor plane that is afs's plane of motion: xy, yz or zx.
    #[arg(long, default_value = "xy", value_parser = ["xy", "yz", "zx"])]
    plane: String,
    /// Angle from the plane's first axis to afs's x (degrees).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    angle_deg: f64,
    /// Records per datagram of a buffered stream (1 to 40).
    #[arg(long, default_value_t = 10)]
    records_per_packet: usize,
    /// Start raw, not biased at the free-air reading.
    #[arg(long)]
    no_power_up_bias: bool,
    /// Sample nothing before the simulated world's first sample (in a stack); without it, the
    /// device samples free air until then.
    #[arg(long)]
    wait_for_world: bool,
    /// Fraction of datagrams lost.
    #[arg(long, default_value_t = 0.0)]
    loss: f64,
    /// Fraction of datagrams sent twice.
    #[arg(long, default_value_t = 0.0)]
    duplicate: f64,
    /// Fraction of datagrams held back and sent after the next.
    #[arg(long, default_value_t = 0.0)]
    reorder: f64,
    /// Seconds after the first sample at which records carry an error status (0: never).
    #[arg(long, default_value_t = 0.0)]
    status_error_at_s: f64,
    /// How long the error status lasts (s).
    #[arg(long, default_value_t = 0.5)]
    status_error_s: f64,
    /// Seconds after the first sample at which the device goes silent for good (0: never).
    #[arg(long, default_value_t = 0.0)]
    silent_at_s: f64,
    /// Start the sequence numbers this many records before they wrap at 2^32 (0: as a device).
    #[arg(long, default_value_t = 0)]
    wrap_in: u32,
    /// Seed of the faults.
    #[arg(long, default_value_t = 1)]
    fault_seed: u64,
    /// Write what the device did (samples, datagrams, records, records with an error status)
    /// to this file as JSON when it stops.
    #[arg(long)]
    summary: Option<std::path::PathBuf>,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = (|| {
        let scenario = cli.common.scenario()?;
        let mut params = scenario.cfg.sensor;
        if let Some(r) = cli.rate_hz {
            params.rate_hz = r;
        }
        if !(1..=afs_shared::rdt::MAX_RECORDS_PER_PACKET).contains(&cli.records_per_packet) {
            anyhow::bail!(
                "--records-per-packet {} must be 1 to {}",
                cli.records_per_packet,
                afs_shared::rdt::MAX_RECORDS_PER_PACKET
            );
        }
        let stop = stop_flag()?;
        run(
            &NetftArgs {
                prefix: cli.common.prefix.clone(),
                params,
                seed: scenario.cfg.seed,
                cpu: cli.common.cpu,
                priority: cli.common.priority,
                bind: SocketAddr::new(cli.bind, cli.port),
                calibration: Calibration {
                    counts_per_force: cli.counts_per_force,
                    counts_per_torque: cli.counts_per_torque,
                },
                mounting: Mounting {
                    plane: Plane::from_name(&cli.plane).context("plane")?,
                    angle_rad: cli.angle_deg.to_radians(),
                },
                records_per_packet: cli.records_per_packet,
                impairments: Impairments {
                    loss: cli.loss,
                    duplicate: cli.duplicate,
                    reorder: cli.reorder,
                    status_error_at_s: cli.status_error_at_s,
                    status_error_s: cli.status_error_s,
                    silent_at_s: cli.silent_at_s,
                    wrap_in: cli.wrap_in,
                },
                fault_seed: cli.fault_seed,
                power_up_bias: !cli.no_power_up_bias,
                wait_for_world: cli.wait_for_world,
            },
            &stop,
        )
    })();
    match result {
        Ok(s) => {
            if let Some(path) = &cli.summary
                && let Err(e) = serde_json::to_string(&s)
                    .map_err(std::io::Error::other)
                    .and_then(|text| std::fs::write(path, text))
            {
                eprintln!("afs-netft: error: writing {}: {e}", path.display());
                return ExitCode::from(2);
            }
            eprintln!(
                "afs-netft: {} samples, {} datagrams sent, {} requests ({} ignored: another client's or not RDT)",
                s.samples, s.datagrams, s.requests, s.ignored
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("afs-netft: error: {e:#}");
            ExitCode::from(2)
        }
    }
}
