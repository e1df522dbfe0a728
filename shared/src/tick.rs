//! One servo tick, in the order the real-time servo board (`processes/boards/servo`) and the
//! lockstep ([`crate::sim::Lockstep`], and through it the stack's reference) share: the
//! scenario's step and the commands (a closure, as each side drives and commands its servo
//! its own way), the controller on the joints and the force, the world. One place for the
//! order; the tare is the controller's ([`ServoCore::set_tare`], [`Wrench::tared`]).

use crate::sensor::Wrench;
use crate::servo::{ServoCore, ServoInput};
use crate::world::World;

/// The force a tick uses: the newest reading as it came from the sensor, tare not taken off,
/// and whether it may be used at all (false: missing, stale or refused; the servo goes to its
/// safe state).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Force {
    /// The reading (sensor frame).
    pub reading: Wrench,
    /// Whether the controller may use it.
    pub valid: bool,
}

/// What a tick did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// It ran: controller and world stepped.
    Ran,
    /// The scenario is done: nothing was stepped.
    Done,
}

/// One servo tick of `dt` (s) on `world`: `before` (the scenario's driver at the world's time
/// and contact point, then the commands; [`Step::Done`] ends the scenario before anything
/// moves), one [`ServoCore::step`] on the joints and `force`, one world step under its
/// torques. Allocates nothing.
pub fn servo_tick(
    world: &mut World,
    servo: &mut ServoCore,
    force: Force,
    dt: f64,
    before: impl FnOnce(&World, &mut ServoCore) -> Step,
) -> Step {
    if before(world, servo) == Step::Done {
        return Step::Done;
    }
    let (q, qd) = world.joints();
    let input = ServoInput {
        q,
        qd,
        wrench: force.reading,
        force_valid: force.valid,
    };
    let tau = servo.step(&input, dt);
    world.step(tau, dt);
    Step::Ran
}
