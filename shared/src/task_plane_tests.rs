use super::*;
use nalgebra::{Matrix3, Rotation3, SMatrix, Vector2, Vector3};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, Uniform};

fn u(rng: &mut ChaCha8Rng, low: f64, high: f64) -> f64 {
    Uniform::new(low, high).expect("low < high").sample(rng)
}

fn rot(axis: Vector3<f64>, angle: f64) -> Matrix3<f64> {
    *Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle).matrix()
}

/// A tilted plane (not one of the base's), its origin away from the base, the tool pointing
/// into it.
fn plane() -> TaskPlane {
    let r = Rotation3::from_euler_angles(0.3, -0.2, 1.1);
    TaskPlane::new(
        *r.matrix(),
        Vector3::new(0.45, -0.1, 0.2),
        rot(Vector3::x(), std::f64::consts::PI),
    )
    .expect("a rotation")
}

fn random_joints(rng: &mut ChaCha8Rng, scale: f64) -> Joints {
    Joints::from_fn(|_, _| u(rng, -scale, scale))
}

fn random_jacobian(rng: &mut ChaCha8Rng) -> Jacobian {
    Jacobian::from_fn(|_, _| u(rng, -1.0, 1.0))
}

/// A symmetric positive-definite mass matrix: `A Aᵀ + 0.1 I`.
fn random_mass(rng: &mut ChaCha8Rng) -> MassMatrix {
    let a = MassMatrix::from_fn(|_, _| u(rng, -1.0, 1.0));
    a * a.transpose() + MassMatrix::identity() * 0.1
}

#[test]
fn the_planar_coordinates_invert_the_pose() {
    let pl = plane();
    let (j, dq) = (Jacobian::zeros(), Joints::zeros());
    for &(x, y, theta, z) in &[
        (0.0, 0.0, 0.0, 0.0),
        (0.12, -0.03, 0.4, 0.002),
        (-0.2, 0.31, -2.9, -0.01),
        (0.05, 0.05, 3.1, 0.0),
    ] {
        let (r, p) = pl.pose(Vector2::new(x, y), theta, z);
        let s = pl.planar(&r, &p, &j, &dq);
        assert!((s.position_m - Vector2::new(x, y)).amax() < 1e-12, "{s:?}");
        assert!((s.theta_rad - theta).abs() < 1e-12, "{s:?}");
        assert!((s.normal_m - z).abs() < 1e-12, "{s:?}");
        assert!(s.tilt_rad.amax() < 1e-12, "{s:?}");
    }
}

/// `R_T = R_P exp([a, b, 0]^) Rz(θ) R_m`: θ and the tilt (a, b) about the plane's axes come
/// back exactly, the rotation vector's z component being zero at the maximising θ (module
/// docs).
#[test]
fn a_tilt_reads_as_its_rotation_vector_and_leaves_theta() {
    let pl = plane();
    let (j, dq) = (Jacobian::zeros(), Joints::zeros());
    for &(theta, a, b) in &[(0.3, 0.05, 0.0), (-1.2, 0.0, -0.08), (2.5, 0.2, 0.1)] {
        let tilt = Rotation3::new(Vector3::new(a, b, 0.0));
        let r = pl.rotation() * tilt.matrix() * rot(Vector3::z(), theta) * pl.mount;
        let s = pl.planar(&r, &Vector3::zeros(), &j, &dq);
        assert!((s.theta_rad - theta).abs() < 1e-12, "{theta} {s:?}");
        assert!((s.tilt_rad - Vector2::new(a, b)).amax() < 1e-12, "{s:?}");
    }
}

