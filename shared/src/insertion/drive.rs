//! The arm that carries the wrist (docs/insertion-arm.md): the three-joint arm of
//! [`Scara`] with its dynamics, its flange holding the peg through the compliant wrist, and the
//! servo that drives it as the thesis's hybrid controller does (§3.3, fig. 3.4): the insertion
//! controller's position updates (force along the hole's axis, position or force across it and
//! in θ, the selection of §5.4) go through the inverse kinematics to joint PIDs with the
//! inverse dynamics of the commanded motion as feedforward.
//!
//! The arm moves in the hole's frame shifted by `hole_at_m`; its tool point is the peg's tip
//! as the wrist would hold it, its tool angle φ = θ − π/2 (the wrist link points down the peg).
//! The wrist's reaction (force at the flange's compliance centre, a point on the wrist link,
//! and a pure moment) enters the joints as `J_pᵀ f + m (1, 1, 1)`.

pub use super::options::Drive;
use super::plant::Flange;
use super::scara::{Scara, WristParams};
use crate::arm::{ArmParams, Elbow, PidGains, tune_pid_for_bandwidth};
use crate::error::ConfigError;
use crate::math::{Vec2, wrap_angle};
use nalgebra::{Matrix3, Vector3};
use std::f64::consts::FRAC_PI_2;

/// The arm and its servo.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmDriveParams {
    /// Links 1 and 2 (the thesis's arm).
    pub arm: ArmParams,
    /// The wrist link without the peg (which hangs in the compliant wrist): flange, wrist
    /// motor and its rotor.
    pub wrist: WristParams,
    /// The wrist joint's viscous damping (N·m·s/rad).
    pub wrist_damping_nms_per_rad: f64,
    /// The wrist joint's torque limit (N·m).
    pub wrist_torque_limit_nm: f64,
    /// The hole's centre on the face in the arm's frame (m).
    pub hole_at_m: [f64; 2],
    /// The inverse kinematics' branch.
    pub elbow: Elbow,
    /// Closed-loop joint bandwidths (Hz).
    pub joint_bandwidth_hz: [f64; 3],
    /// Damping ratio of the joint PIDs.
    pub damping_ratio: f64,
    /// Their integral corner as a fraction of their natural frequency.
    pub integral_ratio: f64,
    /// The largest acceleration of the commanded motion the servo follows: linear (m/s²) and
    /// angular (rad/s²). A step in the commanded rate (the approach's start, the dither's) is
    /// a ramp at these, not an impulse the torque limits cut off.
    pub max_acceleration: [f64; 2],
    /// The time constant in which the servo's interpolator closes a gap to the command (s).
    pub interpolator_s: f64,
    /// The interpolator's largest speed: linear (m/s) and angular (rad/s).
    pub max_speed: [f64; 2],
}

impl Default for ArmDriveParams {
    /// The thesis's arm reaching 0.55 m, a 30-mm wrist link whose tool point is the peg's tip
    /// (so the wrist joint is the servo wrist's compliance centre) with a 0.3 kg flange and
    /// motor and a direct-drive rotor; joint servos at 10, 20 and 30 Hz.
    fn default() -> Self {
        Self {
            arm: ArmParams::default(),
            wrist: WristParams {
                length_m: 0.03,
                mass_kg: 0.3,
                com_m: 0.01,
                inertia_kg_m2: 2e-3,
            },
            wrist_damping_nms_per_rad: 0.005,
            wrist_torque_limit_nm: 5.0,
            hole_at_m: [0.55, 0.0],
            elbow: Elbow::Positive,
            joint_bandwidth_hz: [10.0, 20.0, 30.0],
            damping_ratio: 0.7,
            integral_ratio: 0.1,
            max_acceleration: [8.0, 50.0],
            interpolator_s: 5e-3,
            max_speed: [0.05, 0.5],
        }
    }
}

/// The drive's whole state ([`ArmDrive::state`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArmDriveState {
    /// Joint angles (rad).
    pub q: [f64; 3],
    /// Joint rates (rad/s).
    pub v: [f64; 3],
    /// The PIDs' integrals (rad·s).
    pub integral: [f64; 3],
    /// The last commanded joint angles (rad).
    pub q_d: [f64; 3],
    /// The last commanded joint rates (rad/s).
    pub v_d: [f64; 3],
    /// The interpolated tool pose the servo follows (hole frame: m, m, rad).
    pub pose_d: [f64; 3],
    /// Its rate (m/s, m/s, rad/s).
    pub rate_d: [f64; 3],
}

