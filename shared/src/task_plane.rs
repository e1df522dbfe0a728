//! The thesis's planar controller on a seven-joint arm (issue 48, docs/franka.md): the task
//! plane, the tool's planar coordinates (x, y, θ) and the three it holds by impedance (the
//! normal offset and two tilts), and the joint torques
//! `τ = Jᵀ W + N τ₀ + c`, limited as the arm limits them.
//!
//! Frames: the robot's base frame O; the plane frame P, its rotation `R_P` (columns: the
//! plane's x and y axes and its normal, in O) and origin `p_P`; the tool frame T, pose
//! (`R_T`, `p_T`) in O. The mount `R_m` is the tool's orientation in P at θ = 0, so that a tool
//! lying in the plane has `R_T = R_P Rz(θ) R_m` (a tool pointing down onto a table whose
//! normal is up: `R_m = Rx(π)`).
//!
//! - Position: `(x, y, z) = R_Pᵀ (p_T − p_P)`; z is the offset along the normal.
//! - θ: with `R_e = R_Pᵀ R_T R_mᵀ`, the θ maximising `tr(Rz(θ)ᵀ R_e)`, i.e.
//!   `θ = atan2(R_e[1,0] − R_e[0,1], R_e[0,0] + R_e[1,1])`.
//! - Tilt: the rotation vector of `R_r = R_e Rz(θ)ᵀ` (the tilt applied in the plane's frame,
//!   `R_e = R_r Rz(θ)`), whose x and y components are the tilts about the plane's axes.
//!   `R_r = Rz(θ) (Rz(θ)ᵀ R_e) Rz(θ)ᵀ`, and at the maximising θ `Rz(θ)ᵀ R_e` is symmetric in
//!   its x-y block, so its rotation vector (the axial vector of `R − Rᵀ`, scaled) has no z
//!   component, nor has `R_r`'s (the same vector turned about z).
//! - Rates: the twist `(v, ω) = J q̇` (the zero Jacobian at the tool: linear rows first, in O),
//!   `R_Pᵀ v` and `R_Pᵀ ω`: ẋ, ẏ, ż, θ̇ = `(R_Pᵀ ω)_z`, and the tilt rates (the tilts'
//!   derivatives at zero tilt).
//!
//! The wrench W (in O) is `(R_P f, R_P m)` with the planar controller's `f_x, f_y, m_θ` and the
//! hold's `f_z = −k_z (z − z_d) − d_z ż` and `m_{x,y} = −k_r tilt − d_r tilt rate`. The null
//! space term projects a joint impedance `τ₀ = −K_q (q − q_n) − D_q q̇` with the dynamically
//! consistent projector `N = I − Jᵀ Λ J M⁻¹`, `Λ = (J M⁻¹ Jᵀ)⁻¹`, so that it adds no
//! acceleration at the tool: `J M⁻¹ N τ₀ = 0`. `c` is the Coriolis and centrifugal torque; the
//! robot compensates gravity itself.
//!
//! Nothing here allocates: every matrix has a fixed size.

use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, Vector2, Vector3};

/// Joint-space vectors of the seven-joint arm (rad, rad/s, N·m).
pub type Joints = SVector<f64, 7>;
/// The zero Jacobian at the tool: rows `(v_x, v_y, v_z, ω_x, ω_y, ω_z)` in the base frame.
pub type Jacobian = SMatrix<f64, 6, 7>;
/// The joint-space mass matrix (kg·m²).
pub type MassMatrix = SMatrix<f64, 7, 7>;

/// Why a task plane or a tool mount is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    /// A rotation that is not orthonormal with determinant +1.
    #[error(
        "the {what} is not a rotation (‖RᵀR − I‖ = {error:.2e}, det = {det:.6}): give an orthonormal, right-handed matrix"
    )]
    NotARotation {
        /// Which frame.
        what: &'static str,
        /// The largest entry of `RᵀR − I`.
        error: f64,
        /// Its determinant.
        det: f64,
    },
    /// A non-finite entry.
    #[error("the {what} has a non-finite entry")]
    NotFinite {
        /// Which frame.
        what: &'static str,
    },
}

