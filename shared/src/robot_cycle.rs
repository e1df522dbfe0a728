//! One control cycle of the servo on a seven-joint arm (issue 48, docs/franka.md, *One cycle
//! on the arm*): the arm's state and model in, the joint torques to send out.
//!
//! 1. The tool's planar state from its pose, the Jacobian and the joint rates
//!    ([`TaskPlane::planar`]).
//! 2. The guard ([`Guard::check`]): the workspace box, the contact force's limit, values that
//!    are not numbers. Tripped, the planar axes hold the guard's pose by the drive's own
//!    impedance (`f = K (p_h − p) − D v`, `m_θ = K_θ (θ_h − θ) − D_θ θ̇`) and the normal
//!    offset is held at the hold pose's; the servo is not stepped.
//! 3. Otherwise the thesis's controller, [`ServoCore::step_task`].
//! 4. The wrench in the base frame with the hold of the normal and the tilts
//!    ([`TaskPlane::wrench`]), the joint torques `Jᵀ W + N τ₀ + c` ([`joint_torques`]), and
//!    the arm's limits on the torque and its rate against the command the robot last received
//!    ([`limit_torques`]).
//!
//! Nothing here allocates; the model (pose, Jacobian, mass matrix, Coriolis vector) is the
//! caller's, evaluated at the state the robot sent.

use crate::robot_guard::{Guard, HoldPose, Trip};
use crate::sensor::Wrench;
use crate::servo::{ServoCore, TaskInput};
use crate::task_plane::{
    Hold, Jacobian, Joints, Limited, MassMatrix, PlanarGains, PlanarState, TaskPlane, TorqueLimits,
    joint_torques, limit_torques,
};
use nalgebra::{Matrix3, Vector2, Vector3};

/// The arm as the robot reports it in one cycle, with its model at that state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmState {
    /// Joint positions (rad).
    pub q: Joints,
    /// Joint rates (rad/s).
    pub dq: Joints,
    /// The torque the robot received last cycle (N·m; FCI's `tau_J_d`).
    pub last_command_nm: Joints,
    /// The tool's orientation in the base frame.
    pub tool_rotation: Matrix3<f64>,
    /// The tool's position in the base frame (m).
    pub tool_position_m: Vector3<f64>,
    /// The zero Jacobian at the tool.
    pub jacobian: Jacobian,
    /// The joint-space mass matrix.
    pub mass: MassMatrix,
    /// The Coriolis and centrifugal torque (N·m).
    pub coriolis: Joints,
}

/// What the cycle holds and limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmCycleParams {
    /// The hold of the normal offset, the tilts and the null space.
    pub hold: Hold,
    /// The null space's posture (rad).
    pub posture: Joints,
    /// The arm's torque and torque-rate limits.
    pub limits: TorqueLimits,
    /// The normal offset the hold keeps while the servo runs (m).
    pub normal_target_m: f64,
    /// The planar impedance that holds the guard's pose once it trips.
    pub guard_gains: PlanarGains,
}

/// What one cycle gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleOutput {
    /// The torque to send, and which joints the limits cut.
    pub torque: Limited,
    /// The tool's planar state this cycle.
    pub planar: PlanarState,
    /// The guard's trip and hold pose, if it has tripped (now or before).
    pub tripped: Option<(Trip, HoldPose)>,
    /// False when the arm is at a singularity (no null-space term this cycle).
    pub null_space: bool,
}

/// The cycle: the task plane, what it holds and limits, and the guard.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmCycle {
    plane: TaskPlane,
    params: ArmCycleParams,
    guard: Guard,
}

impl ArmCycle {
    /// A cycle in `plane` with `params`, guarded by `guard`.
    #[must_use]
    pub fn new(plane: TaskPlane, params: ArmCycleParams, guard: Guard) -> Self {
        Self {
            plane,
            params,
            guard,
        }
    }

    /// The guard (its trip, and its release).
    pub fn guard_mut(&mut self) -> &mut Guard {
        &mut self.guard
    }

