//! The thesis's two-link arm with a third, wrist joint (a planar SCARA-like arm, §5.4's x, y
//! and θ; docs/insertion.md, *The wrist (first step)*): kinematics of the tool pose (x, y, φ), its
//! Jacobian, the closed-form inverse, and the rigid-body dynamics M(q) q̈ + h(q, q̇).
//!
//! Links 1 and 2 are [`Arm`]'s, with its tip mass at the wrist joint; the wrist link (motor
//! rotor, flange, gripper and what it holds) is a rigid body of mass m₃ whose centre of mass
//! lies c₃ along it from the wrist joint, with inertia I₃ about that centre. Its tool point is
//! l₃ along it. Derivation: the wrist link adds `m₃ J_cᵀ J_c + I₃ 1 1ᵀ` to the mass matrix
//! (J_c its centre's Jacobian, 1 = (1, 1, 1) the rate of its angle) and `m₃ J_cᵀ (J̇_c q̇)` to
//! h, with `J̇_c q̇ = −Σ_i r_i θ̇_i² e(θ_i)`: the centripetal acceleration of a point
//! `Σ_i r_i e(θ_i)` on a chain of absolute angles θ_i = q₁ + … + q_i when q̈ = 0.

use crate::arm::{Arm, ArmParams, Elbow};
use crate::error::IkError;
use crate::math::Vec2;
use nalgebra::{Matrix3, Vector2, Vector3};

/// The wrist link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WristParams {
    /// Wrist joint to the tool point (m).
    pub length_m: f64,
    /// Mass of the wrist link with what it holds (kg).
    pub mass_kg: f64,
    /// Its centre of mass from the wrist joint, along the link (m).
    pub com_m: f64,
    /// Its inertia about its centre of mass, rotor included (kg·m²).
    pub inertia_kg_m2: f64,
}

impl Default for WristParams {
    /// A 30 mm wrist carrying the insertion's 0.2 kg peg and a 0.3 kg flange and motor.
    fn default() -> Self {
        Self {
            length_m: 0.03,
            mass_kg: 0.5,
            com_m: 0.015,
            inertia_kg_m2: 2e-4,
        }
    }
}

/// The arm with its wrist.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scara {
    arm: Arm,
    wrist: WristParams,
}

/// `(cos a, sin a)`.
fn e(a: f64) -> Vec2 {
    Vec2::new(a.cos(), a.sin())
}

/// The vector turned by +90°.
fn perp(v: Vec2) -> Vec2 {
    Vec2::new(-v.y, v.x)
}

impl Scara {
    /// The arm of `arm` (its tip mass now at the wrist joint) with the wrist `wrist`.
    pub fn new(arm: ArmParams, wrist: WristParams) -> Self {
        Self {
            arm: Arm::new(arm),
            wrist,
        }
    }

    /// The two-link arm it extends.
    pub fn arm(&self) -> &Arm {
        &self.arm
    }

    /// Absolute link angles θ₁, θ₂, θ₃ (rad).
    fn angles(q: Vector3<f64>) -> [f64; 3] {
        [q[0], q[0] + q[1], q[0] + q[1] + q[2]]
    }

    /// The joint positions (joint 1 at the origin) and the wrist link's point `along` it.
    fn points(&self, q: Vector3<f64>, along: f64) -> [Vec2; 4] {
        let p = &self.arm.params;
        let [a1, a2, a3] = Self::angles(q);
        let j2 = e(a1) * p.link1_length_m;
        let j3 = j2 + e(a2) * p.link2_length_m;
        [Vec2::zeros(), j2, j3, j3 + e(a3) * along]
    }

    /// The tool pose: position (m) and angle φ = q₁ + q₂ + q₃ (rad).
    pub fn forward(&self, q: Vector3<f64>) -> Vector3<f64> {
        let tip = self.points(q, self.wrist.length_m)[3];
        Vector3::new(tip.x, tip.y, Self::angles(q)[2])
    }

    /// The Jacobian of a point `along` the wrist link: column j is ẑ × (point − joint j).
    pub(crate) fn point_jacobian(&self, q: Vector3<f64>, along: f64) -> [Vec2; 3] {
        let pts = self.points(q, along);
        [0, 1, 2].map(|j| perp(pts[3] - pts[j]))
    }

    /// ∂(x, y, φ)/∂q.
    pub fn jacobian(&self, q: Vector3<f64>) -> Matrix3<f64> {
        let c = self.point_jacobian(q, self.wrist.length_m);
        Matrix3::new(
            c[0].x, c[1].x, c[2].x, //
            c[0].y, c[1].y, c[2].y, //
            1.0, 1.0, 1.0,
        )
    }