/// Checks that `r` is a rotation to within `1e-6`.
///
/// # Errors
/// [`FrameError`] naming `what`.
pub fn check_rotation(r: &Matrix3<f64>, what: &'static str) -> Result<(), FrameError> {
    if r.iter().any(|v| !v.is_finite()) {
        return Err(FrameError::NotFinite { what });
    }
    let error = (r.transpose() * r - Matrix3::identity()).amax();
    let det = r.determinant();
    if error > 1e-6 || (det - 1.0).abs() > 1e-6 {
        return Err(FrameError::NotARotation { what, error, det });
    }
    Ok(())
}

/// The plane the thesis's controller acts in, and the tool's mount in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskPlane {
    rotation: Matrix3<f64>,
    origin: Vector3<f64>,
    mount: Matrix3<f64>,
}

/// The tool's coordinates in the task plane.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlanarState {
    /// x and y in the plane (m).
    pub position_m: Vector2<f64>,
    /// The tool's angle about the plane's normal (rad).
    pub theta_rad: f64,
    /// The offset along the normal (m).
    pub normal_m: f64,
    /// The tilts about the plane's x and y axes (rad).
    pub tilt_rad: Vector2<f64>,
    /// ẋ and ẏ (m/s).
    pub velocity_m_per_s: Vector2<f64>,
    /// θ̇ (rad/s).
    pub theta_rate_rad_per_s: f64,
    /// ż (m/s).
    pub normal_velocity_m_per_s: f64,
    /// The rates of the two tilts (rad/s).
    pub tilt_rate_rad_per_s: Vector2<f64>,
}

impl TaskPlane {
    /// A plane with rotation `rotation` (columns: x axis, y axis, normal, in the base frame),
    /// origin `origin_m` (m), and the tool's orientation in it at θ = 0, `mount`.
    ///
    /// # Errors
    /// [`FrameError`] when either matrix is not a rotation or an entry is not finite.
    pub fn new(
        rotation: Matrix3<f64>,
        origin_m: Vector3<f64>,
        mount: Matrix3<f64>,
    ) -> Result<Self, FrameError> {
        check_rotation(&rotation, "task plane's rotation")?;
        check_rotation(&mount, "tool's mount")?;
        if origin_m.iter().any(|v| !v.is_finite()) {
            return Err(FrameError::NotFinite {
                what: "task plane's origin",
            });
        }
        Ok(Self {
            rotation,
            origin: origin_m,
            mount,
        })
    }

    /// The plane's rotation in the base frame.
    #[must_use]
    pub fn rotation(&self) -> &Matrix3<f64> {
        &self.rotation
    }

