//! The plant/servo board: the simulated world and the fast loop at 10 kHz on absolute-time
//! wake-ups.
//!
//! Each tick: wake, take the newest force sample through the watchdog gate, run the scenario
//! driver and one [`ServoCore`] step, advance the plant, publish the world and the controller
//! samples, move the estimator request along, keep the world snapshot, record the loop's
//! timing. Nothing in the tick allocates, locks, logs or blocks: histograms, the request
//! buffer and the probe record are allocated before the loop; iceoryx2 loans come from
//! pre-mapped shared memory.
//!
//! | file | job |
//! |---|---|
//! | `board` | `ServoBoard`: set-up, the tick, the end |
//! | `ports` | the iceoryx2 ports and the world blackboard's entry |
//! | `link` | the estimator's tangent service, moved along a tick at a time |
//! | `timing` | the loop's histograms and statistics |

mod board;
mod link;
mod ports;
mod robot;
mod timing;

use crate::rt;
use afs_shared::config::SimConfig;
use anyhow::Result;
use board::{ServoBoard, Tick};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

/// Default time the estimator has to answer before a request is re-sent (s).
pub const ESTIMATOR_TIMEOUT_S: f64 = 1.0;

/// How the servo reaches the estimator's tangent service.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EstimatorVia {
    /// iceoryx2 request-response: the estimator on the same host.
    RequestResponse,
    /// A request topic and a response topic: the estimator on the same host or, through the
    /// link board, on another (docs/link.md).
    Topics,
}

/// How the servo runs.
#[derive(Debug, Clone)]
pub struct ServoArgs {
    /// Stack prefix.
    pub prefix: String,
    /// Scenario name.
    pub scenario: String,
    /// The set-up (already with the scenario's overrides applied by `Scenario::new`).
    pub base: SimConfig,
    /// Stop after this much simulated time (s); 0 runs the scenario to its end.
    pub duration_s: f64,
    /// CPU to pin to.
    pub cpu: Option<usize>,
    /// SCHED_FIFO priority (0: normal scheduling).
    pub priority: u8,
    /// Resume the world from the supervisor's snapshot (after a servo restart).
    pub resume: bool,
    /// Largest age of force data at use (ms).
    pub max_force_age_ms: f64,
    /// Time the estimator has to answer before a request is re-sent (s).
    pub estimator_timeout_s: f64,
    /// Sends of one request before giving up and keeping the old tangent.
    pub estimator_attempts: u32,
    /// How the estimator is reached.
    pub estimator_via: EstimatorVia,
    /// Time to wait for the first force sample (s).
    pub startup_timeout_s: f64,
    /// Save the wake, execution-time and force-age histograms here at the end.
    pub histograms: Option<PathBuf>,
    /// Monotonic time `main` was entered (ns), for the start-up report.
    pub main_ns: u64,
    /// A robot to drive instead of the simulated world (`[robot]`, docs/franka.md).
    pub robot: Option<crate::stack::RobotTable>,
}

/// How the servo ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServoEnd {
    /// The scenario reached its end or its duration.
    Finished,
    /// Asked to stop (SIGINT/SIGTERM).
    Stopped,
}

/// Runs the board until the scenario ends, the duration passes or `stop` is set: the
/// iceoryx2 example's loop around [`ServoBoard::tick`], on absolute deadlines (no busy-spin).
pub fn run(args: &ServoArgs, stop: &AtomicBool) -> Result<ServoEnd> {
    if let Some(table) = &args.robot {
        return robot::run(args, table, stop);
    }
    let Some(mut board) = ServoBoard::start(args, stop)? else {
        return Ok(ServoEnd::Stopped);
    };
    let period = board.period_ns();
    let fifo = board.is_fifo();
    let mut deadline = rt::monotonic_ns() + period;
    let end = loop {
        rt::sleep_until(deadline);
        if stop.load(Ordering::Relaxed) {
            break ServoEnd::Stopped;
        }
        if !fifo && rt::monotonic_ns() > deadline + period {
            rt::let_peers_run();
        }
        if board.tick(deadline) == Tick::Done {
            break ServoEnd::Finished;
        }
        deadline = rt::next_deadline(deadline, period, rt::monotonic_ns());
    };
    board.finish(args.histograms.as_deref())?;
    Ok(end)
}