    /// The joint angles that put the tool at `pose` (x, y, φ): the wrist joint at
    /// `(x, y) − l₃ e(φ)` by the two-link inverse, then q₃ = φ − q₁ − q₂ (wrapped).
    pub fn inverse(&self, pose: Vector3<f64>, elbow: Elbow) -> Result<Vector3<f64>, IkError> {
        let wrist = Vec2::new(pose[0], pose[1]) - e(pose[2]) * self.wrist.length_m;
        let q = self.arm.inverse(wrist, elbow)?;
        let q3 = crate::math::wrap_angle(pose[2] - q[0] - q[1]);
        Ok(Vector3::new(q[0], q[1], q3))
    }

    /// Joint-space inertia M(q).
    pub fn mass_matrix(&self, q: Vector3<f64>) -> Matrix3<f64> {
        let w = &self.wrist;
        let m2 = self.arm.mass_matrix(Vector2::new(q[0], q[1]));
        let mut m = Matrix3::zeros();
        m.fixed_view_mut::<2, 2>(0, 0).copy_from(&m2);
        let jc = self.point_jacobian(q, w.com_m);
        for i in 0..3 {
            for j in 0..3 {
                m[(i, j)] += w.mass_kg * jc[i].dot(&jc[j]) + w.inertia_kg_m2;
            }
        }
        m
    }

    /// Coriolis and centrifugal torques h(q, q̇) (N·m): the two-link arm's, and the wrist
    /// link's `m₃ J_cᵀ (J̇_c q̇)`.
    pub fn coriolis(&self, q: Vector3<f64>, qd: Vector3<f64>) -> Vector3<f64> {
        let p = &self.arm.params;
        let w = &self.wrist;
        let h2 = self
            .arm
            .coriolis(Vector2::new(q[0], q[1]), Vector2::new(qd[0], qd[1]));
        let angles = Self::angles(q);
        let rates = [qd[0], qd[0] + qd[1], qd[0] + qd[1] + qd[2]];
        let lengths = [p.link1_length_m, p.link2_length_m, w.com_m];
        let acc = (0..3).fold(Vec2::zeros(), |a, i| {
            a - e(angles[i]) * (lengths[i] * rates[i] * rates[i])
        });
        let jc = self.point_jacobian(q, w.com_m);
        Vector3::new(h2[0], h2[1], 0.0) + Vector3::from_fn(|i, _| w.mass_kg * jc[i].dot(&acc))
    }