    /// The tool's pose in the base frame for planar coordinates `(x, y, θ)` at normal offset
    /// `normal_m`, without tilt: `R_P Rz(θ) R_m`, `p_P + R_P (x, y, z)`.
    #[must_use]
    pub fn pose(
        &self,
        position_m: Vector2<f64>,
        theta_rad: f64,
        normal_m: f64,
    ) -> (Matrix3<f64>, Vector3<f64>) {
        let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), theta_rad);
        let r = self.rotation * rz.matrix() * self.mount;
        let p = self.origin + self.rotation * Vector3::new(position_m.x, position_m.y, normal_m);
        (r, p)
    }

    /// The tool's planar coordinates and rates from its pose (`r`, `p` in the base frame), the
    /// Jacobian `jacobian` at the tool and the joint rates `dq` (rad/s).
    #[must_use]
    pub fn planar(
        &self,
        r: &Matrix3<f64>,
        p: &Vector3<f64>,
        jacobian: &Jacobian,
        dq: &Joints,
    ) -> PlanarState {
        let local = self.rotation.transpose() * (p - self.origin);
        let e = self.rotation.transpose() * r * self.mount.transpose();
        let theta = (e[(1, 0)] - e[(0, 1)]).atan2(e[(0, 0)] + e[(1, 1)]);
        let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), theta);
        let tilt = rotation_vector(&(e * rz.matrix().transpose()));
        let twist = jacobian * dq;
        let v = self.rotation.transpose() * twist.fixed_rows::<3>(0);
        let w = self.rotation.transpose() * twist.fixed_rows::<3>(3);
        PlanarState {
            position_m: local.xy(),
            theta_rad: theta,
            normal_m: local.z,
            tilt_rad: tilt.xy(),
            velocity_m_per_s: v.xy(),
            theta_rate_rad_per_s: w.z,
            normal_velocity_m_per_s: v.z,
            tilt_rate_rad_per_s: w.xy(),
        }
    }

    /// The wrench in the base frame `(f, m)` for the planar command (`f_x`, `f_y` in N, `m_θ`
    /// in N·m) and the hold of the normal offset at `normal_target_m` and of zero tilt.
    #[must_use]
    pub fn wrench(
        &self,
        state: &PlanarState,
        planar_force_n: Vector2<f64>,
        planar_moment_nm: f64,
        normal_target_m: f64,
        hold: &Hold,
    ) -> SVector<f64, 6> {
        let fz = -hold.normal_stiffness_n_per_m * (state.normal_m - normal_target_m)
            - hold.normal_damping_n_s_per_m * state.normal_velocity_m_per_s;
        let m_tilt = -hold.tilt_stiffness_nm_per_rad * state.tilt_rad
            - hold.tilt_damping_nm_s_per_rad * state.tilt_rate_rad_per_s;
        let f = self.rotation * Vector3::new(planar_force_n.x, planar_force_n.y, fz);
        let m = self.rotation * Vector3::new(m_tilt.x, m_tilt.y, planar_moment_nm);
        SVector::<f64, 6>::new(f.x, f.y, f.z, m.x, m.y, m.z)
    }
}

/// The largest `d Δt / Λ` the planar gains give (a damper `d` on an inertia `Λ`, sampled every
/// `Δt`): the discrete pole `1 − d Δt / Λ` stays inside the unit circle while it is below 2
/// (docs/franka.md, *The planar gains*); a quarter of that leaves the pole at 0.5.
pub const DISCRETE_DAMPING_LIMIT: f64 = 0.5;

/// Stiffness and damping of the planar axes: x and y (N/m, N·s/m), θ (N·m/rad, N·m·s/rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarGains {
    /// Stiffness along x, y and about the normal.
    pub stiffness: Vector3<f64>,
    /// Damping along x, y and about the normal.
    pub damping: Vector3<f64>,
    /// The natural frequency the axes got (rad/s): the one asked for, or the sampling's limit.
    pub natural_frequency_rad_per_s: f64,
}

impl TaskPlane {
    /// The inertia the tool shows along the plane's x and y (kg) and about its normal (kg·m²):
    /// the diagonal of the task-space inertia `Λ = (J_P M⁻¹ J_Pᵀ)⁻¹`, with `J_P` the Jacobian's
    /// rows turned into the plane's frame (`R_Pᵀ` on the linear and the angular rows). `None`
    /// where M or `J M⁻¹ Jᵀ` is not positive definite (a singular arm).
    #[must_use]
    pub fn planar_inertia(&self, jacobian: &Jacobian, mass: &MassMatrix) -> Option<Vector3<f64>> {
        let m = mass.cholesky()?;
        let rt = self.rotation.transpose();
        let mut jp = *jacobian;
        let linear = rt * jacobian.fixed_rows::<3>(0);
        let angular = rt * jacobian.fixed_rows::<3>(3);
        jp.fixed_rows_mut::<3>(0).copy_from(&linear);
        jp.fixed_rows_mut::<3>(3).copy_from(&angular);
        let lambda = (jp * m.solve(&jp.transpose())).cholesky()?.inverse();
        Some(Vector3::new(lambda[(0, 0)], lambda[(1, 1)], lambda[(5, 5)]))
    }
}

