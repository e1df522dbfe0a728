//! `afs-servo`: the plant/servo board (simulated world + 10 kHz fast loop).
//!
//! ```text
//! afs-servo --prefix afs --scenario surface-tracking --cpu 1 --priority 80
//! ```
//! Normally started by `afs run`; it waits for `afs-sensor` with the same prefix. Exits 0 when
//! its scenario ends or it is stopped, 2 on an error, 3 when the robot of `--robot-config` was
//! lost (`afs::robot::ROBOT_LOST_EXIT`: the supervisor then ends the run).

use afs::boards::servo::{EstimatorVia, ServoArgs, ServoEnd, run};
use afs::boards::{Common, stop_flag};
use clap::Parser;
use std::process::ExitCode;

/// The plant/servo board.
#[derive(Parser)]
#[command(name = "afs-servo", version)]
struct Cli {
    #[command(flatten)]
    common: Common,
    /// Simulated seconds to run (0: the scenario's own length).
    #[arg(long, default_value_t = 0.0)]
    duration: f64,
    /// Resume the world from the supervisor's snapshot (after a restart).
    #[arg(long)]
    resume: bool,
    /// Largest age of force data at use (ms) before the safe state.
    #[arg(long, default_value_t = 1.5)]
    max_force_age_ms: f64,
    /// Seconds the estimator has to answer before the request is re-sent.
    #[arg(long, default_value_t = afs::boards::servo::ESTIMATOR_TIMEOUT_S)]
    estimator_timeout: f64,
    /// Sends of one request before keeping the old tangent.
    #[arg(long, default_value_t = 10)]
    estimator_attempts: u32,
    /// How the estimator is reached: `request-response` (iceoryx2 request-response, one host)
    /// or `topics` (a request and a response topic, which a link to another host carries;
    /// docs/link.md).
    #[arg(long, value_enum, default_value_t = EstimatorVia::RequestResponse)]
    estimator_via: EstimatorVia,
    /// Seconds to wait for the first force sample.
    #[arg(long, default_value_t = 10.0)]
    startup_timeout: f64,
    /// Save the loop's wake, execution-time and force-age histograms (HdrHistogram V2:
    /// wake.hdr, exec.hdr, force_age.hdr) in this directory when the run ends.
    #[arg(long)]
    histograms: Option<std::path::PathBuf>,
    /// Drive the robot of this file's `[robot]` table (a stack file, or the table `afs run`
    /// writes) instead of the simulated world (docs/franka.md).
    #[arg(long)]
    robot_config: Option<std::path::PathBuf>,
}

fn main() -> ExitCode {
    let main_ns = afs::rt::monotonic_ns();
    let cli = Cli::parse();
    let result = (|| {
        if !(cli.duration.is_finite() && cli.duration >= 0.0) {
            anyhow::bail!(
                "--duration {} must be a number of seconds ≥ 0",
                cli.duration
            );
        }
        if !(cli.max_force_age_ms.is_finite() && cli.max_force_age_ms > 0.0) {
            anyhow::bail!("--max-force-age-ms must be > 0");
        }
        let stop = stop_flag()?;
        let args = ServoArgs {
            prefix: cli.common.prefix.clone(),
            scenario: cli.common.scenario.clone(),
            base: cli.common.base()?,
            duration_s: cli.duration,
            cpu: cli.common.cpu,
            priority: cli.common.priority,
            resume: cli.resume,
            max_force_age_ms: cli.max_force_age_ms,
            estimator_timeout_s: cli.estimator_timeout,
            estimator_attempts: cli.estimator_attempts,
            estimator_via: cli.estimator_via,
            startup_timeout_s: cli.startup_timeout,
            histograms: cli.histograms.clone(),
            main_ns,
            robot: cli
                .robot_config
                .as_deref()
                .map(afs::stack::robot::read)
                .transpose()?,
        };
        run(&args, &stop)
    })();
    match result {
        Ok(ServoEnd::Finished | ServoEnd::Stopped) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("afs-servo: error: {e:#}");
            // The supervisor ends the run on this one instead of restarting the servo.
            if afs::robot::is_robot_lost(&e) {
                ExitCode::from(afs::robot::ROBOT_LOST_EXIT)
            } else {
                ExitCode::from(2)
            }
        }
    }
}
