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
//! | `stack` | the stack file and the command line's overrides |
//! | `child` | one supervised process: spawn, exit, stop, start-up timelines |
//! | `policy` | restart, backoff and stall policy (pure functions) |
//! | `watch` | the loop: streams, injector, children, status, progress |
//! | `footprint` | files and resident memory of a running stack |
//! | `report` | the run report, its checks and summary |
//! | `status` | `afs status` |

mod child;
mod footprint;
mod policy;
mod report;
mod stack;
mod status;
mod watch;

pub use afs_shared::join::{Joiner, SampleCounts};
pub use child::{ExitRecord, Timeline};
pub use footprint::Footprint;
pub use report::*;
pub use stack::*;
pub use status::*;

use crate::chaos::{self, ChaosReport, Injector, LinkCut};
use crate::ipc;
use crate::tools::record::Recorder;
use crate::tools::view::LiveView;
use afs_shared::check::Check;
use afs_shared::msg::{Board, FrictionStatus, ProcessState};
use afs_shared::scenario::{self, Scenario, ScenarioKind};
use anyhow::{Context, Result};
use child::{Launch, Proc};
use std::sync::atomic::AtomicBool;
use watch::{Ports, Sinks, Supervisor};
pub use watch::{RunEnd, default_wall_limit_s};

/// How long observers of the stack (`afs view`, clients) get to close their nodes after the
/// supervisor's Stopping status before the prefix is released and checked for leaks.
const OBSERVER_GRACE: std::time::Duration = std::time::Duration::from_secs(3);

/// The first contact's transient is not a fault's: the normal force counts from here (s).
const FAULT_SETTLE_S: f64 = 0.5;

/// The set-up directory of the supervisor `pid` of stack `prefix`.
pub fn setup_dir(prefix: &str, pid: u32) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("afs-{prefix}-{pid}"))
}

