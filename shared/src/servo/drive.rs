//! What the servo's Cartesian set-point drives: the thesis's two-link arm through its joint
//! servos, or a tool through its planar force (an arm under task-space torque control, such as
//! the FR3 through [`crate::task_plane`]; issue 48, docs/franka.md, *The servo on a task-space
//! arm*).
//!
//! The servo's hybrid controller, dither, tuner and tracker see only the tool: its position,
//! velocity and the contact force in the plane. The drive turns the set-point into the arm's
//! command and reads the tool back.

use crate::arm::{Arm, Elbow, JointServo};
use crate::hybrid::HybridCommand;
use crate::math::Vec2;
use crate::sensor::Wrench;
use crate::task_plane::PlanarGains;
use nalgebra::{Matrix2, Vector2, Vector3};

/// The thesis's two-link arm: the set-point's inverse kinematics, tracked by PID joint servos.
#[derive(Debug, Clone)]
pub(super) struct TwoLink {
    pub(super) arm: Arm,
    pub(super) elbow: Elbow,
    pub(super) pid: JointServo,
    /// The last reachable joint set-point (rad).
    pub(super) last_q_d: Vector2<f64>,
}

/// A tool driven by the force the arm applies to it in the plane: for an arm whose torques are
/// `Jᵀ W` (the FR3 through [`crate::task_plane`]), the set-point's impedance
///
/// `f = Λ a_d + K (p_d − p) + D (v_d − v) + f_ff`,   `m_θ = K_θ (θ_d − θ) − D_θ θ̇`,
///
/// with Λ the tool's inertia along the plane's x and y ([`crate::task_plane::TaskPlane::planar_inertia`]),
/// K and D the planar gains ([`crate::task_plane::planar_gains`]) and `f_ff` the preload's
/// feedforward and the contact mode's damping, the same forces the two-link arm maps through
/// `Jᵀ`. θ is held where it started.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskDrive {
    /// The tool's inertia along x and y (kg) and about the normal (kg·m²).
    pub inertia: Vector3<f64>,
    /// Stiffness and damping of the three planar axes.
    pub gains: PlanarGains,
    /// The angle θ held (rad).
    pub theta_rad: f64,
}

/// One tick's inputs to a servo on a [`TaskDrive`]: the tool's planar state and the latest
/// force sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TaskInput {
    /// x and y in the plane (m).
    pub position_m: Vec2,
    /// ẋ and ẏ (m/s).
    pub velocity_m_per_s: Vec2,
    /// The tool's angle about the plane's normal (rad); the sensor's x axis is the tool's.
    pub theta_rad: f64,
    /// θ̇ (rad/s).
    pub theta_rate_rad_per_s: f64,
    /// Latest wrench in the sensor frame.
    pub wrench: Wrench,
    /// False when the force data must not be used (stale, missing or insane).
    pub force_valid: bool,
}

/// What a servo on a [`TaskDrive`] commands: the force and the moment the arm applies to the
/// tool in the plane.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TaskCommand {
    /// f_x, f_y (N).
    pub force_n: Vec2,
    /// m_θ, about the plane's normal (N·m).
    pub moment_nm: f64,
}

/// The servo's drive.
#[derive(Debug, Clone)]
pub(super) enum Drive {
    TwoLink(TwoLink),
    Task(TaskDrive),
}

/// The forces along the normal that both drives add to the set-point's: the preload's
/// feedforward `n̂ F_d` and the contact mode's damping `n̂ c e`, each to be subtracted (they
/// press the tool into the surface).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct NormalForces {
    pub(super) preload: Option<Vec2>,
    pub(super) damping: Option<Vec2>,
}

/// `1/(nᵀ G⁻¹ n)`: what a diagonal Cartesian gain G (x, y) amounts to along `n`.
fn along_diagonal(g: Vector2<f64>, n: Vec2) -> f64 {
    1.0 / (n.x * n.x / g.x + n.y * n.y / g.y)
}

