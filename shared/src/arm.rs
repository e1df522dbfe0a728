//! The planar two-link direct-drive arm (thesis §3.1, §4.5.1): forward and inverse kinematics,
//! Jacobian, rigid-body dynamics, and the PID joint servos.
//!
//! Joint angles q = (q1, q2) in rad; q1 from world X to link 1, q2 from link 1 to link 2. The
//! tool tip is at the end of link 2 and the force sensor's x axis (x_e) points along link 2
//! (thesis fig. 3.3). No gravity: the arm moves in a horizontal plane.
//!
//! Dynamics (standard two-link form): `M(q) q̈ + h(q, q̇) + B q̇ = τ + Jᵀ F_tip` with
//! `M11 = I1 + m2' l1² + I2 + 2β cos q2`, `M12 = I2 + β cos q2`, `M22 = I2`,
//! `h = (−β sin q2 (2 q̇1 q̇2 + q̇2²), β sin q2 q̇1²)`, where I2 is link 2's inertia (with
//! tip mass and the joint-2 rotor) about joint 2, I1 link 1's about joint 1 (with rotor 1 and
//! the elbow motor's stator), m2' the mass of link 2 and tip, and β = l1 × (first moment of
//! link 2 and tip about joint 2).

use crate::error::ConfigError;
pub use crate::error::IkError;
use crate::math::Vec2;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};

/// Physical parameters of the arm. SI units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArmParams {
    /// Link 1 length l1 (m).
    pub link1_length_m: f64,
    /// Link 2 length l2, joint 2 to tool tip (m).
    pub link2_length_m: f64,
    /// Link 1 mass (kg).
    pub link1_mass_kg: f64,
    /// Link 1 centre of mass from joint 1 (m).
    pub link1_com_m: f64,
    /// Link 1 inertia about its centre of mass (kg·m²).
    pub link1_inertia_kg_m2: f64,
    /// Joint-1 motor rotor inertia (kg·m²).
    pub rotor1_inertia_kg_m2: f64,
    /// Mass at the elbow (joint-2 motor stator) (kg).
    pub elbow_mass_kg: f64,
    /// Link 2 mass (kg).
    pub link2_mass_kg: f64,
    /// Link 2 centre of mass from joint 2 (m).
    pub link2_com_m: f64,
    /// Link 2 inertia about its centre of mass (kg·m²).
    pub link2_inertia_kg_m2: f64,
    /// Joint-2 rotor inertia; a direct-drive rotor turns with link 2 (kg·m²).
    pub rotor2_inertia_kg_m2: f64,
    /// Point mass at the tip: sensor, flange and tool (kg).
    pub tip_mass_kg: f64,
    /// Viscous joint damping (N·m·s/rad), both joints.
    pub joint_damping_nms_per_rad: [f64; 2],
    /// Joint torque limits (N·m).
    pub torque_limit_nm: [f64; 2],
}

impl Default for ArmParams {
    /// A direct-drive arm whose second link has its centre of percussion at the tool tip, so
    /// that at the default operating point (link 2 perpendicular to the line from the base to
    /// the tip) the tangential and normal directions are decoupled in inertia and in servo
    /// compliance (see `docs/model.md`).
    fn default() -> Self {
        Self {
            link1_length_m: 0.5,
            link2_length_m: 0.3,
            link1_mass_kg: 6.0,
            link1_com_m: 0.25,
            link1_inertia_kg_m2: 6.0 * 0.25 / 12.0,
            rotor1_inertia_kg_m2: 0.3,
            elbow_mass_kg: 5.0,
            link2_mass_kg: 1.5,
            link2_com_m: 0.15,
            link2_inertia_kg_m2: 1.5 * 0.09 / 12.0,
            rotor2_inertia_kg_m2: 0.0225,
            tip_mass_kg: 3.0,
            joint_damping_nms_per_rad: [0.05, 0.01],
            torque_limit_nm: [60.0, 25.0],
        }
    }
}

/// Sines and cosines of one configuration: q1, q2 and q1+q2 (the link-2 / sensor angle).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// sin q1.
    pub s1: f64,
    /// cos q1.
    pub c1: f64,
    /// sin q2.
    pub s2: f64,
    /// cos q2.
    pub c2: f64,
    /// sin(q1+q2).
    pub s12: f64,
    /// cos(q1+q2).
    pub c12: f64,
}

/// Which inverse-kinematics branch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Elbow {
    /// q2 > 0.
    Positive,
    /// q2 < 0.
    Negative,
}

/// The arm model with derived dynamic constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arm {
    /// The physical parameters.
    pub params: ArmParams,
    i1: f64,
    i2: f64,
    beta: f64,
    m2t: f64,
}

