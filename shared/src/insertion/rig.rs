//! One insertion as a servo runs it (docs/insertion-stack.md): the peg's plant, the
//! insertion controller and the contact-state estimator, stepped a tick at a time from the
//! wrist sensor's tared readings. One piece of code for `afs experiment insertion`, the
//! `insertion` scenario's lockstep reference and the servo board, so the three run the same
//! insertion; its whole state goes into the world snapshot for a restarted servo.

use super::controller::{Controller, ControllerState, Input, Phase};
use super::drive::{ArmDrive, ArmDriveParams, ArmDriveState};
use super::estimate::{Estimator, EstimatorState};
pub use super::options::{Drive, InsertionOptions, PartFrame};
use super::plant::{ContactState, PegPlantState, PegTruth};
use super::world::PegWorld;
use crate::config::WorldConfig;
use crate::error::ConfigError;
use crate::math::turn;
use crate::sensor::Wrench;
use crate::world::MUJOCO_PEG_STATE_LEN;

/// The rig's whole state ([`InsertionRig::state`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RigState {
    /// Time since the start (s).
    pub time_s: f64,
    /// The plant.
    pub plant: PegPlantState,
    /// The controller.
    pub controller: ControllerState,
    /// The estimator's.
    pub estimator: EstimatorState,
    /// The last estimated contact state.
    pub estimated: ContactState,
    /// The tip's height at the last tick (m), for the insertion speed.
    pub prev_tip_y_m: f64,
    /// The largest contact force so far (N).
    pub peak_force_n: f64,
    /// The arm, when it drives the flange (zero otherwise).
    pub arm: ArmDriveState,
    /// MuJoCo's state of its peg (None on the built-in plant).
    pub mujoco: Option<[f64; MUJOCO_PEG_STATE_LEN]>,
}

/// The plant, the controller and the estimator of one insertion.
#[derive(Debug, Clone)]
pub struct InsertionRig {
    plant: PegWorld,
    arm: Option<ArmDrive>,
    ctl: Controller,
    estimator: Estimator,
    estimated: ContactState,
    prev_tip_y_m: f64,
    time_s: f64,
    peak_force_n: f64,
    limit_n: f64,
    initial: (f64, f64),
    robot: RobotFrame,
}

/// The robot's frame in the part's: turned by `angle_rad` about the hole's centre on the
/// face. The controller reads and commands in it; the plant and the truth are in the part's.
#[derive(Debug, Clone, Copy, PartialEq)]
struct RobotFrame {
    angle_rad: f64,
}

impl RobotFrame {
    /// A vector of the part's frame in the robot's.
    fn vector_in(self, v: [f64; 2]) -> [f64; 2] {
        turn(v, -self.angle_rad)
    }

    /// A vector of the robot's frame in the part's.
    fn vector_out(self, v: [f64; 2]) -> [f64; 2] {
        turn(v, self.angle_rad)
    }

    /// A pose (or a pose's rate) of the part's frame in the robot's.
    fn pose_in(self, p: [f64; 3]) -> [f64; 3] {
        let v = self.vector_in([p[0], p[1]]);
        [v[0], v[1], p[2] - self.angle_rad]
    }

    /// A pose of the robot's frame in the part's.
    fn pose_out(self, p: [f64; 3]) -> [f64; 3] {
        let v = self.vector_out([p[0], p[1]]);
        [v[0], v[1], p[2] + self.angle_rad]
    }

    /// A pose's rate of the robot's frame in the part's.
    fn rate_out(self, r: [f64; 3]) -> [f64; 3] {
        let v = self.vector_out([r[0], r[1]]);
        [v[0], v[1], r[2]]
    }
}

impl InsertionRig {
    /// The insertion of `o` at `seed` on the built-in plant: the peg 1 mm above the face,
    /// offset and tilted by the seed's initial errors.
    pub fn new(o: &InsertionOptions, seed: u64) -> Result<Self, ConfigError> {
        Self::on_world(o, seed, &WorldConfig::default(), 1e-4)
    }

    /// The insertion of `o` at `seed` in the world `world` names (the built-in plant or
    /// MuJoCo's), stepped every `dt` seconds.
    pub fn on_world(
        o: &InsertionOptions,
        seed: u64,
        world: &WorldConfig,
        dt: f64,
    ) -> Result<Self, ConfigError> {
        o.validate()?;
        let params = o.peg_params();
        let g = params.geometry;
        let (lateral, angle) = o.initial_errors(seed);
        let start = [lateral, 1e-3, angle];
        // Not knowing the part's orientation, the robot believes its peg square to the part:
        // its frame is the part's turned by the angle error (docs/insertion-frame.md).
        let robot = RobotFrame {
            angle_rad: match o.part_frame {
                PartFrame::Known => 0.0,
                PartFrame::Unknown => angle,
            },
        };
        let chamfer_depth = g.chamfer_m / g.chamfer_angle_deg.to_radians().tan().max(1e-9);
        let ctl_params = o.controller_params();
        let plant = PegWorld::new(params, start, world, dt)?;
        let arm = match o.drive {
            Drive::Ideal => None,
            // On MuJoCo's peg, MuJoCo's arm carries it (docs/insertion-mujoco.md).
            Drive::Arm => Some(
                ArmDrive::new(
                    ArmDriveParams::default(),
                    start,
                    params.compliance_above_tip_m,
                )?
                .in_world(plant.mujoco_step_s(dt))?,
            ),
        };
        Ok(Self {
            plant,
            arm,
            ctl: Controller::new(
                ctl_params,
                o.method,
                params.wrist_stiffness,
                robot.pose_in(start),
                chamfer_depth,
            ),
            // The face's prior is the controller's: 0 with the part's orientation known.
            estimator: Estimator::new(0.0, chamfer_depth, g.peg_width_m, o.mu)
                .with_static_friction(params.static_mu())
                .with_face_turned_up_to(ctl_params.face.prior_error_deg.to_radians()),
            estimated: ContactState::Free,
            prev_tip_y_m: start[1],
            time_s: 0.0,
            peak_force_n: 0.0,
            limit_n: o.force_limit_n(),
            initial: (lateral, angle),
            robot,
        })
    }