/// Removes the set-up directories of the prefix's supervisors that are no longer alive
/// (killed before they could remove their own).
fn remove_dead_setups(prefix: &str) {
    let head = format!("afs-{prefix}-");
    let Ok(dir) = std::fs::read_dir(std::env::temp_dir()) else {
        return;
    };
    for e in dir.flatten() {
        let name = e.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(|n| n.strip_prefix(&head))
            .and_then(|p| p.parse::<i32>().ok())
        else {
            continue;
        };
        if pid as u32 != std::process::id() && !crate::procfs::alive(pid) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Runs a stack until its scenario ends, it is stopped, or it fails; returns its report.
pub fn run(opts: &RunOptions, stop: &AtomicBool) -> Result<RunReport> {
    let stack = load_stack(opts)?;
    let scenario = Scenario::new(&stack.scenario, &stack.sim_config()?)?;
    let duration = if stack.duration_s > 0.0 {
        stack.duration_s.min(scenario.natural_duration_s)
    } else {
        scenario.natural_duration_s
    };
    let prefix = stack.prefix.clone();
    let mut procs = stack
        .process
        .iter()
        .map(Proc::new)
        .collect::<Result<Vec<_>>>()?;
    let plan = opts
        .chaos
        .as_ref()
        .map(|c| chaos::plan(c, &stack, &scenario, duration))
        .transpose()?;

    // The live view first: a port in use is refused before anything is set up.
    let view = match opts.foxglove {
        Some(v) => {
            let tick_hz = 1.0 / scenario.cfg.servo.dt();
            // The cores of the real-time boards.
            let avoid: Vec<usize> = stack
                .process
                .iter()
                .filter(|p| p.priority > 0)
                .filter_map(|p| p.cpu)
                .collect();
            let lv = LiveView::start(v, Some(tick_hz), &format!("afs {prefix}"), &avoid)?;
            eprintln!(
                "afs: live view at {} (open it in Foxglove with examples/foxglove-layout.json)",
                lv.url()
            );
            Some(lv)
        }
        None => None,
    };

    // The prefix must be free; a dead stack's leftovers are removed.
    let (cleaned, removed) = ipc::claim_prefix(&prefix)?;
    if cleaned > 0 || removed > 0 {
        eprintln!(
            "afs: removed the leftovers of a dead stack '{prefix}' ({cleaned} nodes, {removed} files)"
        );
    }

    // A killed supervisor's set-up directory (below) is removed too.
    remove_dead_setups(&prefix);

    // Shared memory the supervisor owns and reads.
    let node = ipc::node(&prefix, "supervisor")?;
    let world = ipc::create_world(&node).with_context(|| {
        format!("another supervisor holds prefix '{prefix}'; stop it or choose another --prefix")
    })?;
    let ports = Ports::open(&node)?;

    // The set-up the boards read.
    let dir = setup_dir(&prefix, std::process::id());
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let sim_file = match &stack.sim {
        Some(t) => {
            let f = dir.join("sim.toml");
            std::fs::write(&f, toml::to_string(t).context("writing [sim]")?)
                .with_context(|| format!("writing {}", f.display()))?;
            Some(f)
        }
        None => None,
    };
    let launch = Launch {
        prefix: prefix.clone(),
        scenario: stack.scenario.clone(),
        seed: stack.seed,
        sim_file,
        duration,
    };
    let recorder = opts.record.as_deref().map(Recorder::start).transpose()?;
    let injector = match plan {
        Some(plan) => {
            let publisher = ipc::wrench(&node)?
                .publisher_builder()
                .create()
                .context("creating the bad-sample publisher")?;
            let inj = Injector::new(plan, publisher)
                .with_cut(std::time::Duration::from_secs_f64(stack.cut_for_s()));
            for p in procs.iter_mut() {
                if let Some(b) = p.board {
                    p.injected_budget = inj.planned_for(b);
                } else if p.spec.name == LINK_PROCESS {
                    p.injected_budget = inj.planned_link_kills();
                }
            }
            Some(inj)
        }
        None => None,
    };

    let mut sup = Supervisor::new(procs, launch, &scenario, duration, ports)
        .with_sinks(Sinks { recorder, view })
        .injecting(injector)
        .cutting_with(
            stack
                .link_cut()
                .map(|(cut, restore)| LinkCut::new(cut, restore)),
        )
        .with_progress(opts.progress)
        .with_wall_limit(std::time::Duration::from_secs_f64(
            stack
                .wall_limit_s
                .unwrap_or_else(|| default_wall_limit_s(duration)),
        ));
    let result = sup.run(stop);
    let wall_s = sup.shut_down();
    result?;
    let (record, view) = sup.finish_sinks()?;
    let chaos_report = sup.injector.take().map(|inj| {
        let mut records = inj.records().to_vec();
        for r in records.iter_mut().filter(|r| r.pid != 0) {
            r.restart = sup
                .procs
                .iter()
                .flat_map(|p| &p.exits)
                .find(|e| e.pid == r.pid)
                .and_then(|e| e.restart);
        }
        ChaosReport::new(
            inj.plan().len(),
            records,
            inj.bad_samples(),
            sup.stats.as_ref().map(|s| LoopReport::from(s).bad_samples),
            std::mem::take(&mut sup.steady),
        )
    });
    let procs = std::mem::take(&mut sup.procs);
    let monitor = sup.monitor.clone();
    let faults = sup.faults.figures();
    let (stats, friction, sensor_stats) = (sup.stats, sup.friction, sup.sensor_stats);
    let end = sup.end.unwrap_or(RunEnd::Interrupted);
    let (finished, interrupted) = (end == RunEnd::Finished, end == RunEnd::Interrupted);
    let samples = sup.joiner.counts(sup.wrench_received);
    drop(sup);
    drop((world, node));
    let _ = std::fs::remove_dir_all(&dir);
    // Observers told by the Stopping status get a moment to close their nodes first.
    let t_release = std::time::Instant::now();
    while ipc::census(&prefix, false).is_ok_and(|c| !c.alive.is_empty())
        && t_release.elapsed() < OBSERVER_GRACE
    {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // Everything of the prefix must have gone with its nodes (iceoryx2's clean-up); what is
    // left is a leak, reported and failed below, not removed here.
    let left = ipc::release_prefix(&prefix).unwrap_or_else(|_| ipc::leftovers(&prefix));

    // The lockstep reference, going through the stack's events (≈ 300× real time).
    let reference = scenario::run_lockstep_replay(&scenario, duration, &monitor.replay())?;
    let stack_report = monitor.report();
    let agreement = scenario::compare(&stack_report, &reference);

    let mut checks = vec![
        // A run the user did not stop must reach its end: one stopped by the wall-time limit or
        // by a servo that gave up never ran the scenario through, whatever its figures say.
        Check::at_least(
            "reached_end",
            format!("the scenario ran to its end (this run: {})", end.describe()),
            f64::from(finished || interrupted),
            1.0,
        ),
        Check::at_least(
            "servo_ticks_run",
            "servo ticks run",
            stack_report.ticks as f64,
            1.0,
        ),
        Check::at_most(
            "processes_gave_up",
            "processes that gave up (restart limit)",
            procs
                .iter()
                .filter(|p| p.state == ProcessState::Failed)
                .count() as f64,
            0.0,
        ),
        Check::at_most(
            "prefix_files_left",
            "iceoryx2 files of the prefix left",
            left.len() as f64,
            0.0,
        ),
    ];
    // A restarted servo resumes the world and its controller, and the lockstep reference goes
    // through the same restarts at the same ticks (with the same probe runs started again).
    if finished {
        checks.push(Check::at_most(
            "lockstep_agreement",
            "figures within tolerance of the lockstep reference",
            agreement.figures.iter().filter(|f| !f.agrees).count() as f64,
            0.0,
        ));
    }
    match scenario.kind {
        ScenarioKind::SurfaceTracking | ScenarioKind::Corner => {
            checks.push(Check::at_most(
                "ticks_without_contact",
                "servo ticks without contact",
                stack_report.tracking.ticks_without_contact as f64,
                0.0,
            ));
        }
        ScenarioKind::FrictionSuppression => {
            if let Some(f) = &stack_report.friction
                && finished
                && duration >= scenario.natural_duration_s
            {
                checks.push(Check::at_most(
                    "friction_end_over_start",
                    "mean friction at the end / before tuning",
                    f.end_ratio,
                    0.25,
                ));
            }
        }
        ScenarioKind::FrictionId => {
            if finished {
                let identified =
                    friction.is_some_and(|f| f.status.contains(FrictionStatus::MU_VALID));
                checks.push(Check::at_least(
                    "friction_identified",
                    "friction coefficient identified",
                    f64::from(identified),
                    1.0,
                ));
            }
        }
    }
    checks.push(Check::at_most(
        "non_finite_force_ticks",
        "servo ticks whose force values were not finite",
        faults.controller_non_finite as f64,
        0.0,
    ));
    if let Some(c) = &chaos_report {
        checks.extend(
            c.checks(&chaos::Measured {
                faults: &faults,
                preload_n: scenario.cfg.servo.hybrid.preload_n,
                gate: stats.as_ref().map(|s| LoopReport::from(s).bad_samples),
                servo_restarted: procs
                    .iter()
                    .any(|p| p.board == Some(Board::Servo) && p.restarts > 0),
            }),
        );
    }
    Ok(RunReport {
        scenario: stack.scenario.clone(),
        prefix,
        seed: stack.seed,
        duration_s: duration,
        finished,
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
        cleanup: Cleanup {
            left: left.iter().map(|p| p.display().to_string()).collect(),
        },
        faults,
        chaos: chaos_report,
        wall_s,
    })
}
