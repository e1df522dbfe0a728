//! MuJoCo as the world (docs/mujoco.md): the experiments that track a surface and suppress
//! friction hold on it and on the built-in plant at the thesis's 10 kHz and at a real robot's
//! 1 kHz and 500 Hz; the stack runs on MuJoCo against its MuJoCo lockstep, and a killed servo
//! resumes MuJoCo's full state so the agreement holds across the kill.
#![cfg(feature = "mujoco")]

use afs_shared::check::{self, Check};
use afs_shared::experiments::{self, Options};
use afs_shared::setups::{ROBOT_RATES_HZ, set_rate};
use afs_shared::sim::SimConfig;
use afs_shared::world::WorldKind;
use std::time::Duration;

mod common;
use common::*;

fn options(kind: WorldKind, rate_hz: f64) -> Options {
    let mut base = SimConfig::default();
    base.world.kind = kind;
    set_rate(&mut base, rate_hz).unwrap();
    Options {
        base,
        ..Default::default()
    }
}

fn passed(checks: &[Check], id: &str, what: &str) {
    let c = check::find(checks, id).unwrap_or_else(|| panic!("{what}: no check {id}"));
    assert!(c.pass, "{what}: {}", c.line());
}

/// fig. 5.6 (an unknown sinusoid tracked with the tangent estimator) passes every check, and
/// fig. 4.5's dither keeps the mean friction under 20 % of the undithered one, on both worlds
/// at 10 kHz, 1 kHz and 500 Hz. (fig. 4.5's comparison with eq. 4.5's cycle average is the
/// built-in law's; MuJoCo's differs, docs/mujoco.md.)
#[test]
fn tracking_and_suppression_hold_on_both_worlds_at_every_rate() {
    for kind in [WorldKind::Builtin, WorldKind::Mujoco] {
        for rate in ROBOT_RATES_HZ {
            let what = format!("{} at {rate} Hz", kind.name());
            let opts = options(kind, rate);
            let tracked = experiments::fig5_6(&opts).unwrap();
            for c in &tracked.checks {
                assert!(c.pass, "fig5.6 {what}: {}", c.line());
            }
            let suppressed = experiments::fig4_5(&opts).unwrap();
            passed(
                &suppressed.checks,
                "dithered_over_undithered_friction",
                &format!("fig4.5 {what}"),
            );
        }
    }
}

/// The MuJoCo world's contact is the set-up's: a friction coefficient from trials within 3 %
/// of MuJoCo's μ (fig. 4.6), whatever the rate.
#[test]
fn friction_coefficient_from_trials_on_mujoco() {
    for rate in [10_000.0, 500.0] {
        let out = experiments::fig4_6(&options(WorldKind::Mujoco, rate)).unwrap();
        for c in &out.checks {
            assert!(c.pass, "fig4.6 mujoco at {rate} Hz: {}", c.line());
        }
    }
}

/// `afs run --config examples/stack-mujoco.toml`: the servo steps MuJoCo, the supervisor's
/// reference runs the same MuJoCo model in lockstep; the servo is killed mid-run and its
/// successor resumes MuJoCo's state (warm start included), so every tick arrives once and
/// the agreement check holds.
#[test]
fn the_stack_runs_on_mujoco_and_a_killed_servo_resumes_it() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("mj");
    let _clean = CleanPrefix(p.clone());
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/stack-mujoco.toml");
    let run = start_run(&p, &["--config", config, "--duration", "8"]);
    wait_running(&p, Duration::from_secs(60));
    std::thread::sleep(Duration::from_secs(2));
    kill_board_and_wait_restart(&p, "servo");
    let r = finish_passed(run.take(), "afs run");
    assert_eq!(process(&r, "servo").restarts, 1);
    assert_eq!(r.samples.plant_received, 80_001, "{:?}", r.samples);
    assert_eq!(r.samples.plant_lost, 0);
    assert!(check(&r, "lockstep_agreement").pass, "{:#?}", r.agreement);
    assert!(check(&r, "ticks_without_contact").pass);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}