    /// One tick of `dt`: with a tared reading of the wrist's force/torque sensor (force on the
    /// peg, moment about the tip), the estimator and the controller step and the wrist follows
    /// the controller's pose; without one (no valid force data: the servo's safe state) the
    /// controller stands still and the wrist holds its pose.
    pub fn step(&mut self, reading: Option<Wrench>, dt: f64) {
        let (target, rate) = self.control(reading, dt);
        self.advance(target, rate, dt);
    }

    /// The servo's part of a tick: the estimator and the controller on `reading`; the wrist's
    /// commanded pose and rate; with the arm, its joint servos' torques for them.
    pub fn control(&mut self, reading: Option<Wrench>, dt: f64) -> ([f64; 3], [f64; 3]) {
        let (target, rate) = self.command(reading, dt);
        if let Some(arm) = &mut self.arm {
            arm.servo(target, rate, dt);
        }
        (target, rate)
    }

    /// The estimator and the controller on `reading`.
    fn command(&mut self, reading: Option<Wrench>, dt: f64) -> ([f64; 3], [f64; 3]) {
        let tip = self.plant.truth().pose;
        let speed = (tip[1] - self.prev_tip_y_m) / -dt;
        self.prev_tip_y_m = tip[1];
        match reading {
            Some(w) => {
                let inp = Input {
                    force: self.robot.vector_in([w.force.x, w.force.y]),
                    moment_nm: w.torque,
                    tip: self.robot.pose_in(tip),
                };
                // The estimator knows what the controller knows: the part's frame as the
                // face's tangent estimate gives it.
                let part = self.ctl.to_part(&inp);
                self.estimated = self
                    .estimator
                    .update(&part, self.ctl.face_angle(), speed, dt);
                let (target, rate) = self.ctl.step(&inp, dt);
                (self.robot.pose_out(target), self.robot.rate_out(rate))
            }
            None => (self.target(), [0.0; 3]),
        }
    }

    /// The world's part of a tick: the peg under the wrist commanded to `target` at `rate`,
    /// or, with the arm, under the wrist the arm carries with its servos' torques.
    pub fn advance(&mut self, target: [f64; 3], rate: [f64; 3], dt: f64) {
        match &mut self.arm {
            Some(arm) => self.plant.step_with(arm, dt),
            None => self.plant.step(target, rate, dt),
        }
        self.time_s += dt;
        self.peak_force_n = self.peak_force_n.max(self.plant.truth().force.norm());
    }

    /// The peg's world.
    pub fn world(&self) -> &PegWorld {
        &self.plant
    }

    /// The truth of the last step.
    pub fn truth(&self) -> &PegTruth {
        self.plant.truth()
    }

    /// What the wrist's force/torque sensor feels: the contact force on the peg and its moment
    /// about the tip.
    pub fn sensor_wrench(&self) -> Wrench {
        let t = self.plant.truth();
        Wrench {
            force: t.force,
            torque: t.moment_about_tip,
        }
    }

    /// The controller's phase.
    pub fn phase(&self) -> Phase {
        self.ctl.phase()
    }

    /// The estimated contact state of the last tick with force data.
    pub fn estimated(&self) -> ContactState {
        self.estimated
    }

    /// The commanded pose without the dither.
    pub fn target(&self) -> [f64; 3] {
        self.robot.pose_out(self.ctl.target())
    }

    /// Time since the start (s).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// At depth, or stopped by the force limit.
    pub fn finished(&self) -> bool {
        self.phase() == Phase::Done || self.failed()
    }

    /// Stopped by the force limit: a contact force above it has been seen.
    pub fn failed(&self) -> bool {
        self.peak_force_n > self.limit_n
    }

    /// The seed's initial lateral (m) and angle (rad) errors.
    pub fn initial_errors(&self) -> (f64, f64) {
        self.initial
    }

    /// The error of the face's tangent as the controller estimates it (rad): 0 when the
    /// estimate has found the part's orientation.
    pub fn face_error_rad(&self) -> f64 {
        self.ctl.face_angle() + self.robot.angle_rad
    }

    /// The whole state, for a restarted servo.
    pub fn state(&self) -> RigState {
        RigState {
            time_s: self.time_s,
            plant: self.plant.state(),
            controller: self.ctl.state(),
            estimator: self.estimator.state(),
            estimated: self.estimated,
            prev_tip_y_m: self.prev_tip_y_m,
            peak_force_n: self.peak_force_n,
            arm: self.arm.as_ref().map(ArmDrive::state).unwrap_or_default(),
            mujoco: self.plant.mujoco_state(),
        }
    }

    /// Carries on from `s`, taken from a rig built with the same options, seed and world. A
    /// state of the other world is refused, and nothing is changed.
    pub fn restore(&mut self, s: &RigState) -> Result<(), ConfigError> {
        self.plant.restore(&s.plant, s.mujoco.as_ref())?;
        self.time_s = s.time_s;
        self.ctl.restore(&s.controller);
        self.estimator.restore(&s.estimator);
        self.estimated = s.estimated;
        self.prev_tip_y_m = s.prev_tip_y_m;
        self.peak_force_n = s.peak_force_n;
        if let Some(arm) = &mut self.arm {
            arm.restore(&s.arm);
        }
        Ok(())
    }
}

#[cfg(test)]
#[path = "rig_tests.rs"]
mod tests;
