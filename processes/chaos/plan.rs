//! The fault plan of a chaos run: which kinds the scenario allows, and each kind's span from
//! the stack file's policies and the scenario's probe ([`afs_shared::faults::plan`] places them).

use super::inject::{MIN_UPTIME, THAW_AFTER};
use crate::stack::{ChaosOptions, LINK_PROCESS, ProcessSpec, StackFile};
use afs_shared::faults::{self, FaultKind};
use afs_shared::msg::Board;
use afs_shared::scenario::{self, Scenario};
use anyhow::{Context, Result, bail};

/// The fault plan of a chaos run: the kinds (the mid-probe and mid-request ones only where the
/// scenario tracks a surface), each kind's span from the stack's policies and the scenario's
/// probe, between 1 s in and 1 s before the end (the run's, or the scenario's own end in its
/// lockstep run if that comes first).
pub fn plan(
    c: &ChaosOptions,
    stack: &StackFile,
    scenario: &Scenario,
    duration: f64,
) -> Result<Vec<faults::PlannedFault>> {
    if c.faults > MAX_FAULTS {
        bail!(
            "{} faults are too many: at most {MAX_FAULTS} (one per {} ms of a day's run)",
            c.faults,
            86_400_000 / MAX_FAULTS
        );
    }
    if duration < 3.0 {
        bail!(
            "a chaos run needs at least 3 simulated seconds (faults fall between 1 s in and 1 s before the end); got {duration} s"
        );
    }
    let probes = scenario.cfg.servo.tracking.enabled;
    // Why the stack cannot take a kind (None: it can).
    let lacks = |k: FaultKind| -> Option<String> {
        if k.needs_probe() && !probes {
            return Some(format!(
                "needs a scenario that probes the tangent (surface-tracking, corner); {} does not",
                stack.scenario
            ));
        }
        if let Some(b) = k.target()
            && stack.spec(b).is_none()
        {
            return Some(format!(
                "needs a process named '{}' in the stack file (on another host, it is not this supervisor's to fault)",
                b.name()
            ));
        }
        if k.needs_link() && stack.link().is_none() {
            return Some(format!(
                "needs the link board, a process named '{LINK_PROCESS}' (docs/link.md)"
            ));
        }
        if k == FaultKind::CutLink && stack.link_cut().is_none() {
            return Some(
                "needs the commands that cut and restore the link: cut_link and restore_link in the stack file's [chaos] table (docs/link.md)".into(),
            );
        }
        None
    };
    let kinds: Vec<FaultKind> = if c.kinds.is_empty() {
        FaultKind::ALL
            .iter()
            .map(|(_, k)| *k)
            .filter(|k| lacks(*k).is_none())
            .collect()
    } else {
        if let Some((k, why)) = c.kinds.iter().find_map(|k| Some((k, lacks(*k)?))) {
            bail!("{} {why}", k.name());
        }
        c.kinds.clone()
    };
    let ms = |v: Option<u64>| v.unwrap_or(0) as f64 * 1e-3;
    let per_board = |f: fn(&ProcessSpec) -> u64| Board::ALL.map(|b| ms(stack.spec(b).map(f)));
    let tangent = &scenario.cfg.servo.tangent;
    let hybrid = &scenario.cfg.servo.hybrid;
    let spans = faults::FaultSpans {
        backoff_s: per_board(|p| p.backoff_ms),
        stall_s: per_board(|p| p.stall_ms),
        start_s: START_ALLOWANCE_S,
        uptime_s: MIN_UPTIME.as_secs_f64(),
        // Braking from the tracking speed, the hold until the normal force is back at the
        // preload (the probe's settle time), and margin.
        probe_start_s: scenario::TRACKING_VELOCITY / hybrid.tangential_acceleration_m_per_s2
            + tangent.settle_s
            + 0.3,
        probe_s: tangent.first_plan().duration(),
        retry_s: crate::boards::servo::ESTIMATOR_TIMEOUT_S + 0.5,
        thaw_s: THAW_AFTER.as_secs_f64(),
        burst_s: 0.05,
        link_backoff_s: ms(stack.link().map(|p| p.backoff_ms)),
        link_up_s: LINK_UP_S,
        cut_s: stack.cut_for_s(),
        link_lease_s: ZENOH_LEASE_S,
    };
    // A traverse can end before the duration.
    let end = match scenario.end_u_m {
        Some(_) => scenario::run_lockstep(scenario, duration)?
            .duration_s
            .min(duration),
        None => duration,
    };
    faults::plan(
        c.seed,
        c.faults,
        (1.0, end - 1.0),
        &kinds,
        c.in_turn,
        &spans,
        2.0 + (duration - end),
    )
    .with_context(|| format!("a chaos run of {duration} s"))
}

/// A board's start-up beyond its backoff, with margin, in a fault's span (s): restarts take
/// 20–70 ms beyond the backoff (docs/reliability.md).
const START_ALLOWANCE_S: f64 = 0.3;

/// From the link board's start, or a cut's end, until the tunnel carries again, with margin
/// (s): zenoh retries its connection about every second, and the tunnel discovers every
/// 100 ms (docs/link.md: a 12-s cut showed as 14.0 s of missing samples on host B).
const LINK_UP_S: f64 = 3.0;

/// zenoh's lease, as the link board leaves it (s): a cut longer than this closes zenoh's
/// session (docs/link.md).
const ZENOH_LEASE_S: f64 = 10.0;

/// Most faults one chaos run takes.
pub const MAX_FAULTS: usize = 10_000;
