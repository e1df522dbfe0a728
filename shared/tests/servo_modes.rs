//! `ServoCore`'s mode machine, transition by transition: track → stop → probe → await the
//! estimate → resume → track, with each estimator answer (estimate, re-probe, failure, none),
//! and the safe state entered from each mode. Driven through the lockstep (plant and sensor in
//! the loop), with the estimator's answers given by hand.

use afs_shared::servo::{ServoCore, ServoMode};
use afs_shared::sim::{Lockstep, SimConfig};
use afs_shared::tangent::{ReprobeReason, TangentError, TangentOutcome};

/// A lockstep tracking at 5 mm/s with a 3° tangent error; the test answers the estimator.
fn tracking() -> Lockstep {
    let cfg = SimConfig {
        tangent_error_rad: 3f64.to_radians(),
        ..SimConfig::default()
    };
    let mut sim = Lockstep::new(&cfg).unwrap();
    sim.set_auto_estimate(false);
    sim.servo_mut().hybrid_mut().set_velocity(0.005);
    sim.run(3000);
    assert_eq!(sim.servo().mode(), ServoMode::Track);
    sim
}

/// Steps until the servo is in `mode` (at most `limit` ticks); returns the ticks it took.
fn until(sim: &mut Lockstep, mode: ServoMode, limit: usize) -> usize {
    for n in 0..limit {
        if sim.servo().mode() == mode {
            return n;
        }
        sim.step();
    }
    panic!(
        "not {mode:?} within {limit} ticks: {:?} at {} s",
        sim.servo().mode(),
        sim.time()
    );
}

/// The estimator's answer to the pending probe run, as the estimator board computes it.
fn estimate(servo: &ServoCore) -> TangentOutcome {
    let req = servo
        .pending_probe()
        .expect("a probe run awaits its estimate");
    afs_shared::tangent::estimate(
        req.samples,
        req.plan,
        req.base_angle,
        &servo.params().tangent,
        req.reprobe,
    )
}

/// The whole cycle: a request stops the servo (velocity target 0 at once), it probes once
/// stopped and settled, awaits the estimate with the record pending, applies it, resumes and
/// tracks again at the old speed along the new tangent; a second request while busy is
/// ignored.
#[test]
fn track_stop_probe_await_resume_track() {
    let mut sim = tracking();
    sim.servo_mut().request_tangent_estimate();
    assert_eq!(sim.servo().mode(), ServoMode::Stopping);
    assert_eq!(sim.servo().hybrid().velocity_target(), 0.0);
    sim.servo_mut().request_tangent_estimate();
    let c = sim.servo().counters();
    assert_eq!((c.started, c.requested), (1, 1));
    until(&mut sim, ServoMode::Probing, 40_000);
    assert_eq!(sim.servo().hybrid().nominal_velocity(), 0.0);
    assert!(sim.servo().pending_probe().is_none());
    until(&mut sim, ServoMode::AwaitingEstimate, 200_000);
    let outcome = estimate(sim.servo());
    let TangentOutcome::Estimate(e) = outcome else {
        panic!("{outcome:?}")
    };
    // Waiting holds: no answer, no change.
    sim.run(1000);
    assert_eq!(sim.servo().mode(), ServoMode::AwaitingEstimate);
    sim.servo_mut().apply_tangent_outcome(&outcome);
    assert_eq!(sim.servo().mode(), ServoMode::Resuming);
    assert_eq!(
        sim.servo().hybrid().frame().tangent_angle,
        e.tangent_angle_rad
    );
    until(&mut sim, ServoMode::Track, 40_000);
    assert_eq!(sim.servo().hybrid().velocity_target(), 0.005);
    let c = sim.servo().counters();
    assert_eq!((c.started, c.estimates, c.failures), (1, 1, 0));
}