/// The arm, its servo and the flange it carries.
#[derive(Debug, Clone)]
pub struct ArmDrive {
    scara: Scara,
    p: ArmDriveParams,
    gains: [PidGains; 3],
    limit: [f64; 3],
    damping: Vector3<f64>,
    /// The flange's compliance centre along the wrist link from the wrist joint (m).
    centre_along_m: f64,
    s: ArmDriveState,
    /// The servo's torques, held over the tick (N·m).
    torque: [f64; 3],
    /// MuJoCo's dynamics of the arm in place of the closed form's (on MuJoCo's peg).
    #[cfg(feature = "mujoco")]
    mujoco: Option<Box<crate::world::MujocoArm>>,
}

/// The joint-space vector of an array.
fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::from(a)
}

impl ArmDrive {
    /// The arm at rest with the tool at `tip_pose` (hole frame: m, m, rad of tilt), its wrist's
    /// compliance centre `compliance_above_tip_m` up the peg.
    pub fn new(
        p: ArmDriveParams,
        tip_pose: [f64; 3],
        compliance_above_tip_m: f64,
    ) -> Result<Self, ConfigError> {
        let scara = Scara::new(p.arm, p.wrist);
        let q = scara
            .inverse(Self::arm_pose(&p, tip_pose), p.elbow)
            .map_err(|e| {
                ConfigError::rule(
                    "insertion.drive",
                    format!("is `arm`, and the arm cannot reach the peg's start: {e}"),
                )
            })?;
        let m = scara.mass_matrix(q);
        let gains = [0, 1, 2].map(|j| {
            tune_pid_for_bandwidth(
                m[(j, j)],
                p.joint_bandwidth_hz[j],
                p.damping_ratio,
                p.integral_ratio,
            )
        });
        let [l1, l2] = p.arm.torque_limit_nm;
        let [b1, b2] = p.arm.joint_damping_nms_per_rad;
        let q = q.into();
        Ok(Self {
            scara,
            p,
            gains,
            limit: [l1, l2, p.wrist_torque_limit_nm],
            damping: Vector3::new(b1, b2, p.wrist_damping_nms_per_rad),
            centre_along_m: p.wrist.length_m - compliance_above_tip_m,
            s: ArmDriveState {
                q,
                q_d: q,
                pose_d: tip_pose,
                ..ArmDriveState::default()
            },
            torque: [0.0; 3],
            #[cfg(feature = "mujoco")]
            mujoco: None,
        })
    }

    /// The drive in a world whose MuJoCo steps are `mujoco_step_s` seconds long (None: the
    /// built-in plant, which keeps the closed form). On MuJoCo, MuJoCo's dynamics of the arm
    /// move it ([`MujocoArm`]), and every [`Flange::react`] must be one such step.
    ///
    /// [`MujocoArm`]: crate::world::MujocoArm
    pub fn in_world(self, mujoco_step_s: Option<f64>) -> Result<Self, ConfigError> {
        #[cfg(feature = "mujoco")]
        if let Some(step_s) = mujoco_step_s {
            let b = self.damping;
            let mut arm = crate::world::MujocoArm::new(
                &self.p.arm,
                &self.p.wrist,
                [b[0], b[1], b[2]],
                step_s,
            )?;
            arm.set(self.s.q, self.s.v);
            return Ok(Self {
                mujoco: Some(Box::new(arm)),
                ..self
            });
        }
        // Without MuJoCo no world has MuJoCo steps.
        #[cfg(not(feature = "mujoco"))]
        let _ = mujoco_step_s;
        Ok(self)
    }

    /// Whether MuJoCo moves the arm.
    #[cfg(feature = "mujoco")]
    pub fn on_mujoco(&self) -> bool {
        self.mujoco.is_some()
    }

    /// The tool pose in the arm's frame (x, y, φ) for a tip pose in the hole's.
    fn arm_pose(p: &ArmDriveParams, tip: [f64; 3]) -> Vector3<f64> {
        Vector3::new(
            tip[0] + p.hole_at_m[0],
            tip[1] + p.hole_at_m[1],
            tip[2] - FRAC_PI_2,
        )
    }

    /// The whole state.
    pub fn state(&self) -> ArmDriveState {
        self.s
    }

    /// Carries on from `s`, taken from a drive with the same parameters.
    pub fn restore(&mut self, s: &ArmDriveState) {
        self.s = *s;
        #[cfg(feature = "mujoco")]
        if let Some(arm) = &mut self.mujoco {
            arm.set(s.q, s.v);
        }
    }