/// The rates from the twist `J q̇` are the time derivatives of the coordinates: a tool moving
/// with a constant twist `(v, ω)` (base frame, `R(t) = exp([ω]t) R(0)`), differentiated by a
/// central difference.
#[test]
fn the_rates_are_the_coordinates_derivatives() {
    let pl = plane();
    let (r0, p0) = pl.pose(Vector2::new(0.1, 0.02), 0.7, 0.0);
    let v = Vector3::new(0.03, -0.02, 0.01);
    let w = Vector3::new(0.02, -0.01, 0.4);
    let mut j = Jacobian::zeros();
    j.fixed_view_mut::<3, 1>(0, 0).copy_from(&v);
    j.fixed_view_mut::<3, 1>(3, 0).copy_from(&w);
    let dq = Joints::from([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let at = |t: f64| {
        let r = Rotation3::new(w * t).matrix() * r0;
        pl.planar(&r, &(p0 + v * t), &Jacobian::zeros(), &Joints::zeros())
    };
    let h = 1e-5;
    let (a, b) = (at(-h), at(h));
    let s = pl.planar(&r0, &p0, &j, &dq);
    let d = |x: f64, y: f64| (y - x) / (2.0 * h);
    let vx = d(a.position_m.x, b.position_m.x);
    let vy = d(a.position_m.y, b.position_m.y);
    assert!(
        (s.velocity_m_per_s - Vector2::new(vx, vy)).amax() < 1e-8,
        "{s:?}"
    );
    assert!((s.normal_velocity_m_per_s - d(a.normal_m, b.normal_m)).abs() < 1e-8);
    assert!((s.theta_rate_rad_per_s - d(a.theta_rad, b.theta_rad)).abs() < 1e-8);
    let tilt_rate = Vector2::new(d(a.tilt_rad.x, b.tilt_rad.x), d(a.tilt_rad.y, b.tilt_rad.y));
    assert!(
        (s.tilt_rate_rad_per_s - tilt_rate).amax() < 1e-8,
        "{s:?} {tilt_rate}"
    );
}

/// The hold's wrench: 1 cm past the target along the normal at 1 kN/m is 10 N back along the
/// normal; a tilt of 0.1 rad about the plane's x axis at 20 N·m/rad is 2 N·m back about it;
/// the planar command goes along the plane's axes.
#[test]
fn the_holds_wrench_pushes_back_along_the_planes_axes() {
    let pl = plane();
    let hold = Hold {
        normal_stiffness_n_per_m: 1000.0,
        normal_damping_n_s_per_m: 0.0,
        tilt_stiffness_nm_per_rad: 20.0,
        tilt_damping_nm_s_per_rad: 0.0,
        null_stiffness_nm_per_rad: 0.0,
        null_damping_nm_s_per_rad: 0.0,
    };
    let s = PlanarState {
        normal_m: 0.011,
        tilt_rad: Vector2::new(0.1, 0.0),
        ..Default::default()
    };
    let w = pl.wrench(&s, Vector2::new(3.0, 0.0), 0.5, 0.001, &hold);
    let (x, n) = (pl.rotation().column(0), pl.rotation().column(2));
    let f = x * 3.0 - n * 10.0;
    let m = -x * 2.0 + n * 0.5;
    assert!((w.fixed_rows::<3>(0) - f).amax() < 1e-12, "{w}");
    assert!((w.fixed_rows::<3>(3) - m).amax() < 1e-12, "{w}");
}

/// The task torque does the wrench's work (`τ·q̇ = W·J q̇`) and the null-space term adds no
/// acceleration at the tool (`J M⁻¹ N τ₀ = 0`), on random Jacobians and mass matrices.
#[test]
fn the_null_space_term_leaves_the_tool_alone_and_the_task_term_does_the_wrenchs_work() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let hold = Hold {
        normal_stiffness_n_per_m: 0.0,
        normal_damping_n_s_per_m: 0.0,
        tilt_stiffness_nm_per_rad: 0.0,
        tilt_damping_nm_s_per_rad: 0.0,
        null_stiffness_nm_per_rad: 10.0,
        null_damping_nm_s_per_rad: 2.0,
    };
    for _ in 0..50 {
        let (j, m) = (random_jacobian(&mut rng), random_mass(&mut rng));
        let (q, dq, qn) = (
            random_joints(&mut rng, 1.0),
            random_joints(&mut rng, 1.0),
            random_joints(&mut rng, 1.0),
        );
        let w = SVector::<f64, 6>::from_fn(|_, _| u(&mut rng, -5.0, 5.0));
        let c = random_joints(&mut rng, 0.5);
        let (tau, full) = joint_torques(&j, &m, &c, &q, &dq, &qn, &w, &hold);
        assert!(full);
        let null = tau - j.transpose() * w - c;
        let tool = j * m.cholesky().unwrap().solve(&null);
        assert!(tool.amax() < 1e-9 * (1.0 + null.amax()), "{tool}");
        let tau0 = -(q - qn) * 10.0 - dq * 2.0;
        assert!(
            (null - tau0).amax() > 1e-3,
            "the projection changed nothing"
        );
        let power = (tau - null - c).dot(&dq);
        assert!((power - w.dot(&(j * dq))).abs() < 1e-9 * (1.0 + power.abs()));
    }
}

#[test]
fn a_singular_jacobian_drops_the_null_space_term() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut j = random_jacobian(&mut rng);
    j.row_mut(4).fill(0.0);
    let m = random_mass(&mut rng);
    assert!(null_space(&j, &m, &Joints::repeat(1.0)).is_none());
    let hold = Hold {
        normal_stiffness_n_per_m: 0.0,
        normal_damping_n_s_per_m: 0.0,
        tilt_stiffness_nm_per_rad: 0.0,
        tilt_damping_nm_s_per_rad: 0.0,
        null_stiffness_nm_per_rad: 10.0,
        null_damping_nm_s_per_rad: 0.0,
    };
    let w = SVector::<f64, 6>::repeat(1.0);
    let q = Joints::repeat(0.3);
    let (tau, full) = joint_torques(
        &j,
        &m,
        &Joints::zeros(),
        &q,
        &q,
        &Joints::zeros(),
        &w,
        &hold,
    );
    assert!(!full);
    assert!((tau - j.transpose() * w).amax() < 1e-12);
}

