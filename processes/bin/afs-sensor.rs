//! `afs-sensor`: the force-sensor board: the sensor model on its own 7 kHz clock, or a real
//! sensor (or `afs-netft`) speaking ATI's RDT over UDP.
//!
//! ```text
//! afs-sensor --prefix afs --scenario surface-tracking --cpu 1 --priority 85
//! afs-sensor --prefix afs --source rdt --address 192.168.1.1 --counts-per-force 1000000
//! ```

use afs::boards::sensor::rdt::RdtArgs;
use afs::boards::sensor::{SensorArgs, Source, run};
use afs::boards::{Common, stop_flag};
use clap::Parser;
use std::process::ExitCode;

/// The force-sensor board.
#[derive(Parser)]
#[command(name = "afs-sensor", version)]
struct Cli {
    #[command(flatten)]
    common: Common,
    /// Where the samples come from: the sensor model on the simulated world, or an RDT device.
    #[arg(long, default_value = "model", value_parser = ["model", "rdt"])]
    source: String,
    #[command(flatten)]
    rdt: RdtArgs,
    /// Low-pass cut-off (Hz, 0 disables), overriding the set-up's (model).
    #[arg(long)]
    cutoff_hz: Option<f64>,
    /// Sample rate (Hz), overriding the set-up's (model: the board's clock; rdt: the device's
    /// internal rate).
    #[arg(long)]
    rate_hz: Option<f64>,
}

fn main() -> ExitCode {
    let main_ns = afs::rt::monotonic_ns();
    let cli = Cli::parse();
    let result = (|| {
        let scenario = cli.common.scenario()?;
        let mut params = scenario.cfg.sensor;
        if let Some(c) = cli.cutoff_hz {
            params.cutoff_hz = c;
        }
        if let Some(r) = cli.rate_hz {
            params.rate_hz = r;
        }
        let source = match cli.source.as_str() {
            "rdt" => Source::Rdt(cli.rdt.settings(params.rate_hz)?),
            _ => Source::Model,
        };
        let stop = stop_flag()?;
        run(
            &SensorArgs {
                prefix: cli.common.prefix.clone(),
                params,
                seed: scenario.cfg.seed,
                cpu: cli.common.cpu,
                priority: cli.common.priority,
                source,
                main_ns,
            },
            &stop,
        )
    })();
    match result {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("afs-sensor: error: {e:#}");
            ExitCode::from(2)
        }
    }
}
