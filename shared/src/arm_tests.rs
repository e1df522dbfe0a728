use super::*;

fn arm() -> Arm {
    Arm::new(ArmParams::default())
}

#[test]
fn kinematics_round_trip_on_both_branches() {
    let a = arm();
    for &(x, y) in &[
        (0.4, 0.0),
        (0.3, 0.5),
        (-0.2, 0.6),
        (0.75, -0.1),
        (0.25, -0.1),
    ] {
        for elbow in [Elbow::Positive, Elbow::Negative] {
            let p = Vec2::new(x, y);
            let (q, pose) = a.inverse_pose(p, elbow).unwrap();
            assert!((a.forward(q) - p).norm() < 1e-12, "{p:?} {elbow:?}");
            let direct = a.pose(q);
            for (x, y) in [
                (pose.s1, direct.s1),
                (pose.c1, direct.c1),
                (pose.s12, direct.s12),
                (pose.c12, direct.c12),
            ] {
                assert!((x - y).abs() < 1e-12);
            }
        }
    }
    assert!(matches!(
        a.inverse(Vec2::new(0.9, 0.0), Elbow::Positive),
        Err(IkError::OutOfReach { .. })
    ));
    assert!(matches!(
        a.inverse(Vec2::new(f64::NAN, 0.0), Elbow::Positive),
        Err(IkError::NotFinite)
    ));
}

#[test]
fn jacobian_matches_finite_differences() {
    let a = arm();
    for &(q1, q2) in &[(0.3, -1.2), (1.0, 2.0), (-0.7, 0.4)] {
        let q = Vector2::new(q1, q2);
        let j = a.jacobian(q);
        let h = 1e-7;
        for k in 0..2 {
            let mut dq = Vector2::zeros();
            dq[k] = h;
            let col = (a.forward(q + dq) - a.forward(q - dq)) / (2.0 * h);
            assert!((col - j.column(k)).norm() < 1e-8);
        }
        let qd = Vector2::new(0.7, -1.3);
        let jd = a.jacobian_dot(q, qd);
        let num = (a.jacobian(q + qd * h) - a.jacobian(q - qd * h)) / (2.0 * h);
        assert!((jd - num).norm() < 1e-7);
    }
}

/// M(q) from the closed form equals the sum over bodies of m Jvᵀ Jv + I Jωᵀ Jω.
#[test]
fn mass_matrix_matches_body_jacobian_sum() {
    let a = arm();
    let p = a.params;
    let l1 = p.link1_length_m;
    for &(q1, q2) in &[(0.2f64, -2.2f64), (1.3, 0.5)] {
        let q = Vector2::new(q1, q2);
        let (s1, c1) = q1.sin_cos();
        let (s12, c12) = (q1 + q2).sin_cos();
        let jv1 = Matrix2::new(-p.link1_com_m * s1, 0.0, p.link1_com_m * c1, 0.0);
        let jel = Matrix2::new(-l1 * s1, 0.0, l1 * c1, 0.0);
        let lc2 = p.link2_com_m;
        let jv2 = Matrix2::new(
            -l1 * s1 - lc2 * s12,
            -lc2 * s12,
            l1 * c1 + lc2 * c12,
            lc2 * c12,
        );
        let jt = a.jacobian(q);
        let w1 = Matrix2::new(1.0, 0.0, 0.0, 0.0);
        let w2 = Matrix2::new(1.0, 1.0, 1.0, 1.0);
        let m = jv1.transpose() * jv1 * p.link1_mass_kg
            + w1 * (p.link1_inertia_kg_m2 + p.rotor1_inertia_kg_m2)
            + jel.transpose() * jel * p.elbow_mass_kg
            + jv2.transpose() * jv2 * p.link2_mass_kg
            + w2 * (p.link2_inertia_kg_m2 + p.rotor2_inertia_kg_m2)
            + jt.transpose() * jt * p.tip_mass_kg;
        assert!(
            (m - a.mass_matrix(q)).norm() < 1e-12,
            "{m} vs {}",
            a.mass_matrix(q)
        );
    }
}