/// A step to 200 N·m on joint 1 from rest at 1 kHz: 1 N·m per cycle (1 000 N·m/s), held at
/// 87 N·m from the 87th cycle (the last one cut by rate is the 86th); joint 5 stops at 12 N·m; a NaN keeps the last command.
#[test]
fn the_limits_cut_the_rate_then_hold_the_magnitude() {
    let limits = TorqueLimits::fr3();
    let wanted = Joints::from([200.0, 0.0, 0.0, 0.0, -30.0, 0.0, f64::NAN]);
    let mut last = Joints::from([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]);
    for cycle in 1..=100 {
        let out = limit_torques(&wanted, &last, &limits, 1e-3);
        assert_eq!(out.non_finite, 1 << 6);
        assert_eq!(out.torque_nm[6], 2.0);
        let expected = f64::from(cycle).min(87.0);
        assert!(
            (out.torque_nm[0] - expected).abs() < 1e-9,
            "{cycle}: {out:?}"
        );
        assert!((out.torque_nm[4] + f64::from(cycle).min(12.0)).abs() < 1e-9);
        assert_eq!(out.saturated & 1, 1);
        assert_eq!(out.rate_limited & 1, u8::from(cycle < 87));
        last = out.torque_nm;
    }
}

#[test]
fn limited_commands_stay_within_both_limits() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let limits = TorqueLimits::fr3();
    for _ in 0..1000 {
        let last = Joints::from_fn(|j, _| u(&mut rng, -1.0, 1.0) * limits.torque_nm[j]);
        let wanted = random_joints(&mut rng, 200.0);
        let dt = u(&mut rng, 0.0, 2e-3);
        let out = limit_torques(&wanted, &last, &limits, dt);
        for j in 0..7 {
            let t = out.torque_nm[j];
            assert!(t.abs() <= limits.torque_nm[j] + 1e-12);
            assert!((t - last[j]).abs() <= 1000.0 * dt + 1e-12);
            if out.saturated & (1 << j) == 0 && out.rate_limited & (1 << j) == 0 {
                assert_eq!(t, wanted[j]);
            }
        }
    }
}

/// The rotation vector of `exp([v]×)` is v, from 1e-9 rad to 3 rad, to 1e-12 relative at
/// small angles (where an arccosine of the trace keeps half the digits).
#[test]
fn the_rotation_vector_inverts_the_exponential() {
    let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
    for &angle in &[1e-9, 1e-6, 1e-3, 0.1, 1.0, 2.0, 3.0] {
        let v = axis * angle;
        let back = rotation_vector(Rotation3::new(v).matrix());
        assert!(
            (back - v).amax() <= 1e-12 * angle.max(1e-3),
            "{angle}: {back}"
        );
    }
    assert_eq!(rotation_vector(&Matrix3::identity()), Vector3::zeros());
}