impl TaskDrive {
    /// The contact mode's arm side along `normal`: the tool's effective mass (kg), the drive's
    /// damping (N·s/m) and stiffness (N/m).
    pub(super) fn along(&self, normal: Vec2) -> [f64; 3] {
        let xy = |v: Vector3<f64>| Vector2::new(v.x, v.y);
        [
            along_diagonal(xy(self.inertia), normal),
            along_diagonal(xy(self.gains.damping), normal),
            along_diagonal(xy(self.gains.stiffness), normal),
        ]
    }

    /// Checks the inertias and the gains: every entry finite and positive.
    pub(super) fn is_valid(&self) -> bool {
        let positive = |v: &Vector3<f64>| v.iter().all(|x| x.is_finite() && *x > 0.0);
        positive(&self.inertia)
            && positive(&self.gains.stiffness)
            && positive(&self.gains.damping)
            && self.theta_rad.is_finite()
    }

    /// The impedance's command for the set-point `cmd` at the tool's state `inp`.
    pub(super) fn command(
        &self,
        cmd: &HybridCommand,
        inp: &TaskInput,
        normal: &NormalForces,
        inertia_feedforward: bool,
    ) -> TaskCommand {
        let k = self.gains.stiffness;
        let d = self.gains.damping;
        let e = cmd.position - inp.position_m;
        let ev = cmd.velocity - inp.velocity_m_per_s;
        let mut f = Vec2::new(k.x * e.x + d.x * ev.x, k.y * e.y + d.y * ev.y);
        if inertia_feedforward {
            f += Vec2::new(
                self.inertia.x * cmd.acceleration.x,
                self.inertia.y * cmd.acceleration.y,
            );
        }
        if let Some(p) = normal.preload {
            f -= p;
        }
        if let Some(c) = normal.damping {
            f -= c;
        }
        let theta_error = crate::math::wrap_angle(self.theta_rad - inp.theta_rad);
        TaskCommand {
            force_n: f,
            moment_nm: k.z * theta_error - d.z * inp.theta_rate_rad_per_s,
        }
    }
}

impl TwoLink {
    /// The joint torques for the set-point `cmd`, the arm at `q` with rates `qd` and the
    /// Jacobian `j` there (which carries the normal forces); also whether the set-point was out
    /// of reach (the last reachable one held).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn torque(
        &mut self,
        cmd: &HybridCommand,
        q: Vector2<f64>,
        qd: Vector2<f64>,
        j: &Matrix2<f64>,
        normal: &NormalForces,
        inertia_feedforward: bool,
        dt: f64,
    ) -> (Vector2<f64>, bool) {
        let mut held = false;
        let (q_d, pose_d) = match self.arm.inverse_pose(cmd.position, self.elbow) {
            Ok(x) => x,
            Err(_) => {
                held = true;
                (self.last_q_d, self.arm.pose(self.last_q_d))
            }
        };
        let jinv = if held {
            None
        } else {
            self.arm.jacobian_at(&pose_d).try_inverse()
        };
        let (qd_d, qdd_d) = match jinv {
            Some(ji) => {
                let qd_d = ji * cmd.velocity;
                let qdd_d =
                    ji * (cmd.acceleration - self.arm.jacobian_dot_at(&pose_d, qd_d) * qd_d);
                (qd_d, qdd_d)
            }
            None => (Vector2::zeros(), Vector2::zeros()),
        };
        self.last_q_d = q_d;
        let mut feedforward = if inertia_feedforward {
            self.arm.inverse_dynamics_at(&pose_d, qd_d, qdd_d)
        } else {
            Vector2::zeros()
        };
        if let Some(p) = normal.preload {
            feedforward -= j.transpose() * p;
        }
        if let Some(c) = normal.damping {
            feedforward -= j.transpose() * c;
        }
        (self.pid.torque(q_d, qd_d, q, qd, feedforward, dt), held)
    }
}

/// Sensor-frame force into the plane, for a sensor whose x axis is at the angle with sine
/// `s` and cosine `c`.
pub fn to_plane(s: f64, c: f64, w: Wrench) -> Vec2 {
    Vec2::new(c * w.force.x - s * w.force.y, s * w.force.x + c * w.force.y)
}

/// Whether a sample's force may be used: flagged valid and every number finite.
pub(super) fn force_is_valid(valid: bool, w: &Wrench) -> bool {
    valid && w.force.x.is_finite() && w.force.y.is_finite() && w.torque.is_finite()
}