    /// One cycle of `dt_s` seconds: the servo's command, or the guard's hold, as the torques to
    /// send. `wrench` is the latest sensor sample (sensor frame), used only when
    /// `force_valid`.
    pub fn cycle(
        &mut self,
        servo: &mut ServoCore,
        arm: &ArmState,
        wrench: Wrench,
        force_valid: bool,
        dt_s: f64,
    ) -> CycleOutput {
        let s = self.planar(arm);
        let force = force_valid.then(|| Vector3::new(wrench.force.x, wrench.force.y, 0.0));
        let tripped = self.guard.check(&s, force.as_ref());
        if let Some((_, pose)) = tripped {
            return self.hold_planar(arm, &s, &pose, tripped, dt_s);
        }
        let out = servo.step_task(
            &TaskInput {
                position_m: s.position_m,
                velocity_m_per_s: s.velocity_m_per_s,
                theta_rad: s.theta_rad,
                theta_rate_rad_per_s: s.theta_rate_rad_per_s,
                wrench,
                force_valid,
            },
            dt_s,
        );
        let normal_target = self.params.normal_target_m;
        self.command(
            arm,
            &s,
            out.force_n,
            out.moment_nm,
            normal_target,
            tripped,
            dt_s,
        )
    }

    /// One cycle that holds `pose` by the hold's planar gains, without a servo (a robot
    /// reached before any contact, or held while nothing else runs); the guard still checks
    /// the tool's pose (there is no force), and once it trips its own pose is held instead.
    pub fn hold_at(&mut self, arm: &ArmState, pose: &HoldPose, dt_s: f64) -> CycleOutput {
        let s = self.planar(arm);
        let tripped = self.guard.check(&s, None);
        let pose = tripped.map_or(*pose, |(_, p)| p);
        self.hold_planar(arm, &s, &pose, tripped, dt_s)
    }

    /// The tool's planar state.
    #[must_use]
    pub fn planar(&self, arm: &ArmState) -> PlanarState {
        self.plane.planar(
            &arm.tool_rotation,
            &arm.tool_position_m,
            &arm.jacobian,
            &arm.dq,
        )
    }

    fn hold_planar(
        &self,
        arm: &ArmState,
        s: &PlanarState,
        pose: &HoldPose,
        tripped: Option<(Trip, HoldPose)>,
        dt_s: f64,
    ) -> CycleOutput {
        let (f, m) = self.hold_force(s, pose);
        self.command(arm, s, f, m, pose.normal_m, tripped, dt_s)
    }

    /// The torques for the planar force `f` and moment `m`, the normal held at
    /// `normal_target` (m), limited against the last command.
    #[allow(clippy::too_many_arguments)]
    fn command(
        &self,
        arm: &ArmState,
        s: &PlanarState,
        f: Vector2<f64>,
        m: f64,
        normal_target: f64,
        tripped: Option<(Trip, HoldPose)>,
        dt_s: f64,
    ) -> CycleOutput {
        let p = &self.params;
        let w = self.plane.wrench(s, f, m, normal_target, &p.hold);
        let (tau, null_space) = joint_torques(
            &arm.jacobian,
            &arm.mass,
            &arm.coriolis,
            &arm.q,
            &arm.dq,
            &p.posture,
            &w,
            &p.hold,
        );
        CycleOutput {
            torque: limit_torques(&tau, &arm.last_command_nm, &p.limits, dt_s),
            planar: *s,
            tripped,
            null_space,
        }
    }

    /// The planar impedance toward the hold pose.
    fn hold_force(&self, s: &PlanarState, pose: &HoldPose) -> (Vector2<f64>, f64) {
        let k = self.params.guard_gains.stiffness;
        let d = self.params.guard_gains.damping;
        let e = pose.position_m - s.position_m;
        let f = Vector2::new(
            k.x * e.x - d.x * s.velocity_m_per_s.x,
            k.y * e.y - d.y * s.velocity_m_per_s.y,
        );
        let m = k.z * crate::math::wrap_angle(pose.theta_rad - s.theta_rad)
            - d.z * s.theta_rate_rad_per_s;
        (f, m)
    }
}

#[cfg(test)]
#[path = "robot_cycle_tests.rs"]
mod tests;