#[test]
fn a_frame_that_is_not_a_rotation_is_refused_by_name() {
    let good = Matrix3::identity();
    let scaled = good * 1.01;
    let reflected = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
    let e = TaskPlane::new(scaled, Vector3::zeros(), good).unwrap_err();
    assert!(
        e.to_string()
            .contains("task plane's rotation is not a rotation"),
        "{e}"
    );
    let e = TaskPlane::new(good, Vector3::zeros(), reflected).unwrap_err();
    assert!(matches!(e, FrameError::NotARotation { what: "tool's mount", det, .. } if det < 0.0));
    let e = TaskPlane::new(good, Vector3::new(0.0, f64::NAN, 0.0), good).unwrap_err();
    assert_eq!(
        e,
        FrameError::NotFinite {
            what: "task plane's origin"
        }
    );
    let mut nan = good;
    nan[(1, 2)] = f64::INFINITY;
    assert!(matches!(
        TaskPlane::new(nan, Vector3::zeros(), good),
        Err(FrameError::NotFinite { .. })
    ));
}

/// The planar gains' closed forms: `k = Λ ω²`, `d = 2 ζ Λ ω`; a bandwidth past the sampling's
/// limit is held there, with `d Δt / Λ` exactly the limit; bad inputs get none.
#[test]
fn the_planar_gains_are_the_inertias_mass_spring_damper() {
    let inertia = Vector3::new(2.0, 3.0, 1.2e-4);
    let (zeta, dt) = (0.7, 1e-3);
    let g = planar_gains(&inertia, 5.0, zeta, dt).unwrap();
    let w = std::f64::consts::TAU * 5.0;
    assert_eq!(g.natural_frequency_rad_per_s, w);
    for i in 0..3 {
        assert!((g.stiffness[i] - inertia[i] * w * w).abs() <= 1e-12 * g.stiffness[i]);
        assert!((g.damping[i] - 2.0 * zeta * inertia[i] * w).abs() <= 1e-12 * g.damping[i]);
    }
    let fast = planar_gains(&inertia, 100.0, zeta, dt).unwrap();
    let cap = DISCRETE_DAMPING_LIMIT / (2.0 * zeta * dt);
    assert!(cap < std::f64::consts::TAU * 100.0);
    assert_eq!(fast.natural_frequency_rad_per_s, cap);
    for i in 0..3 {
        let pole = fast.damping[i] * dt / inertia[i];
        assert!((pole - DISCRETE_DAMPING_LIMIT).abs() < 1e-12, "{pole}");
    }
    let bad = [
        (Vector3::new(0.0, 3.0, 1e-4), 5.0, zeta, dt),
        (Vector3::new(2.0, f64::NAN, 1e-4), 5.0, zeta, dt),
        (inertia, 0.0, zeta, dt),
        (inertia, 5.0, -1.0, dt),
        (inertia, 5.0, zeta, f64::INFINITY),
    ];
    for (i, f, z, t) in bad {
        assert_eq!(planar_gains(&i, f, z, t), None, "{i:?} {f} {z} {t}");
    }
}

/// The planar inertia is the diagonal of `Λ = (J M⁻¹ Jᵀ)⁻¹` with the Jacobian's rows in the
/// plane's frame: on random arms, the same as `blockdiag(R_Pᵀ) Λ blockdiag(R_P)` by inversion;
/// a zero row (a singular arm) gives none.
#[test]
fn the_planar_inertia_is_the_task_inertia_in_the_planes_frame() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let p = plane();
    let r = *p.rotation();
    let mut r6 = SMatrix::<f64, 6, 6>::zeros();
    r6.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    r6.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    for _ in 0..20 {
        let j = random_jacobian(&mut rng);
        let m = random_mass(&mut rng);
        let lambda = (j * m.try_inverse().unwrap() * j.transpose())
            .try_inverse()
            .unwrap();
        let want = r6.transpose() * lambda * r6;
        let got = p.planar_inertia(&j, &m).unwrap();
        for (k, idx) in [0, 1, 5].into_iter().enumerate() {
            let w = want[(idx, idx)];
            assert!((got[k] - w).abs() <= 1e-9 * w.abs(), "{got:?} vs {w}");
        }
    }
    let mut j = random_jacobian(&mut rng);
    j.row_mut(5).fill(0.0);
    assert_eq!(p.planar_inertia(&j, &random_mass(&mut rng)), None);
}
