//! `afs run`: launches the process graph of a stack file, watches it, restarts what dies,
//! records, and reports the scenario's figures against the lockstep reference.
//!
//! The supervisor owns the world blackboard (so a restarted servo resumes the world) and
//! consumes the plant and servo streams: it joins them by tick, feeds the same
//! `ScenarioMonitor` the lockstep reference uses, and forwards every sample to the recorder.
//! Children get SIGTERM if the supervisor dies (`PR_SET_PDEATHSIG`); a supervisor that finds a
//! dead stack's resources under its prefix removes them before starting.
//!
//! | file | job |
//! |---|---|
//! | `setup` | what a run is set up with: plan, live view, prefix, shared memory, injector |
//! | `child` | one supervised process: spawn, exit, stop, start-up timelines |
//! | `policy` | restart, backoff and stall policy (pure functions) |
//! | `watch` | the loop: streams, injector, children, status, progress |
//! | `footprint` | measuring a running stack's files and resident memory |
//! | `report` | the run report and its summary |
//! | `checks` | the run's correctness checks |
//! | `status` | `afs status` |

mod checks;
mod child;
mod footprint;
#[doc(hidden)]
pub mod policy;
mod report;
mod setup;
mod status;
mod watch;

pub use afs_shared::join::{Joiner, SampleCounts};
pub use child::ExitRecord;
pub use report::*;
pub use status::*;

use crate::chaos::{BadSampleReport, ChaosReport};
use crate::ipc;
use crate::stack::RunOptions;
use afs_shared::msg::ProcessState;
use afs_shared::scenario;
use anyhow::Result;
pub use setup::setup_dir;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use watch::Supervisor;
pub use watch::{RunEnd, default_wall_limit_s};

/// How long observers of the stack (`afs view`, clients) get to close their nodes after the
/// supervisor's Stopping status before the prefix is released and checked for leaks.
const OBSERVER_GRACE: Duration = Duration::from_secs(3);

/// Runs a stack until its scenario ends, it is stopped, or it fails; returns its report.
pub fn run(opts: &RunOptions, stop: &AtomicBool) -> Result<RunReport> {
    let mut setup = setup::Setup::prepare(opts)?;
    let mut sup = match setup.supervisor(opts) {
        Ok(sup) => sup,
        Err(e) => {
            let _ = setup.release(&[]);
            return Err(e);
        }
    };
    let result = sup.run(stop);
    let wall_s = sup.shut_down();
    if let Err(e) = result {
        // A run that fails (a board that cannot start) gives its prefix back all the same:
        // its processes are stopped; the supervisor's node and the node counter go.
        let procs = std::mem::take(&mut sup.procs);
        drop(sup);
        let _ = setup.release(&procs);
        return Err(e);
    }
    let (record, view) = sup.finish_sinks()?;
    let chaos_report = chaos_report(&mut sup);
    let procs = std::mem::take(&mut sup.procs);
    let monitor = sup.monitor.clone();
    let faults = sup.faults.figures();
    let (stats, friction, sensor_stats) = (sup.stats, sup.friction, sup.sensor_stats);
    let end = sup.end.unwrap_or(RunEnd::Interrupted);
    let samples = sup.joiner.counts(sup.wrench_received);
    drop(sup);
    let contact = setup.contact_report();
    let cleanup = setup.release(&procs)?;
    let (stack, scenario, duration) = (&setup.stack, &setup.scenario, setup.duration);

    // The lockstep reference, going through the stack's events (≈ 300× real time).
    let reference = scenario::run_lockstep_replay(scenario, duration, &monitor.replay())?;
    let stack_report = monitor.report();
    let agreement = scenario::compare(&stack_report, &reference);
    let checks = checks::run_checks(&checks::Inputs {
        scenario,
        duration,
        end,
        procs: &procs,
        cleanup: &cleanup,
        stack: &stack_report,
        agreement: &agreement,
        friction: friction.as_ref(),
        faults: &faults,
        chaos: chaos_report.as_ref(),
        robot: stack.robot.is_some(),
    });
    let interrupted = end == RunEnd::Interrupted;
    Ok(RunReport {
        scenario: stack.scenario.clone(),
        prefix: stack.prefix.clone(),
        seed: stack.seed,
        duration_s: duration,
        finished: end == RunEnd::Finished,
        interrupted,
        end,
        passed: RunReport::all_passed(&checks, interrupted),
        checks,
        stack: stack_report,
        reference,
        agreement,
        loop_stats: stats.as_ref().map(LoopReport::from),
        sensor: sensor_stats.as_ref().map(SensorReport::from),
        friction: friction.as_ref().map(FrictionIdReport::from),
        samples,
        contact,
        processes: procs
            .into_iter()
            .map(|p| ProcessReport {
                name: p.spec.name,
                restarts: p.restarts,
                stalls_killed: p.stalls,
                gave_up: p.state == ProcessState::Failed,
                first_start: p.first_start,
                exits: p.exits,
            })
            .collect(),
        record,
        view,
        cleanup,
        faults,
        chaos: chaos_report,
        wall_s,
    })
}

/// The chaos part of the report: each fault with its board's restart timeline, and the bad
/// samples, sent and as the servo judged them.
fn chaos_report(sup: &mut Supervisor) -> Option<ChaosReport> {
    let inj = sup.injector.take()?;
    let mut records = inj.records().to_vec();
    for r in records.iter_mut().filter(|r| r.pid != 0) {
        r.restart = sup
            .procs
            .iter()
            .flat_map(|p| &p.exits)
            .find(|e| e.pid == r.pid)
            .and_then(|e| e.restart);
    }
    let bad = inj.bad_samples();
    let bad = BadSampleReport {
        sent: bad.sent(),
        to_servo: bad.to_servo(),
        not_sent_to_servo: bad.sent().total() - bad.to_servo().total(),
        judged_by_servo: sup.stats.as_ref().map(|s| s.injected),
    };
    Some(ChaosReport::new(
        inj.plan().len(),
        records,
        bad,
        std::mem::take(&mut sup.steady),
    ))
}

/// Waits (at most [`OBSERVER_GRACE`]) for the nodes of the prefix to go, observers told by the
/// Stopping status among them, then gives the prefix back: what the stack's own processes
/// (`own`) left is a leak, an observer still attached is reported with its services.
fn end_stack(prefix: &str, own: &[i32]) -> Result<ipc::StackEnd> {
    let t0 = Instant::now();
    while ipc::census(prefix, false).is_ok_and(|c| !c.alive.is_empty())
        && t0.elapsed() < OBSERVER_GRACE
    {
        std::thread::sleep(Duration::from_millis(20));
    }
    ipc::end_stack(prefix, own)
}