impl Arm {
    /// Builds the model.
    pub fn new(params: ArmParams) -> Self {
        let p = params;
        let l1 = p.link1_length_m;
        let l2 = p.link2_length_m;
        let i1 = p.link1_inertia_kg_m2
            + p.link1_mass_kg * p.link1_com_m.powi(2)
            + p.rotor1_inertia_kg_m2
            + p.elbow_mass_kg * l1 * l1;
        let i2 = p.link2_inertia_kg_m2
            + p.link2_mass_kg * p.link2_com_m.powi(2)
            + p.rotor2_inertia_kg_m2
            + p.tip_mass_kg * l2 * l2;
        let s2 = p.link2_mass_kg * p.link2_com_m + p.tip_mass_kg * l2;
        Self {
            params,
            i1,
            i2,
            beta: l1 * s2,
            m2t: p.link2_mass_kg + p.tip_mass_kg,
        }
    }

    /// Checks the parameters.
    pub fn validate(params: &ArmParams) -> Result<(), ConfigError> {
        let vals = [
            ("link1_length_m", params.link1_length_m),
            ("link2_length_m", params.link2_length_m),
        ];
        for (n, v) in vals {
            if !(v.is_finite() && v > 0.0) {
                return Err(ConfigError::setting(format!("arm.{n}"), v, "must be > 0"));
            }
        }
        let nonneg = [
            ("link1_mass_kg", params.link1_mass_kg),
            ("link1_inertia_kg_m2", params.link1_inertia_kg_m2),
            ("rotor1_inertia_kg_m2", params.rotor1_inertia_kg_m2),
            ("elbow_mass_kg", params.elbow_mass_kg),
            ("link2_mass_kg", params.link2_mass_kg),
            ("link2_inertia_kg_m2", params.link2_inertia_kg_m2),
            ("rotor2_inertia_kg_m2", params.rotor2_inertia_kg_m2),
            ("tip_mass_kg", params.tip_mass_kg),
            (
                "joint_damping_nms_per_rad[0]",
                params.joint_damping_nms_per_rad[0],
            ),
            (
                "joint_damping_nms_per_rad[1]",
                params.joint_damping_nms_per_rad[1],
            ),
            ("torque_limit_nm[0]", params.torque_limit_nm[0]),
            ("torque_limit_nm[1]", params.torque_limit_nm[1]),
        ];
        for (n, v) in nonneg {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ConfigError::setting(
                    format!("arm.{n}"),
                    v,
                    "must be a non-negative number",
                ));
            }
        }
        let arm = Arm::new(*params);
        if arm.i2 <= 0.0 || arm.i1 <= 0.0 {
            return Err(ConfigError::rule(
                "arm inertias",
                "must be positive: give the links mass or inertia",
            ));
        }
        Ok(())
    }

    /// The trigonometry of a configuration, computed once and shared by the kinematic and
    /// dynamic quantities below (the fast loop's dominant cost otherwise).
    pub fn pose(&self, q: Vector2<f64>) -> Pose {
        let (s1, c1) = q[0].sin_cos();
        let (s2, c2) = q[1].sin_cos();
        // sin/cos(q1+q2) by the addition formulas.
        let s12 = s1 * c2 + c1 * s2;
        let c12 = c1 * c2 - s1 * s2;
        Pose {
            s1,
            c1,
            s2,
            c2,
            s12,
            c12,
        }
    }

    /// Tip position (m).
    pub fn forward(&self, q: Vector2<f64>) -> Vec2 {
        self.forward_at(&self.pose(q))
    }

    /// Tip position (m) at a precomputed pose.
    pub fn forward_at(&self, p: &Pose) -> Vec2 {
        let (l1, l2) = (self.params.link1_length_m, self.params.link2_length_m);
        Vec2::new(l1 * p.c1 + l2 * p.c12, l1 * p.s1 + l2 * p.s12)
    }

    /// Tip Jacobian ∂p/∂q.
    pub fn jacobian(&self, q: Vector2<f64>) -> Matrix2<f64> {
        self.jacobian_at(&self.pose(q))
    }

    /// Tip Jacobian at a precomputed pose.
    pub fn jacobian_at(&self, p: &Pose) -> Matrix2<f64> {
        let (l1, l2) = (self.params.link1_length_m, self.params.link2_length_m);
        Matrix2::new(
            -l1 * p.s1 - l2 * p.s12,
            -l2 * p.s12,
            l1 * p.c1 + l2 * p.c12,
            l2 * p.c12,
        )
    }

    /// Time derivative of the Jacobian, J̇(q, q̇).
    pub fn jacobian_dot(&self, q: Vector2<f64>, qd: Vector2<f64>) -> Matrix2<f64> {
        self.jacobian_dot_at(&self.pose(q), qd)
    }

    /// J̇ at a precomputed pose.
    pub fn jacobian_dot_at(&self, p: &Pose, qd: Vector2<f64>) -> Matrix2<f64> {
        let (l1, l2) = (self.params.link1_length_m, self.params.link2_length_m);
        let w1 = qd[0];
        let w12 = qd[0] + qd[1];
        Matrix2::new(
            -l1 * p.c1 * w1 - l2 * p.c12 * w12,
            -l2 * p.c12 * w12,
            -l1 * p.s1 * w1 - l2 * p.s12 * w12,
            -l2 * p.s12 * w12,
        )
    }

    /// Angle of link 2 (and of the sensor's x_e axis) from world X (rad).
    pub fn link2_angle(&self, q: Vector2<f64>) -> f64 {
        q[0] + q[1]
    }

    /// Inverse kinematics for the tip at `p` on the given elbow branch.
    pub fn inverse(&self, p: Vec2, elbow: Elbow) -> Result<Vector2<f64>, IkError> {
        self.inverse_pose(p, elbow).map(|(q, _)| q)
    }

    /// Inverse kinematics that also returns the pose's trigonometry, obtained from the
    /// geometry by the angle-difference formulas instead of sin/cos calls.
    pub fn inverse_pose(&self, p: Vec2, elbow: Elbow) -> Result<(Vector2<f64>, Pose), IkError> {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return Err(IkError::NotFinite);
        }
        let (l1, l2) = (self.params.link1_length_m, self.params.link2_length_m);
        let r2 = p.norm_squared();
        let c2 = (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
        if !(-1.0..=1.0).contains(&c2) {
            return Err(IkError::OutOfReach {
                x: p.x,
                y: p.y,
                r: r2.sqrt(),
                min: (l1 - l2).abs(),
                max: l1 + l2,
            });
        }
        let s2 = match elbow {
            Elbow::Positive => (1.0 - c2 * c2).sqrt(),
            Elbow::Negative => -(1.0 - c2 * c2).sqrt(),
        };
        let r = r2.sqrt();
        if r == 0.0 {
            return Err(IkError::OutOfReach {
                x: p.x,
                y: p.y,
                r,
                min: (l1 - l2).abs(),
                max: l1 + l2,
            });
        }
        // q1 = α − β with α the bearing of p and β the angle of the tip seen from link 1;
        // |(l1 + l2 c2, l2 s2)| = r.
        let (sa, ca) = (p.y / r, p.x / r);
        let (sb, cb) = (l2 * s2 / r, (l1 + l2 * c2) / r);
        let s1 = sa * cb - ca * sb;
        let c1 = ca * cb + sa * sb;
        let q = Vector2::new(s1.atan2(c1), s2.atan2(c2));
        let pose = Pose {
            s1,
            c1,
            s2,
            c2,
            s12: s1 * c2 + c1 * s2,
            c12: c1 * c2 - s1 * s2,
        };
        Ok((q, pose))
    }

    /// Joint-space inertia M(q).
    pub fn mass_matrix(&self, q: Vector2<f64>) -> Matrix2<f64> {
        self.mass_matrix_at(&self.pose(q))
    }

    /// Joint-space inertia at a precomputed pose.
    pub fn mass_matrix_at(&self, p: &Pose) -> Matrix2<f64> {
        let l1 = self.params.link1_length_m;
        let c2 = p.c2;
        let m11 = self.i1 + self.m2t * l1 * l1 + self.i2 + 2.0 * self.beta * c2;
        let m12 = self.i2 + self.beta * c2;
        Matrix2::new(m11, m12, m12, self.i2)
    }

    /// Coriolis and centrifugal torques h(q, q̇).
    pub fn coriolis(&self, q: Vector2<f64>, qd: Vector2<f64>) -> Vector2<f64> {
        self.coriolis_at(&self.pose(q), qd)
    }

    /// Coriolis and centrifugal torques at a precomputed pose.
    pub fn coriolis_at(&self, p: &Pose, qd: Vector2<f64>) -> Vector2<f64> {
        let s2 = p.s2;
        Vector2::new(
            -self.beta * s2 * (2.0 * qd[0] * qd[1] + qd[1] * qd[1]),
            self.beta * s2 * qd[0] * qd[0],
        )
    }

    /// Kinetic energy ½ q̇ᵀ M q̇ (J).
    pub fn kinetic_energy(&self, q: Vector2<f64>, qd: Vector2<f64>) -> f64 {
        0.5 * qd.dot(&(self.mass_matrix(q) * qd))
    }

    /// Inverse dynamics without contact: `M(q) q̈ + h(q, q̇) + B q̇` (N·m), at a pose.
    pub fn inverse_dynamics_at(
        &self,
        p: &Pose,
        qd: Vector2<f64>,
        qdd: Vector2<f64>,
    ) -> Vector2<f64> {
        let b = &self.params.joint_damping_nms_per_rad;
        self.mass_matrix_at(p) * qdd
            + self.coriolis_at(p, qd)
            + Vector2::new(b[0] * qd[0], b[1] * qd[1])
    }

    /// Joint accelerations for torques `tau` and a tip force `f_tip` (world, on the tool).
    pub fn acceleration(
        &self,
        q: Vector2<f64>,
        qd: Vector2<f64>,
        tau: Vector2<f64>,
        f_tip: Vec2,
    ) -> Vector2<f64> {
        self.acceleration_at(&self.pose(q), qd, tau, f_tip)
    }

    /// Joint accelerations at a precomputed pose.
    pub fn acceleration_at(
        &self,
        p: &Pose,
        qd: Vector2<f64>,
        tau: Vector2<f64>,
        f_tip: Vec2,
    ) -> Vector2<f64> {
        let m = self.mass_matrix_at(p);
        let damping = Vector2::new(
            self.params.joint_damping_nms_per_rad[0] * qd[0],
            self.params.joint_damping_nms_per_rad[1] * qd[1],
        );
        let rhs = tau + self.jacobian_at(p).transpose() * f_tip - self.coriolis_at(p, qd) - damping;
        // M is symmetric positive definite: closed-form 2×2 solve.
        let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
        Vector2::new(
            (m[(1, 1)] * rhs[0] - m[(0, 1)] * rhs[1]) / det,
            (m[(0, 0)] * rhs[1] - m[(1, 0)] * rhs[0]) / det,
        )
    }

    /// The configuration at which link 2 is perpendicular to the line from the base to the tip,
    /// with the tip at distance `√(l1² − l2²)` along world angle `bearing` (rad). There the
    /// tip's motion along the bearing is joint 2 alone and motion along link 2 is joint 1 alone.
    /// Returns `None` if l2 ≥ l1.
    pub fn decoupled_configuration(&self, bearing: f64, elbow: Elbow) -> Option<Vector2<f64>> {
        let (l1, l2) = (self.params.link1_length_m, self.params.link2_length_m);
        if l2 >= l1 {
            return None;
        }
        let r = (l1 * l1 - l2 * l2).sqrt();
        let p = Vec2::new(r * bearing.cos(), r * bearing.sin());
        self.inverse(p, elbow).ok()
    }
}