    /// Kinetic energy ½ q̇ᵀ M q̇ (J).
    pub fn kinetic_energy(&self, q: Vector3<f64>, qd: Vector3<f64>) -> f64 {
        0.5 * qd.dot(&(self.mass_matrix(q) * qd))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scara() -> Scara {
        Scara::new(ArmParams::default(), WristParams::default())
    }

    const Q: [f64; 3] = [0.3, 1.1, -0.7];

    /// The Jacobian is the derivative of the forward kinematics (central differences).
    #[test]
    fn the_jacobian_is_the_derivative_of_the_pose() {
        let s = scara();
        let q = Vector3::from(Q);
        let j = s.jacobian(q);
        let h = 1e-6;
        for k in 0..3 {
            let dq = Vector3::from_fn(|i, _| if i == k { h } else { 0.0 });
            let d = (s.forward(q + dq) - s.forward(q - dq)) / (2.0 * h);
            for i in 0..3 {
                assert!((d[i] - j[(i, k)]).abs() < 1e-8, "({i}, {k}): {d} vs {j}");
            }
        }
    }

    /// The inverse puts the tool back where the forward kinematics had it, on both elbows.
    #[test]
    fn the_inverse_returns_the_pose() {
        let s = scara();
        for q in [Vector3::from(Q), Vector3::new(-0.4, -1.3, 0.9)] {
            let elbow = if q[1] > 0.0 {
                Elbow::Positive
            } else {
                Elbow::Negative
            };
            let back = s.inverse(s.forward(q), elbow).unwrap();
            assert!((back - q).norm() < 1e-9, "{back} vs {q}");
        }
        let far = Vector3::new(10.0, 0.0, 0.0);
        assert!(s.inverse(far, Elbow::Positive).is_err());
    }

    /// A massless wrist leaves the two-link arm's inertia in the upper block and nothing else;
    /// a massive one makes M symmetric and positive definite.
    #[test]
    fn a_massless_wrist_is_the_two_link_arm() {
        let q = Vector3::from(Q);
        let light = WristParams {
            mass_kg: 0.0,
            inertia_kg_m2: 0.0,
            ..WristParams::default()
        };
        let s = Scara::new(ArmParams::default(), light);
        let m = s.mass_matrix(q);
        let m2 = s.arm().mass_matrix(Vector2::new(q[0], q[1]));
        assert!((m.fixed_view::<2, 2>(0, 0) - m2).norm() < 1e-15);
        assert!(m.row(2).norm() == 0.0 && m.column(2).norm() == 0.0);
        let qd = Vector3::new(0.4, -0.9, 2.0);
        let h2 = s
            .arm()
            .coriolis(Vector2::new(q[0], q[1]), Vector2::new(qd[0], qd[1]));
        let h = s.coriolis(q, qd);
        assert!((h - Vector3::new(h2[0], h2[1], 0.0)).norm() < 1e-15);
        let m = scara().mass_matrix(q);
        assert!((m - m.transpose()).norm() < 1e-15);
        assert!(m.cholesky().is_some());
    }

    /// Lagrange's equations without gravity: the power of τ = M q̈ + h is the rate of the
    /// kinetic energy, for any q̈ (checked along a trajectory by central differences), which
    /// pins h to M (a wrong h, or an M inconsistent with the link geometry, breaks it). And
    /// the kinetic energy is the sum over the wrist link's translation and rotation computed
    /// directly from its centre's velocity.
    #[test]
    fn the_dynamics_conserve_power() {
        let s = scara();
        let q0 = Vector3::from(Q);
        let qd0 = Vector3::new(0.7, -1.2, 2.5);
        let qdd = Vector3::new(3.0, -2.0, 5.0);
        let at = |t: f64| (q0 + qd0 * t + qdd * (0.5 * t * t), qd0 + qdd * t);
        let h = 1e-5;
        let ke = |t: f64| {
            let (q, qd) = at(t);
            s.kinetic_energy(q, qd)
        };
        let rate = (ke(h) - ke(-h)) / (2.0 * h);
        let tau = s.mass_matrix(q0) * qdd + s.coriolis(q0, qd0);
        let power = qd0.dot(&tau);
        assert!(
            (rate - power).abs() < 1e-6 * power.abs().max(1.0),
            "{rate} vs {power}"
        );
        // The wrist link's share of the kinetic energy, from first principles.
        let w = WristParams::default();
        let light = Scara::new(
            ArmParams::default(),
            WristParams {
                mass_kg: 0.0,
                inertia_kg_m2: 0.0,
                ..w
            },
        );
        let jc = s.point_jacobian(q0, w.com_m);
        let vc = jc[0] * qd0[0] + jc[1] * qd0[1] + jc[2] * qd0[2];
        let omega = qd0.sum();
        let wrist = 0.5 * w.mass_kg * vc.norm_squared() + 0.5 * w.inertia_kg_m2 * omega * omega;
        let direct = light.kinetic_energy(q0, qd0) + wrist;
        assert!((s.kinetic_energy(q0, qd0) - direct).abs() < 1e-12);
    }

    /// The tool point's operational-space inertia Λ = (J M⁻¹ Jᵀ)⁻¹ with the peg pointing
    /// down the hole, at three poses on both elbows (docs/insertion.md, *Not yet*): 4.25 kg
    /// and 13–14 kg in x–y, 4–9·10⁻³ kg·m² in θ, at least 20 times the peg's 0.2 kg under the
    /// compliant wrist. `-- --nocapture` prints them.
    #[test]
    fn the_tool_point_carries_the_arms_inertia() {
        let s = scara();
        for (x, y) in [(0.55, 0.0), (0.45, 0.2), (0.6, -0.2)] {
            for elbow in [Elbow::Negative, Elbow::Positive] {
                let pose = Vector3::new(x, y, -std::f64::consts::FRAC_PI_2);
                let q = s.inverse(pose, elbow).unwrap();
                let j = s.jacobian(q);
                let m_inv = s.mass_matrix(q).try_inverse().unwrap();
                let lambda = (j * m_inv * j.transpose()).try_inverse().unwrap();
                let xy = lambda.fixed_view::<2, 2>(0, 0).into_owned();
                let ev = xy.symmetric_eigenvalues();
                let (lo, hi) = (ev.min(), ev.max());
                eprintln!(
                    "({x}, {y}) {elbow:?}: x-y {lo:.3} kg, {hi:.3} kg; theta {:.2e} kg m^2",
                    lambda[(2, 2)]
                );
                assert!(
                    (4.2..4.3).contains(&lo) && (13.0..14.5).contains(&hi),
                    "{ev:?}"
                );
                assert!((3e-3..1e-2).contains(&lambda[(2, 2)]), "{lambda}");
                assert!(lo >= 20.0 * 0.2);
            }
        }
    }
}
