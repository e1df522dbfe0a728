//! `afs-sensor`: the force-sensor board (its own 7 kHz clock and the sensor model).
//!
//! ```text
//! afs-sensor --prefix afs --scenario surface-tracking --cpu 1 --priority 85
//! ```

use afs::boards::sensor::{SensorArgs, run};
use afs::boards::{Common, stop_flag};
use clap::Parser;
use std::process::ExitCode;

/// The force-sensor board.
#[derive(Parser)]
#[command(name = "afs-sensor", version)]
struct Cli {
    #[command(flatten)]
    common: Common,
    /// Low-pass cut-off (Hz, 0 disables), overriding the set-up's.
    #[arg(long)]
    cutoff_hz: Option<f64>,
    /// Sample rate (Hz), overriding the set-up's.
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
        let stop = stop_flag()?;
        run(
            &SensorArgs {
                prefix: cli.common.prefix.clone(),
                params,
                seed: scenario.cfg.seed,
                cpu: cli.common.cpu,
                priority: cli.common.priority,
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
