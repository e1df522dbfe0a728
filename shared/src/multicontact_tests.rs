use super::*;

/// With a general (non-diagonal) stiffness, three signed dither responses give P exactly.
#[test]
fn rotation_centre_is_exact_for_linear_responses() {
    let k = nalgebra::Matrix2::new(8000.0, 1500.0, 1500.0, 5000.0);
    let j = nalgebra::Matrix2::new(0.0, -1.0, 1.0, 0.0);
    let p = Vec2::new(0.013, -0.021);
    let g = |c: Vec2| -(k * j * (p - c));
    let cs = [
        Vec2::new(0.0, 0.0),
        Vec2::new(0.01, 0.0),
        Vec2::new(0.0, 0.01),
    ];
    let est = rotation_centre(&cs, &cs.map(g)).unwrap();
    assert!((est - p).norm() < 1e-12, "{est:?}");
    let two: Vec<Vec2> = cs[..2].iter().map(|c| g(*c)).collect();
    assert!(rotation_centre(&cs[..2], &two).is_none());
}

/// The unsigned form with diagonal stiffness finds P among its four candidates using the
/// third dither, where P lies on either side of the dither centres.
#[test]
fn thesis_form_picks_the_right_root_with_the_third_dither() {
    let (kx, ky) = (7000.0, 4000.0);
    for p in [
        Vec2::new(0.013, -0.021),
        Vec2::new(-0.004, 0.017),
        Vec2::new(0.03, 0.002),
    ] {
        let rms = |c: Vec2| [kx * (p.y - c.y).abs(), ky * (p.x - c.x).abs()];
        let c0 = Vec2::new(0.0, 0.0);
        let c1 = Vec2::new(0.01, 0.01);
        let c2 = Vec2::new(-0.01, 0.005);
        let est = thesis_rotation_centre(c0, c1, c2, [rms(c0), rms(c1), rms(c2)]).unwrap();
        assert!((est - p).norm() < 1e-12, "{p:?}: {est:?}");
    }
}

/// The friction filter recovers the split of a synthetic wrench: normal resultant through
/// P, friction perpendicular to it through R.
#[test]
fn friction_filter_recovers_the_split() {
    let r = Vec2::new(0.0, 0.0);
    let p = Vec2::new(0.02, 0.035);
    for (fnv, mu) in [
        (Vec2::new(1.5, 2.0), 0.3),
        (Vec2::new(-0.5, 2.5), -0.2),
        (Vec2::new(2.0, 0.3), 0.6),
    ] {
        let ft = perp(fnv) * mu;
        // Moments about R: normal resultant through P, friction through R.
        let m_r = cross(p - r, fnv);
        let (n, t) = friction_filter(fnv + ft, m_r, p - r).unwrap();
        assert!(
            (n - fnv).norm() < 1e-12 && (t - ft).norm() < 1e-12,
            "{n:?} {t:?}"
        );
    }
}

/// Eq. 5.29's roots: one is the true θ̄, the other its mirror 90° − β − θ̄; writing β for
/// tan β (as printed) moves the roots by O(β³).
#[test]
fn eq_5_29_has_the_true_angle_and_its_mirror() {
    let beta = 8f64.to_radians();
    for theta_deg in [10.0f64, 25.0, 55.0, 70.0] {
        let th = theta_deg.to_radians();
        let r = th.tan() / (th + beta).tan();
        let roots = eq_5_29_roots(r, beta.tan()).unwrap();
        let angles = roots.map(|t| t.atan().to_degrees());
        let mirror = 90.0 - beta.to_degrees() - theta_deg;
        let has = |a: f64| angles.iter().any(|x| (x - a).abs() < 1e-9);
        assert!(has(theta_deg) && has(mirror), "{theta_deg}: {angles:?}");
        assert!((roots[0] * roots[1] - r).abs() < 1e-12);
        let printed = eq_5_29_roots(r, beta)
            .unwrap()
            .map(|t| t.atan().to_degrees());
        let off = printed
            .iter()
            .map(|p| {
                angles
                    .iter()
                    .fold(f64::INFINITY, |m, a| m.min((p - a).abs()))
            })
            .fold(0.0f64, f64::max);
        assert!(
            off > 1e-4 && off < 0.5,
            "{theta_deg}: printed form off by {off}°"
        );
    }
}

