//! `afs bench robot` (docs/franka.md, *The FCI loop*): afs's FCI client holding an FR3 where it
//! found it, the robot of `--config`'s `[robot]` table (franky-sim's through
//! examples/python/fr3_cell.py, or a real one): from a state received to its torque command
//! sent, the cycles the robot ran without a command from afs, its command success rate, and
//! how far the held tool drifted.

use super::{BenchOptions, PartReport, Series, finish_part};
use crate::robot::hold;
use crate::stack::StackFile;
use crate::stack::robot::RobotTable;
use afs_shared::check::Check;
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::sync::atomic::AtomicBool;

/// The robot part's report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RobotPart {
    /// The robot's address.
    pub address: String,
    /// Cycles run (packets answered).
    pub cycles: u64,
    /// The robot's time over the run (s).
    pub robot_time_s: f64,
    /// The loop's wall time (s).
    pub wall_s: f64,
    /// Robot cycles with no command from afs.
    pub missed_cycles: u64,
    /// The robot's command success rate at the end (0–1).
    pub command_success_rate: f64,
    /// The largest planar distance of the tool from where it was held (m).
    pub drift_m: f64,
    /// The largest |θ − θ₀| (rad).
    pub drift_rad: f64,
    /// Cycles in which the torque-rate limit cut a joint.
    pub rate_limited_cycles: u64,
    /// Why the guard tripped, if it did.
    pub trip: Option<String>,
    /// Where the tool was held: x, y (m), θ (rad) and the normal offset (m) in the task plane.
    pub start_in_plane: [f64; 4],
    /// The loop's thread ran at SCHED_FIFO.
    pub fifo: bool,
    /// Its memory was locked.
    pub mlocked: bool,
    /// The peer figure: pylibfranka's own torque loop on the same robot right after
    /// (examples/python/fci_peer_loop.py's report, or why it was skipped).
    pub peer_pylibfranka: serde_json::Value,
    /// Series, targets, files.
    #[serde(flatten)]
    pub part: PartReport,
}

/// The `[robot]` table of the stack file `--config`.
fn table(opts: &BenchOptions) -> Result<RobotTable> {
    let Some(path) = &opts.config else {
        bail!(
            "afs bench robot needs --config FILE, a stack file with a [robot] table (docs/franka.md)"
        );
    };
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading stack file {}", path.display()))?;
    let stack = StackFile::parse(&text, &path.display().to_string())?;
    stack.robot.with_context(|| {
        format!(
            "{} has no [robot] table: afs bench robot needs the robot's (docs/franka.md)",
            path.display()
        )
    })
}

/// Runs the part.
pub(super) fn robot_part(opts: &BenchOptions, stop: &AtomicBool) -> Result<RobotPart> {
    let table = table(opts)?;
    let run = hold(&table, opts.duration_s, stop)?;
    let targets = vec![
        Check::at_most(
            "state_to_command_p99_us",
            "from a state received to its command sent, p99 (µs), within the 1-ms cycle",
            run.state_to_command_ns.value_at_quantile(0.99) as f64 / 1e3,
            300.0,
        ),
        Check::at_least(
            "command_success_rate",
            "the robot's command success rate",
            run.command_success_rate,
            0.95,
        ),
        Check::at_most(
            "drift_m",
            "the held tool's largest drift (m)",
            run.drift_m,
            1e-3,
        ),
        Check::at_most(
            "guard_trips",
            "the guard's trips (the tool out of [robot.limits])",
            f64::from(u8::from(run.trip.is_some())),
            0.0,
        ),
    ];
    let series = [Series {
        name: "state_to_command",
        what: "from a robot state received to its torque command sent",
        floor: None,
        hist: run.state_to_command_ns,
    }];
    let peer_pylibfranka = peer(&table.address, opts.duration_s);
    let part = finish_part(
        "robot",
        &series,
        &[],
        targets,
        &opts.out,
        "afs bench robot: state received to command sent",
    )?;
    Ok(RobotPart {
        address: table.address,
        cycles: run.cycles,
        robot_time_s: run.robot_time_s,
        wall_s: run.wall_s,
        missed_cycles: run.missed_cycles,
        command_success_rate: run.command_success_rate,
        drift_m: run.drift_m,
        drift_rad: run.drift_rad,
        rate_limited_cycles: run.rate_limited_cycles,
        trip: run.trip,
        start_in_plane: run.start,
        fifo: run.realtime.fifo,
        mlocked: run.realtime.mlocked,
        peer_pylibfranka,
        part,
    })
}

/// pylibfranka's torque loop on the robot at `address` for `seconds` of its time
/// (examples/python/fci_peer_loop.py, from the working directory or the source tree afs was
/// built from); `{"skipped": why}` when it cannot run.
fn peer(address: &str, seconds: f64) -> serde_json::Value {
    let script = [
        "examples/python/fci_peer_loop.py",
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/examples/python/fci_peer_loop.py"
        ),
    ]
    .into_iter()
    .map(std::path::PathBuf::from)
    .find(|p| p.is_file());
    let Some(script) = script else {
        return serde_json::json!({"skipped": "examples/python/fci_peer_loop.py not found: run from afs's source tree"});
    };
    let out = std::process::Command::new("python3")
        .arg(&script)
        .args(["--address", address, "--seconds", &seconds.to_string()])
        .output();
    match out {
        Ok(o) if o.status.success() => serde_json::from_slice(&o.stdout).unwrap_or_else(
            |e| serde_json::json!({"skipped": format!("its report did not parse: {e}")}),
        ),
        Ok(o) => serde_json::json!({"skipped": format!(
            "it failed ({}): {}",
            o.status,
            String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("")
        )}),
        Err(e) => serde_json::json!({"skipped": format!("python3 did not start: {e}")}),
    }
}