    /// The servo's tick of `dt`: the joint torques that take the tool to the tip pose
    /// `target` at `rate` (hole frame), held until the next tick. A target out of reach holds
    /// the last commanded joints.
    pub fn servo(&mut self, target: [f64; 3], rate: [f64; 3], dt: f64) {
        self.interpolate(target, rate, dt);
        let s = &mut self.s;
        let q_d = match self
            .scara
            .inverse(Self::arm_pose(&self.p, s.pose_d), self.p.elbow)
        {
            // The wrist angle continuous with the last command's, not wrapped.
            Ok(mut q) => {
                q[2] = s.q_d[2] + wrap_angle(q[2] - s.q_d[2]);
                q
            }
            Err(_) => v3(s.q_d),
        };
        let j = self.scara.jacobian(q_d);
        let v_d = j.lu().solve(&v3(s.rate_d)).unwrap_or_else(Vector3::zeros);
        let a_d = (v_d - v3(s.v_d)) / dt;
        let feedforward = self.scara.mass_matrix(q_d) * a_d
            + self.scara.coriolis(q_d, v_d)
            + self.damping.component_mul(&v_d);
        for k in 0..3 {
            self.torque[k] = self.gains[k].torque(
                (q_d[k] - s.q[k], v_d[k] - s.v[k]),
                (&mut s.integral[k], true),
                feedforward[k],
                self.limit[k],
                dt,
            );
        }
        s.q_d = q_d.into();
        s.v_d = v_d.into();
    }

    /// The servo's interpolator: the tool pose it follows moves towards `target` at `rate`
    /// plus a correction that closes the gap in `interpolator_s`, no faster than a stop at the
    /// largest acceleration allows; its speed and its acceleration are bounded. A step in the
    /// command (the controller's snap of its lead, the dither's start) becomes a ramp the arm
    /// can follow.
    fn interpolate(&mut self, target: [f64; 3], rate: [f64; 3], dt: f64) {
        let s = &mut self.s;
        let [lin, ang] = self.p.max_acceleration;
        let [vmax, wmax] = self.p.max_speed;
        for k in 0..3 {
            let a = if k < 2 { lin } else { ang };
            let gap = target[k] - s.pose_d[k];
            let closing = (gap.abs() / self.p.interpolator_s).min((2.0 * a * gap.abs()).sqrt());
            let v = if k < 2 { vmax } else { wmax };
            let want = (rate[k] + closing.copysign(gap)).clamp(-v, v);
            s.rate_d[k] += (want - s.rate_d[k]).clamp(-a * dt, a * dt);
            s.pose_d[k] += s.rate_d[k] * dt;
        }
    }

    /// The joints' acceleration under the held torques and `external` joint torques.
    fn acceleration(&self, external: Vector3<f64>) -> Vector3<f64> {
        let (q, v) = (v3(self.s.q), v3(self.s.v));
        let m: Matrix3<f64> = self.scara.mass_matrix(q);
        let rhs =
            v3(self.torque) + external - self.scara.coriolis(q, v) - self.damping.component_mul(&v);
        m.cholesky().map_or_else(Vector3::zeros, |c| c.solve(&rhs))
    }
}

impl Flange for ArmDrive {
    fn pose(&self) -> ([f64; 3], [f64; 3]) {
        let (q, v) = (v3(self.s.q), v3(self.s.v));
        let x = self.scara.forward(q);
        let rate = self.scara.jacobian(q) * v;
        let h = self.p.hole_at_m;
        (
            [x[0] - h[0], x[1] - h[1], x[2] + FRAC_PI_2],
            [rate[0], rate[1], rate[2]],
        )
    }

