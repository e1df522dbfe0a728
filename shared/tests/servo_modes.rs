//! `ServoCore`'s mode machine, transition by transition: track → stop → probe → await the
//! estimate → resume → track, with each estimator answer (estimate, re-probe, failure, none),
//! and the safe state entered from each mode. Driven through the lockstep (plant and sensor in
//! the loop), with the estimator's answers given by hand.

use afs_shared::config::SimConfig;
use afs_shared::servo::{ServoCore, ServoMode, Trigger};
use afs_shared::sim::Lockstep;
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
        &req.params,
        req.reprobe,
    )
}

/// On a contact a tenth of the design stiffness (1 kN/m), an estimate asked for is re-probed
/// with a longer stroke about the corrected tangent and answers within 0.05°; a re-estimate the
/// tracker started itself (here a slope trigger, as a restored state says) is sent without the
/// soft-contact re-probe.
#[test]
fn a_soft_contact_is_reprobed_when_the_estimate_was_asked_for() {
    let mut cfg = SimConfig {
        tangent_error_rad: 3f64.to_radians(),
        ..SimConfig::default()
    };
    cfg.plant.contact.interaction_stiffness_n_per_m = 1e3;
    let mut sim = Lockstep::new(&cfg).unwrap();
    sim.set_auto_estimate(false);
    // The friction-suppression dither at 50 mm/s, as `afs experiment tangent` runs it.
    sim.servo_mut().set_a_omega(0.05);
    sim.run(3000);
    sim.servo_mut().request_tangent_estimate();
    until(&mut sim, ServoMode::AwaitingEstimate, 240_000);
    let configured = sim.servo().params().tangent;
    assert_eq!(sim.servo().pending_probe().unwrap().params, configured);
    let outcome = estimate(sim.servo());
    let TangentOutcome::Reprobe {
        reason: ReprobeReason::SoftContact,
        plan,
    } = outcome
    else {
        panic!("{outcome:?}")
    };
    assert!(plan.amplitude_m >= 1.5 * configured.amplitude_m, "{plan:?}");
    sim.servo_mut().apply_tangent_outcome(&outcome);
    until(&mut sim, ServoMode::AwaitingEstimate, 240_000);
    let TangentOutcome::Estimate(e) = estimate(sim.servo()) else {
        panic!("no estimate after the soft re-probe")
    };
    let truth = sim.truth().tangent_angle_rad;
    let error = (e.tangent_angle_rad - truth).to_degrees();
    eprintln!(
        "soft re-probe: stroke {:.2} mm, k_e read {:.0} N/m, error {error:.4}°",
        plan.amplitude_m * 1e3,
        e.stiffness_n_per_m
    );
    assert!(error.abs() < 0.05, "{error}° off");
    // The same servo, as if its last estimation had been a slope trigger's.
    let mut state = sim.servo().state();
    state.last_trigger = u32::from(Trigger::Slope);
    sim.servo_mut().restore(&state).unwrap();
    let p = sim.servo().estimation_params();
    assert_eq!(p.design_stiffness_n_per_m, 0.0);
    assert_eq!(
        afs_shared::tangent::TangentParams {
            design_stiffness_n_per_m: configured.design_stiffness_n_per_m,
            ..p
        },
        configured
    );
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

/// `ticks` fast-loop ticks with the tool off the surface (a zero wrench after the tare), the
/// arm where the lockstep left it.
fn lift_off(sim: &mut Lockstep, ticks: usize) {
    let dt = sim.dt();
    let (q, qd) = (sim.truth().q, sim.truth().qd);
    for _ in 0..ticks {
        let inp = afs_shared::servo::ServoInput {
            q,
            qd,
            wrench: sim.servo().tare(),
            force_valid: true,
        };
        sim.servo_mut().step(&inp, dt);
    }
}

/// The contact guard: a probe run that loses the contact (normal force below a fifth of the
/// preload for 5 ms) while tracking on its own is abandoned, and tracking goes on at once at
/// the old speed with the triggers disarmed for `contact_lost_travel_m`; a shorter loss does
/// not; with automatic tracking off (an estimate on request only) the guard stays out.
#[test]
fn a_probe_that_loses_the_contact_is_abandoned_while_tracking() {
    for enabled in [true, false] {
        let cfg = SimConfig {
            tangent_error_rad: 3f64.to_radians(),
            ..SimConfig::default()
        };
        let mut cfg = cfg;
        cfg.servo.tracking.enabled = enabled;
        let mut sim = Lockstep::new(&cfg).unwrap();
        sim.set_auto_estimate(false);
        sim.servo_mut().hybrid_mut().set_velocity(0.005);
        sim.run(3000);
        sim.servo_mut().request_tangent_estimate();
        until(&mut sim, ServoMode::Probing, 40_000);
        sim.run(100);
        lift_off(&mut sim, 45);
        assert_eq!(
            sim.servo().mode(),
            ServoMode::Probing,
            "4.5 ms is not a loss"
        );
        sim.run(10);
        lift_off(&mut sim, 45);
        assert_eq!(sim.servo().mode(), ServoMode::Probing, "the count restarts");
        lift_off(&mut sim, 10);
        let c = sim.servo().counters();
        if enabled {
            assert_eq!(sim.servo().mode(), ServoMode::Track);
            assert_eq!(c.contact_losses, 1);
            assert_eq!(sim.servo().hybrid().velocity_target(), 0.005);
            assert!(sim.servo().pending_probe().is_none());
            let t = cfg.servo.tracking;
            // Owed: the travel to `contact_lost_travel_m` (the feed has moved a few µm since).
            let owed = sim.servo().state().track.odometer_m - t.min_travel_m;
            assert!(
                (owed + t.contact_lost_travel_m).abs() < 1e-5,
                "{owed} m owed"
            );
        } else {
            assert_eq!(sim.servo().mode(), ServoMode::Probing);
            assert_eq!(c.contact_losses, 0);
        }
    }
}

/// Confirming a corner: an accepted estimate that turns the tangent by more than
/// `corner_angle_deg` makes the tracker estimate once more after `corner_confirm_m` of travel
/// (trigger `travel`), and only once; with `corner_confirm_m` = 0 it does not.
#[test]
fn an_estimate_that_turns_a_corner_is_confirmed_once() {
    for confirm in [0.003, 0.0] {
        let mut cfg = SimConfig {
            tangent_error_rad: 8f64.to_radians(),
            ..SimConfig::default()
        };
        cfg.servo.tracking.enabled = true;
        cfg.servo.tracking.corner_confirm_m = confirm;
        let mut sim = Lockstep::new(&cfg).unwrap();
        sim.set_auto_estimate(false);
        sim.servo_mut().hybrid_mut().set_velocity(0.005);
        sim.run(3000);
        // First answer: the tangent as it is (no turn); second: the estimator's, 8° on.
        let base = sim.servo().hybrid().frame().tangent_angle;
        for turn in [false, true] {
            sim.servo_mut().request_tangent_estimate();
            until(&mut sim, ServoMode::AwaitingEstimate, 240_000);
            let outcome = match estimate(sim.servo()) {
                TangentOutcome::Estimate(mut e) if !turn => {
                    e.tangent_angle_rad = base;
                    TangentOutcome::Estimate(e)
                }
                o => o,
            };
            assert!(
                matches!(outcome, TangentOutcome::Estimate(_)),
                "{outcome:?}"
            );
            sim.servo_mut().apply_tangent_outcome(&outcome);
            until(&mut sim, ServoMode::Track, 40_000);
        }
        let flags = sim.servo().state().flags;
        let confirming = flags.contains(afs_shared::servo::ServoStateFlags::CONFIRM_CORNER);
        assert_eq!(confirming, confirm > 0.0);
        // 6 mm at 5 mm/s: one travel-triggered estimation, at 3 mm, if confirming; none
        // otherwise, nor after the confirmation.
        let before = sim.servo().counters().started;
        for _ in 0..12_000 {
            sim.step();
            if sim.servo().mode() == ServoMode::Stopping {
                let t = sim.servo().state().track.odometer_m;
                assert!((t - confirm).abs() < 5e-4, "confirmed at {t} m");
                assert_eq!(sim.servo().last_trigger(), Some(Trigger::Travel));
                until(&mut sim, ServoMode::AwaitingEstimate, 240_000);
                let outcome = estimate(sim.servo());
                sim.servo_mut().apply_tangent_outcome(&outcome);
                until(&mut sim, ServoMode::Track, 40_000);
            }
        }
        let c = sim.servo().counters();
        assert_eq!(c.started - before, u32::from(confirm > 0.0), "{c:?}");
        assert_eq!(c.slope_triggers + c.force_triggers, 0, "{c:?}");
    }
}