/// PID gains of one joint (N·m/rad, N·m/(rad·s), N·m·s/rad).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PidGains {
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain.
    pub ki: f64,
    /// Derivative gain.
    pub kd: f64,
}

/// |T(jω)| of a rigid joint of inertia `inertia` under PID `g` (derivative on error):
/// `T(s) = (kd s² + kp s + ki) / (I s³ + kd s² + kp s + ki)`.
pub fn closed_loop_magnitude(g: &PidGains, inertia: f64, omega: f64) -> f64 {
    use nalgebra::Complex;
    let s = Complex::new(0.0, omega);
    let num = s * s * g.kd + s * g.kp + g.ki;
    let den = s * s * s * inertia + s * s * g.kd + s * g.kp + g.ki;
    (num / den).norm()
}

/// PID gains giving a rigid joint of `inertia` (kg·m²) a closed-loop −3 dB bandwidth of
/// `bandwidth_hz`: `kp = I ωn²`, `kd = 2 ζ I ωn`, `ki = r I ωn³` (integral corner at r·ωn),
/// with ωn found so that `|T(j 2π f_b)| = 1/√2` (the highest crossing).
pub fn tune_pid_for_bandwidth(
    inertia: f64,
    bandwidth_hz: f64,
    damping_ratio: f64,
    integral_ratio: f64,
) -> PidGains {
    let gains = |wn: f64| PidGains {
        kp: inertia * wn * wn,
        kd: 2.0 * damping_ratio * inertia * wn,
        ki: integral_ratio * inertia * wn * wn * wn,
    };
    // T depends on s/ωn only: find the bandwidth x of the ωn = 1 loop, then scale.
    let unit_loop = gains(1.0);
    let target = std::f64::consts::FRAC_1_SQRT_2;
    // Scan down from high frequency to the first crossing, then bisect.
    let mut hi = 100.0;
    let mut lo = hi;
    while lo > 1e-3 {
        lo *= 0.95;
        if closed_loop_magnitude(&unit_loop, inertia, lo) >= target {
            break;
        }
        hi = lo;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if closed_loop_magnitude(&unit_loop, inertia, mid) >= target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let x = 0.5 * (lo + hi);
    gains(std::f64::consts::TAU * bandwidth_hz / x)
}

wire_struct! {
    /// The [`JointServo`]s' state, for a snapshot.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::JointServoState")]
    pub struct JointServoState {
        /// Integral of the position error per joint (rad·s).
        pub integral_rad_s: [f64; 2],
        /// 1 while integrating (0: frozen).
        pub integrating: u32,
        /// Reserved (0).
        pub reserved: u32,
    }
}

/// The two joint PID servos with torque saturation and anti-windup.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointServo {
    /// Gains of joint 1 and 2.
    pub gains: [PidGains; 2],
    /// Torque limits (N·m).
    pub torque_limit: [f64; 2],
    /// Integral of the position error (rad·s), scaled by ki inside.
    integral: Vector2<f64>,
    integrating: bool,
}

