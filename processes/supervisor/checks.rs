//! The correctness checks of a run: it reached its end, nothing gave up, nothing of the stack
//! was left, the figures agree with the lockstep reference, the scenario's own criteria, no
//! non-finite force reached the controller; with faults, chaos's checks.

use super::child::Proc;
use super::{Cleanup, RunEnd};
use crate::chaos::{ChaosReport, Measured};
use afs_shared::check::Check;
use afs_shared::faults::FaultFigures;
use afs_shared::msg::{Board, FrictionReport, FrictionStatus, ProcessState};
use afs_shared::scenario::{Agreement, Scenario, ScenarioKind, ScenarioReport};

/// What the checks look at.
pub(super) struct Inputs<'a> {
    pub(super) scenario: &'a Scenario,
    pub(super) duration: f64,
    pub(super) end: RunEnd,
    pub(super) procs: &'a [Proc],
    pub(super) cleanup: &'a Cleanup,
    pub(super) stack: &'a ScenarioReport,
    pub(super) agreement: &'a Agreement,
    pub(super) friction: Option<&'a FrictionReport>,
    pub(super) faults: &'a FaultFigures,
    pub(super) chaos: Option<&'a ChaosReport>,
    /// The servo drove a robot (`[robot]`): the lockstep's planar plant is not its world.
    pub(super) robot: bool,
}

/// A robot's surface tracking passes with its tangent error's RMS at most this (°; issue 48).
pub const ROBOT_TANGENT_ERROR_RMS_DEG: f64 = 1.0;

/// The run's checks, each with its stable identifier.
pub(super) fn run_checks(i: &Inputs<'_>) -> Vec<Check> {
    let finished = i.end == RunEnd::Finished;
    let interrupted = i.end == RunEnd::Interrupted;
    let mut checks = vec![
        // A run the user did not stop must reach its end: one stopped by the wall-time limit or
        // by a servo that gave up never ran the scenario through, whatever its figures say.
        Check::at_least(
            "reached_end",
            format!(
                "the scenario ran to its end (this run: {})",
                i.end.describe()
            ),
            f64::from(finished || interrupted),
            1.0,
        ),
        Check::at_least(
            "servo_ticks_run",
            "servo ticks run",
            i.stack.ticks as f64,
            1.0,
        ),
        Check::at_most(
            "processes_gave_up",
            "processes that gave up (restart limit)",
            i.procs
                .iter()
                .filter(|p| p.state == ProcessState::Failed)
                .count() as f64,
            0.0,
        ),
        Check::at_most(
            "prefix_files_left",
            "iceoryx2 files of the stack left (an observer's own are not the stack's)",
            i.cleanup.left.len() as f64,
            0.0,
        ),
    ];
    // A restarted servo resumes the world and its controller, and the lockstep reference goes
    // through the same restarts at the same ticks (with the same probe runs started again).
    // On a robot the lockstep's planar plant is another world (it is reported beside the
    // robot's figures, not held against them); the scenario's own limits stand instead.
    if finished && i.robot {
        checks.extend(robot_checks(i));
    } else if finished {
        checks.push(Check::at_most(
            "lockstep_agreement",
            "figures within tolerance of the lockstep reference",
            i.agreement.figures.iter().filter(|f| !f.agrees).count() as f64,
            0.0,
        ));
    }
    checks.extend(scenario_checks(i, finished));
    checks.push(Check::at_most(
        "non_finite_force_ticks",
        "servo ticks whose force values were not finite",
        i.faults.controller_non_finite as f64,
        0.0,
    ));
    if let Some(c) = i.chaos {
        checks.extend(
            c.checks(&Measured {
                faults: i.faults,
                preload_n: super::watch::nominal_force_n(i.scenario),
                force_limits: i
                    .scenario
                    .insertion
                    .map_or((2.0, 1.5), |o| (o.force_limit_factor, o.force_limit_factor)),
                servo_restarted: i
                    .procs
                    .iter()
                    .any(|p| p.board == Some(Board::Servo) && p.restarts > 0),
                robot: i.robot,
            }),
        );
    }
    checks
}

/// What a robot's run must reach on its own (issue 48's done-when).
fn robot_checks(i: &Inputs<'_>) -> Vec<Check> {
    match i.scenario.kind {
        ScenarioKind::SurfaceTracking | ScenarioKind::Corner => vec![Check::at_most(
            "tangent_error_rms_deg",
            "the tangent estimate's RMS error on the robot (°)",
            i.stack.tracking.tangent_error_rms_deg,
            ROBOT_TANGENT_ERROR_RMS_DEG,
        )],
        _ => Vec::new(),
    }
}

/// The scenario's own criteria.
fn scenario_checks(i: &Inputs<'_>, finished: bool) -> Vec<Check> {
    match i.scenario.kind {
        ScenarioKind::SurfaceTracking | ScenarioKind::Corner => vec![Check::at_most(
            "ticks_without_contact",
            "servo ticks without contact",
            i.stack.tracking.ticks_without_contact as f64,
            0.0,
        )],
        ScenarioKind::FrictionSuppression => i
            .stack
            .friction
            .as_ref()
            .filter(|_| finished && i.duration >= i.scenario.natural_duration_s)
            .map(|f| {
                Check::at_most(
                    "friction_end_over_start",
                    "mean friction at the end / before tuning",
                    f.end_ratio,
                    0.25,
                )
            })
            .into_iter()
            .collect(),
        ScenarioKind::FrictionId if finished => {
            let identified = i
                .friction
                .is_some_and(|f| f.status.contains(FrictionStatus::MU_VALID));
            vec![Check::at_least(
                "friction_identified",
                "friction coefficient identified",
                f64::from(identified),
                1.0,
            )]
        }
        ScenarioKind::FrictionId => Vec::new(),
        ScenarioKind::Insertion => insertion_checks(i, finished),
    }
}

/// The insertion's own criteria (those of `afs experiment insertion`): in, within the force
/// limit, the contact state estimated right.
fn insertion_checks(i: &Inputs<'_>, finished: bool) -> Vec<Check> {
    let (Some(run), Some(o), true) = (&i.stack.insertion, &i.scenario.insertion, finished) else {
        return Vec::new();
    };
    // A run shorter than the time limit may end before the depth: in, or not yet over.
    let whole = i.duration >= i.scenario.natural_duration_s;
    let done = run.inserted || (!whole && run.peak_force_n <= o.force_limit_n());
    vec![
        Check::at_least(
            "inserted",
            "depth reached in time, force in limit (1 = yes; a run shorter than the time \
             limit: not failed yet)",
            f64::from(u8::from(done)),
            1.0,
        ),
        Check::at_most(
            "peak_force_over_insertion_force",
            "largest contact force / insertion force",
            run.peak_force_n / o.controller_params().insertion_force_n,
            o.force_limit_factor,
        ),
        Check::at_least(
            "state_classification_accuracy",
            "contact states estimated right, outside 10 ms of a transition",
            run.state_classification_accuracy,
            0.95,
        ),
    ]
}