/// A re-probe answer runs the re-probe plan (marked as a re-probe) and awaits again; a failure
/// keeps the old tangent and resumes; so does giving up on an estimator that does not answer.
/// An answer outside the await is ignored.
#[test]
fn reprobe_failure_and_no_answer() {
    let mut sim = tracking();
    let tangent = sim.servo().hybrid().frame().tangent_angle;
    sim.servo_mut()
        .apply_tangent_outcome(&TangentOutcome::Failed(TangentError::TooNoisy {
            signal_n: 0.0,
            noise_n: 1.0,
        }));
    assert_eq!(sim.servo().mode(), ServoMode::Track);
    sim.servo_mut().request_tangent_estimate();
    until(&mut sim, ServoMode::AwaitingEstimate, 240_000);
    let plan = sim.servo().params().tangent.reprobe_plan();
    sim.servo_mut()
        .apply_tangent_outcome(&TangentOutcome::Reprobe {
            reason: ReprobeReason::Fold,
            plan,
        });
    assert_eq!(sim.servo().mode(), ServoMode::Probing);
    until(&mut sim, ServoMode::AwaitingEstimate, 240_000);
    assert!(sim.servo().pending_probe().unwrap().reprobe);
    sim.servo_mut()
        .apply_tangent_outcome(&TangentOutcome::Failed(TangentError::Uncertain {
            std_error_deg: 1.0,
            limit_deg: 0.5,
        }));
    assert_eq!(sim.servo().mode(), ServoMode::Resuming);
    assert_eq!(sim.servo().hybrid().frame().tangent_angle, tangent);
    until(&mut sim, ServoMode::Track, 40_000);
    sim.servo_mut().request_tangent_estimate();
    until(&mut sim, ServoMode::AwaitingEstimate, 240_000);
    sim.servo_mut().give_up_estimate();
    assert_eq!(sim.servo().mode(), ServoMode::Resuming);
    let c = sim.servo().counters();
    assert_eq!(
        (c.started, c.reprobes, c.failures, c.estimates),
        (2, 1, 2, 0)
    );
}

/// Force data lost while stopping or probing: the safe state abandons the estimation (counted
/// as aborted) and, once the data is good again, resumes tracking; lost while awaiting the
/// estimate: it keeps waiting (the record is whole) and still takes the answer.
#[test]
fn the_safe_state_from_each_mode() {
    for mode in [ServoMode::Stopping, ServoMode::Probing] {
        let mut sim = tracking();
        sim.servo_mut().request_tangent_estimate();
        until(&mut sim, mode, 40_000);
        sim.run(50);
        sim.set_force_valid(false);
        sim.step();
        assert!(sim.servo().is_safe(), "{mode:?}");
        assert_eq!(sim.servo().mode(), ServoMode::Resuming, "{mode:?}");
        assert!(sim.servo().pending_probe().is_none());
        sim.run(100);
        sim.set_force_valid(true);
        until(&mut sim, ServoMode::Track, 60_000);
        assert!(!sim.servo().is_safe());
        let c = sim.servo().counters();
        assert_eq!((c.aborted, c.safe_entries), (1, 1), "{mode:?}");
        assert_eq!(sim.servo().hybrid().velocity_target(), 0.005);
    }
    let mut sim = tracking();
    sim.servo_mut().request_tangent_estimate();
    until(&mut sim, ServoMode::AwaitingEstimate, 240_000);
    sim.set_force_valid(false);
    sim.run(100);
    assert!(sim.servo().is_safe());
    assert_eq!(sim.servo().mode(), ServoMode::AwaitingEstimate);
    sim.set_force_valid(true);
    sim.run(1000);
    assert!(!sim.servo().is_safe());
    assert_eq!(sim.servo().mode(), ServoMode::AwaitingEstimate);
    let outcome = estimate(sim.servo());
    sim.servo_mut().apply_tangent_outcome(&outcome);
    assert_eq!(sim.servo().mode(), ServoMode::Resuming);
    assert_eq!(sim.servo().counters().aborted, 0);
}