impl JointServo {
    /// New servo with a zero integrator.
    pub fn new(gains: [PidGains; 2], torque_limit: [f64; 2]) -> Self {
        Self {
            gains,
            torque_limit,
            integral: Vector2::zeros(),
            integrating: true,
        }
    }

    /// Presets the integrator so that, at zero error, the servo outputs `torque` (bumpless start
    /// in contact).
    pub fn preset_torque(&mut self, torque: Vector2<f64>) {
        for j in 0..2 {
            let ki = self.gains[j].ki;
            self.integral[j] = if ki > 0.0 { torque[j] / ki } else { 0.0 };
        }
    }

    /// Its state (the gains and limits are settings).
    pub fn state(&self) -> JointServoState {
        JointServoState {
            integral_rad_s: [self.integral[0], self.integral[1]],
            integrating: u32::from(self.integrating),
            reserved: 0,
        }
    }

    /// Restores a state taken by [`JointServo::state`].
    pub fn restore(&mut self, s: &JointServoState) {
        self.integral = Vector2::new(s.integral_rad_s[0], s.integral_rad_s[1]);
        self.integrating = s.integrating != 0;
    }

    /// Freezes (false) or resumes (true) the integrators; frozen, they hold their torque.
    pub fn set_integrating(&mut self, on: bool) {
        self.integrating = on;
    }