    fn react(&mut self, force: Vec2, moment_nm: f64, h: f64) {
        let jp = self.scara.point_jacobian(v3(self.s.q), self.centre_along_m);
        let external = Vector3::from_fn(|i, _| jp[i].dot(&force) + moment_nm);
        #[cfg(feature = "mujoco")]
        if let Some(arm) = &mut self.mujoco {
            debug_assert!(
                (h - arm.step_s()).abs() <= 1e-9 * h,
                "{h} s vs MuJoCo's step"
            );
            (self.s.q, self.s.v) = arm.step((v3(self.torque) + external).into());
            return;
        }
        let acc = self.acceleration(external);
        for k in 0..3 {
            self.s.v[k] += acc[k] * h;
            self.s.q[k] += self.s.v[k] * h;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const START: [f64; 3] = [0.001, 0.001, 0.02];

    fn drive() -> ArmDrive {
        ArmDrive::new(ArmDriveParams::default(), START, 0.03).unwrap()
    }

    /// One tick of `dt`: the servo to `target` at `rate`, then the arm under the constant
    /// reaction `(force, moment)` in ten sub-steps.
    fn tick(d: &mut ArmDrive, target: [f64; 3], rate: [f64; 3], load: (Vec2, f64), dt: f64) {
        d.servo(target, rate, dt);
        for _ in 0..10 {
            d.react(load.0, load.1, dt / 10.0);
        }
    }

    /// The flange starts where it was put, and follows the approach and the insertion's dither
    /// (0.1 mm at 20 Hz along the axis on a 2 mm/s descent, a 0.05 rad/s tilt), once the start's
    /// steps in rate have settled, to within 3 µm and 10 µrad: the inverse dynamics carry the
    /// motion, the PIDs only the rest.
    #[test]
    fn the_flange_follows_the_commanded_motion() {
        let mut d = drive();
        let (pose, rate) = d.pose();
        for k in 0..3 {
            assert!(
                (pose[k] - START[k]).abs() < 1e-12 && rate[k] == 0.0,
                "{pose:?}"
            );
        }
        let dt = 1e-4;
        let w = std::f64::consts::TAU * 20.0;
        let (a, v, tilt) = (1e-4, 2e-3, 0.05);
        let (mut worst, mut worst_angle) = (0.0f64, 0.0f64);
        let at = |t: f64| {
            let target = [
                START[0],
                START[1] - v * t + a * (w * t).sin(),
                START[2] + tilt * t,
            ];
            (target, [0.0, -v + a * w * (w * t).cos(), tilt])
        };
        for n in 0..20_000 {
            let t = f64::from(n) * dt;
            let (target, rate) = at(t);
            tick(&mut d, target, rate, (Vec2::zeros(), 0.0), dt);
            // The flange a tick on, against the command a tick on.
            let ((pose, _), (then, _)) = (d.pose(), at(t + dt));
            if t > 0.5 {
                worst = worst.max((pose[0] - then[0]).hypot(pose[1] - then[1]));
                worst_angle = worst_angle.max((pose[2] - then[2]).abs());
            }
        }
        eprintln!("{worst} m, {worst_angle} rad");
        assert!(
            worst < 3e-6 && worst_angle < 1e-5,
            "{worst} m, {worst_angle} rad"
        );
    }

    /// Statics: under a constant reaction the integrators bring the flange back to its
    /// commanded pose, and the joint torques then balance the load exactly, τ = −(J_pᵀ f + m 1)
    /// with J_p the Jacobian of the flange's compliance centre.
    #[test]
    fn the_servo_holds_a_load_where_it_was_commanded() {
        let mut d = drive();
        let load = (Vec2::new(1.0, -5.0), 0.02);
        for _ in 0..100_000 {
            tick(&mut d, START, [0.0; 3], load, 1e-4);
        }
        let (pose, _) = d.pose();
        for k in 0..3 {
            assert!((pose[k] - START[k]).abs() < 1e-7, "{pose:?}");
        }
        let jp = d.scara.point_jacobian(v3(d.s.q), d.centre_along_m);
        for (k, (column, tau)) in jp.iter().zip(d.torque).enumerate() {
            let balance = -(column.dot(&load.0) + load.1);
            assert!(
                (tau - balance).abs() < 1e-4 * balance.abs().max(0.01),
                "{k}: {tau} vs {balance}"
            );
        }
    }

    /// A tool pose the arm cannot reach is refused at the start; in the servo, the arm goes
    /// towards it at the interpolator's speed, stops at the edge of its reach where the inverse
    /// kinematics fail, and holds there, every state finite.
    #[test]
    fn out_of_reach_is_refused_or_held() {
        let far = ArmDriveParams {
            hole_at_m: [2.0, 0.0],
            ..ArmDriveParams::default()
        };
        assert!(ArmDrive::new(far, START, 0.03).is_err());
        let mut d = drive();
        let reach = d.p.arm.link1_length_m + d.p.arm.link2_length_m + d.p.wrist.length_m;
        let mut held = 0;
        for _ in 0..10_000 {
            let before = d.state().q_d;
            tick(
                &mut d,
                [0.5, 0.0, 0.0],
                [0.0; 3],
                (Vec2::zeros(), 0.0),
                1e-3,
            );
            held += usize::from(d.state().q_d == before);
        }
        let s = d.state();
        let all = [s.q, s.v, s.integral, s.q_d, s.v_d, s.pose_d, s.rate_d];
        assert!(all.iter().flatten().all(|x| x.is_finite()), "{s:?}");
        assert!(d.torque.iter().all(|t| t.is_finite()));
        let (pose, _) = d.pose();
        let from_base = (pose[0] + 0.55).hypot(pose[1]);
        assert!(from_base > 0.79 && from_base < reach, "{from_base} m");
        assert!(held > 3000, "held {held} ticks");
    }
}