/// The planar gains for the axes' inertias `inertia` (x, y in kg, θ in kg·m²,
/// [`TaskPlane::planar_inertia`]): each axis a mass-spring-damper of natural frequency
/// `ω = 2π bandwidth_hz` and damping ratio `damping_ratio`, `k = Λ ω²`, `d = 2 ζ Λ ω`, with ω
/// held to `DISCRETE_DAMPING_LIMIT / (2 ζ Δt)` so that `d Δt / Λ` stays at or below
/// [`DISCRETE_DAMPING_LIMIT`] for a controller sampled every `dt_s`. `None` unless every
/// input is finite and positive.
#[must_use]
pub fn planar_gains(
    inertia: &Vector3<f64>,
    bandwidth_hz: f64,
    damping_ratio: f64,
    dt_s: f64,
) -> Option<PlanarGains> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !(inertia.iter().all(|&v| positive(v))
        && positive(bandwidth_hz)
        && positive(damping_ratio)
        && positive(dt_s))
    {
        return None;
    }
    let omega = (std::f64::consts::TAU * bandwidth_hz)
        .min(DISCRETE_DAMPING_LIMIT / (2.0 * damping_ratio * dt_s));
    Some(PlanarGains {
        stiffness: inertia * (omega * omega),
        damping: inertia * (2.0 * damping_ratio * omega),
        natural_frequency_rad_per_s: omega,
    })
}

/// The rotation vector (axis × angle, rad) of rotation `r`: the angle as
/// `atan2(|a|, (tr r − 1)/2)`, `a` the axial vector of `(r − rᵀ)/2` (`sin φ` times the axis).
/// nalgebra's `scaled_axis` takes the angle from the trace alone (an arccosine), which keeps
/// only half the digits of a small angle: about 1e-4 relative at 1e-6 rad, seen as a tilt rate
/// off by 3e-6 in this module's tests. Past a half turn it falls back to nalgebra's.
#[must_use]
pub fn rotation_vector(r: &Matrix3<f64>) -> Vector3<f64> {
    let a = Vector3::new(
        r[(2, 1)] - r[(1, 2)],
        r[(0, 2)] - r[(2, 0)],
        r[(1, 0)] - r[(0, 1)],
    ) * 0.5;
    let sin = a.norm();
    let cos = (r.trace() - 1.0) * 0.5;
    if cos < 0.0 {
        return Rotation3::from_matrix_unchecked(*r).scaled_axis();
    }
    if sin == 0.0 {
        return Vector3::zeros();
    }
    a * (sin.atan2(cos) / sin)
}

/// The impedance that holds what the planar controller does not command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hold {
    /// Along the plane's normal (N/m).
    pub normal_stiffness_n_per_m: f64,
    /// Along the normal (N·s/m).
    pub normal_damping_n_s_per_m: f64,
    /// About the plane's x and y axes (N·m/rad).
    pub tilt_stiffness_nm_per_rad: f64,
    /// About the plane's x and y axes (N·m·s/rad).
    pub tilt_damping_nm_s_per_rad: f64,
    /// The null space's joint stiffness toward the posture (N·m/rad).
    pub null_stiffness_nm_per_rad: f64,
    /// The null space's joint damping (N·m·s/rad).
    pub null_damping_nm_s_per_rad: f64,
}

impl Hold {
    /// The hold measured on the FR3's model (docs/franka.md, *The loop closed on the FR3's
    /// model*): 800 N/m and 60 N·s/m along the normal, 40 N·m/rad and 2 N·m·s/rad in tilt,
    /// 4 N·m/rad and 0.8 N·m·s/rad in the null space.
    pub const FR3: Hold = Hold {
        normal_stiffness_n_per_m: 800.0,
        normal_damping_n_s_per_m: 60.0,
        tilt_stiffness_nm_per_rad: 40.0,
        tilt_damping_nm_s_per_rad: 2.0,
        null_stiffness_nm_per_rad: 4.0,
        null_damping_nm_s_per_rad: 0.8,
    };
}