    /// The integrator's share of the torque (N·m).
    pub fn integral_torque(&self) -> Vector2<f64> {
        Vector2::new(
            self.gains[0].ki * self.integral[0],
            self.gains[1].ki * self.integral[1],
        )
    }

    /// Torque for set-point (q_d, q̇_d) at measured (q, q̇) plus a feedforward torque;
    /// integrates over `dt`. The sum saturates at the torque limits.
    pub fn torque(
        &mut self,
        q_d: Vector2<f64>,
        qd_d: Vector2<f64>,
        q: Vector2<f64>,
        qd: Vector2<f64>,
        feedforward: Vector2<f64>,
        dt: f64,
    ) -> Vector2<f64> {
        let mut tau = Vector2::zeros();
        for j in 0..2 {
            let error = (q_d[j] - q[j], qd_d[j] - qd[j]);
            tau[j] = self.gains[j].torque(
                error,
                (&mut self.integral[j], self.integrating),
                feedforward[j],
                self.torque_limit[j],
                dt,
            );
        }
        tau
    }
}

impl PidGains {
    /// One joint's torque for the position and rate errors `(e, ė)` plus `feedforward`,
    /// saturated at ±`limit`. The integral of `e` (rad·s), while integrating, takes `e · dt`
    /// unless that would wind it further into saturation (conditional integration); frozen, it
    /// holds its torque.
    pub fn torque(
        &self,
        (e, ed): (f64, f64),
        (integral, integrating): (&mut f64, bool),
        feedforward: f64,
        limit: f64,
        dt: f64,
    ) -> f64 {
        let unsat = self.kp * e + self.kd * ed + self.ki * (*integral + e * dt) + feedforward;
        // Conditional integration: do not wind up further into saturation.
        if integrating && (unsat.abs() <= limit || unsat.signum() != e.signum()) {
            *integral += e * dt;
        }
        let out = self.kp * e + self.kd * ed + self.ki * *integral + feedforward;
        out.clamp(-limit, limit)
    }
}

#[cfg(test)]
#[path = "arm_tests.rs"]
mod tests;