/// Eq. 5.17 derived: with F_Tx = p F_Ty − c (eq. 5.18, from M_s = F_N × P with R at the
/// origin) and F_T · F_N = 0, the true F_Ty satisfies
/// `F_Ty²(1 + p²) = F_Ty(2cp + p F_x + F_y) − (c² + c F_x)`; the printed M² in place of c²
/// does not hold.
#[test]
fn eq_5_17_has_c_squared_not_m_squared() {
    let p_c = Vec2::new(0.02, 0.035);
    let f_n = Vec2::new(1.5, 2.0);
    let f_t = perp(f_n) * 0.3;
    let f = f_n + f_t;
    // Thesis order: A × B = A_x B_y − A_y B_x.
    let m = f_n.x * p_c.y - f_n.y * p_c.x;
    let p = p_c.x / p_c.y;
    let c = m / p_c.y - f.x + p * f.y;
    assert!((f_t.x - (p * f_t.y - c)).abs() < 1e-12, "eq. 5.18");
    let lhs = f_t.y * f_t.y * (1.0 + p * p);
    let rhs = |k: f64| f_t.y * (2.0 * c * p + p * f.x + f.y) - (k + c * f.x);
    assert!((lhs - rhs(c * c)).abs() < 1e-12, "corrected eq. 5.17");
    assert!((lhs - rhs(m * m)).abs() > 1e-3, "printed eq. 5.17");
}

/// The filter's assumption F_T ⊥ F_N, justified: a box rotating about P = (a, b) with a
/// floor contact at (a, 0) and a wall contact at (0, b), both sliding with the same μ, has
/// friction resultant μ·J·F_N, exactly perpendicular, and the filter recovers the split.
/// With unequal μ, or friction below μN (sticking), the assumption and the split fail.
#[test]
fn friction_is_perpendicular_to_the_normals_for_equal_sliding_friction() {
    let (a, b) = (0.03, 0.05);
    let (n_floor, n_wall) = (2.0, 1.2);
    let split = |mu_floor: f64, mu_wall: f64, omega: f64| {
        // Contact velocities ω J (c − P): floor (ω b, 0), wall (0, −ω a).
        let v_floor = omega * b;
        let v_wall = -omega * a;
        let f_n = Vec2::new(n_wall, n_floor);
        let f_t = Vec2::new(
            -mu_floor * n_floor * v_floor.signum(),
            -mu_wall * n_wall * v_wall.signum(),
        );
        (f_n, f_t)
    };
    let p_c = Vec2::new(a, b);
    for omega in [1.0, -1.0] {
        let (f_n, f_t) = split(0.4, 0.4, omega);
        assert!(f_n.dot(&f_t).abs() < 1e-12);
        // Moment about R = (0, 0): the normal forces act through P, friction through R.
        let m_r = cross(p_c, f_n);
        let (n, t) = friction_filter(f_n + f_t, m_r, p_c).unwrap();
        assert!((n - f_n).norm() < 1e-12 && (t - f_t).norm() < 1e-12);
    }
    let (f_n, f_t) = split(0.4, 0.1, 1.0);
    assert!(f_n.dot(&f_t).abs() > 0.1);
    let (n, _) = friction_filter(f_n + f_t, cross(p_c, f_n), p_c).unwrap();
    assert!((n - f_n).norm() > 0.05, "{n:?} vs {f_n:?}");
}

/// At rest in the corner with a preload the box's contacts are one floor and one wall
/// vertex and the true rotation centre is where their normals cross.
#[test]
fn box_in_corner_has_two_contacts_and_a_centre() {
    let params = BoxParams::default();
    let theta = 20f64.to_radians();
    let touch = BoxPlant::touching_pose(&params, theta);
    let mut b = BoxPlant::new(params, touch);
    let push = [touch[0] - 0.0008, touch[1] - 0.0008, theta];
    for _ in 0..20000 {
        b.step(push, [0.0; 3], 1e-4);
    }
    let t = b.truth();
    assert_eq!(t.contacts, [1, 1]);
    let bl = to_world(&b.pose(), corners_body(params.size_m)[0]);
    let tl = to_world(&b.pose(), corners_body(params.size_m)[3]);
    let pc = t.rotation_centre.unwrap();
    assert!((pc.x - bl.x).abs() < 1e-12 && (pc.y - tl.y).abs() < 1e-12);
    assert!(t.force.x > 0.5 && t.force.y > 0.5, "{:?}", t.force);
}