/// The joint torques for wrench `wrench` (base frame) at the tool, plus the null-space
/// impedance toward `posture` and the Coriolis torque `coriolis`; `false` in the second slot
/// when `J M⁻¹ Jᵀ` is singular (the arm at a singularity: no null-space term is added).
#[must_use]
#[allow(clippy::too_many_arguments)]
pub fn joint_torques(
    jacobian: &Jacobian,
    mass: &MassMatrix,
    coriolis: &Joints,
    q: &Joints,
    dq: &Joints,
    posture: &Joints,
    wrench: &SVector<f64, 6>,
    hold: &Hold,
) -> (Joints, bool) {
    let task = jacobian.transpose() * wrench;
    let tau0 =
        -hold.null_stiffness_nm_per_rad * (q - posture) - hold.null_damping_nm_s_per_rad * dq;
    match null_space(jacobian, mass, &tau0) {
        Some(n) => (task + n + coriolis, true),
        None => (task + coriolis, false),
    }
}

/// `N τ₀ = τ₀ − Jᵀ Λ J M⁻¹ τ₀`, `Λ = (J M⁻¹ Jᵀ)⁻¹`; `None` if M or `J M⁻¹ Jᵀ` is not
/// positive definite.
#[must_use]
pub fn null_space(jacobian: &Jacobian, mass: &MassMatrix, tau0: &Joints) -> Option<Joints> {
    let m = mass.cholesky()?;
    let m_inv_jt = m.solve(&jacobian.transpose());
    let lambda_inv = jacobian * m_inv_jt;
    let l = lambda_inv.cholesky()?;
    let m_inv_tau0 = m.solve(tau0);
    let acc = jacobian * m_inv_tau0;
    Some(tau0 - jacobian.transpose() * l.solve(&acc))
}

/// The FR3's limits on the commanded joint torque (Franka's datasheet, as franky-sim and
/// libfranka state them: ±87 N·m on joints 1–4, ±12 N·m on 5–7) and its rate
/// (libfranka's `kMaxTorqueRate`, 1 000 N·m/s per joint).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueLimits {
    /// |τ| per joint (N·m).
    pub torque_nm: Joints,
    /// |τ̇| per joint (N·m/s).
    pub rate_nm_per_s: Joints,
}

impl TorqueLimits {
    /// The FR3's.
    #[must_use]
    pub fn fr3() -> Self {
        Self {
            torque_nm: Joints::from([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]),
            rate_nm_per_s: Joints::repeat(1000.0),
        }
    }
}

/// A command after [`limit_torques`]: which joints were cut by magnitude, by rate, and which
/// were not finite (bit j for joint j).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limited {
    /// The torque to send (N·m).
    pub torque_nm: Joints,
    /// Joints held at their torque limit.
    pub saturated: u8,
    /// Joints whose change was cut to the rate limit.
    pub rate_limited: u8,
    /// Joints whose wanted torque was not finite (the last command kept).
    pub non_finite: u8,
}

/// The command for `wanted` after `last` (the torque commanded one cycle of `dt_s` seconds
/// before, as the robot reports it): a non-finite entry keeps the last one; then each entry is
/// held within ±`torque_nm`, and its change within `rate_nm_per_s · dt_s`. `last` within the
/// magnitude limits gives a result within them.
#[must_use]
pub fn limit_torques(wanted: &Joints, last: &Joints, limits: &TorqueLimits, dt_s: f64) -> Limited {
    let mut out = Limited {
        torque_nm: *last,
        saturated: 0,
        rate_limited: 0,
        non_finite: 0,
    };
    for j in 0..7 {
        let bit = 1u8 << j;
        let mut t = wanted[j];
        if !t.is_finite() {
            out.non_finite |= bit;
            t = last[j];
        }
        let cap = limits.torque_nm[j];
        if t.abs() > cap {
            out.saturated |= bit;
            t = t.clamp(-cap, cap);
        }
        let step = limits.rate_nm_per_s[j] * dt_s.max(0.0);
        if (t - last[j]).abs() > step {
            out.rate_limited |= bit;
            t = last[j] + (t - last[j]).clamp(-step, step);
        }
        out.torque_nm[j] = t;
    }
    out
}

#[cfg(test)]
#[path = "task_plane_tests.rs"]
mod tests;