/// Without damping or torque the dynamics conserve energy, and with a torque the power
/// balance dE/dt = q̇ᵀτ holds (checked by RK4 integration).
#[test]
fn dynamics_conserve_energy() {
    let params = ArmParams {
        joint_damping_nms_per_rad: [0.0, 0.0],
        ..Default::default()
    };
    let a = Arm::new(params);
    let f =
        |q: Vector2<f64>, qd: Vector2<f64>| a.acceleration(q, qd, Vector2::zeros(), Vec2::zeros());
    let (mut q, mut qd) = (Vector2::new(0.3, -1.0), Vector2::new(2.0, -3.0));
    let e0 = a.kinetic_energy(q, qd);
    let dt = 1e-4;
    for _ in 0..20000 {
        let k1 = (qd, f(q, qd));
        let k2 = (
            qd + k1.1 * dt / 2.0,
            f(q + k1.0 * dt / 2.0, qd + k1.1 * dt / 2.0),
        );
        let k3 = (
            qd + k2.1 * dt / 2.0,
            f(q + k2.0 * dt / 2.0, qd + k2.1 * dt / 2.0),
        );
        let k4 = (qd + k3.1 * dt, f(q + k3.0 * dt, qd + k3.1 * dt));
        q += (k1.0 + k2.0 * 2.0 + k3.0 * 2.0 + k4.0) * dt / 6.0;
        qd += (k1.1 + k2.1 * 2.0 + k3.1 * 2.0 + k4.1) * dt / 6.0;
    }
    let e1 = a.kinetic_energy(q, qd);
    assert!((e1 - e0).abs() < 1e-9 * e0, "{e0} -> {e1}");
}

/// At the decoupled configuration the tangential and normal directions are decoupled:
/// M12 = 0 (centre of percussion at the tip) and the Jacobian columns are orthogonal.
#[test]
fn default_arm_is_decoupled_at_the_operating_point() {
    let a = arm();
    let q = a.decoupled_configuration(0.0, Elbow::Negative).unwrap();
    let p = a.forward(q);
    assert!((p - Vec2::new(0.4, 0.0)).norm() < 1e-12);
    let j = a.jacobian(q);
    assert!(j.column(0).dot(&j.column(1)).abs() < 1e-12);
    assert!(
        a.mass_matrix(q)[(0, 1)].abs() < 1e-12,
        "M12 = {}",
        a.mass_matrix(q)[(0, 1)]
    );
    // Link 2 points along −Y: into a surface below the tip.
    assert!((a.link2_angle(q) + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
}

#[test]
fn pid_bandwidth_is_as_requested() {
    for &(inertia, bw) in &[(2.4, 3.0), (0.3, 15.0)] {
        let g = tune_pid_for_bandwidth(inertia, bw, 0.7, 0.1);
        let m = closed_loop_magnitude(&g, inertia, std::f64::consts::TAU * bw);
        assert!((m - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-9, "{m}");
        // Above the bandwidth it only falls.
        assert!(closed_loop_magnitude(&g, inertia, std::f64::consts::TAU * bw * 1.5) < m);
    }
}

#[test]
fn servo_saturates_without_windup() {
    let g = PidGains {
        kp: 100.0,
        ki: 1000.0,
        kd: 1.0,
    };
    let mut s = JointServo::new([g, g], [1.0, 1.0]);
    let z = Vector2::zeros();
    for _ in 0..10000 {
        let t = s.torque(Vector2::new(1.0, -1.0), z, z, z, z, 1e-3);
        assert!(t[0] <= 1.0 && t[1] >= -1.0);
    }
    // Integrator did not wind up: error reversal reverses the torque at once.
    let t = s.torque(Vector2::new(-0.1, 0.1), z, z, z, z, 1e-3);
    assert!(t[0] < 0.0 && t[1] > 0.0, "{t:?}");
}
