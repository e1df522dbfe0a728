//! The solver on the FR3's chain written out from its Denavit-Hartenberg table (Craig's
//! convention, Franka's published parameters), with its geometric Jacobian: the exact model,
//! independent of franka-rs (whose model `tests/franka_model.rs` checks).

use super::*;
use std::f64::consts::FRAC_PI_2;

/// `(a_{i−1}, d_i, α_{i−1})` of joints 1..7 and the flange (m, m, rad).
const DH: [(f64, f64, f64); 8] = [
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -FRAC_PI_2),
    (0.0, 0.316, FRAC_PI_2),
    (0.0825, 0.0, FRAC_PI_2),
    (-0.0825, 0.384, -FRAC_PI_2),
    (0.0, 0.0, FRAC_PI_2),
    (0.088, 0.0, FRAC_PI_2),
    (0.0, 0.107, 0.0),
];

/// `RotX(α) TransX(a) RotZ(θ) TransZ(d)` as (rotation, translation).
fn link(a: f64, d: f64, alpha: f64, theta: f64) -> Pose {
    let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), alpha);
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), theta);
    let r = rx * rz;
    let p = rx * Vector3::new(a, 0.0, 0.0) + r * Vector3::new(0.0, 0.0, d);
    (*r.matrix(), p)
}

/// A joint's axis and origin in the base frame.
type Axis = (Vector3<f64>, Vector3<f64>);

/// Every joint's axis and origin in the base frame, and the flange's pose.
fn chain(q: &Joints) -> ([Axis; 7], Pose) {
    let mut r = Matrix3::identity();
    let mut p = Vector3::zeros();
    let mut axes = [(Vector3::zeros(), Vector3::zeros()); 7];
    for (i, &(a, d, alpha)) in DH.iter().enumerate() {
        let theta = if i < 7 { q[i] } else { 0.0 };
        let (lr, lp) = link(a, d, alpha, theta);
        p += r * lp;
        r *= lr;
        if i < 7 {
            axes[i] = (r.column(2).into_owned(), p);
        }
    }
    (axes, (r, p))
}

fn pose(q: &Joints) -> Pose {
    chain(q).1
}

fn jacobian(q: &Joints) -> Jacobian {
    let (axes, (_, p)) = chain(q);
    let mut j = Jacobian::zeros();
    for (i, (z, o)) in axes.iter().enumerate() {
        let v = z.cross(&(p - o));
        j.fixed_view_mut::<3, 1>(0, i).copy_from(&v);
        j.fixed_view_mut::<3, 1>(3, i).copy_from(z);
    }
    j
}

/// The geometric Jacobian is the pose's derivative (central differences): the chain the
/// solver is tested on is self-consistent.
#[test]
fn the_chains_jacobian_is_its_poses_derivative() {
    let q = fr3_starts()[0] + Joints::from([0.1, 0.2, -0.3, 0.1, 0.4, -0.2, 0.3]);
    let j = jacobian(&q);
    let h = 1e-5;
    for i in 0..7 {
        let mut up = q;
        let mut down = q;
        up[i] += h;
        down[i] -= h;
        let (ru, pu) = pose(&up);
        let (rd, pd) = pose(&down);
        let dp = (pu - pd) / (2.0 * h);
        let w = Rotation3::from_matrix_unchecked(ru * rd.transpose()).scaled_axis() / (2.0 * h);
        for k in 0..3 {
            assert!((dp[k] - j[(k, i)]).abs() < 1e-6, "v {k} of joint {i}");
            assert!((w[k] - j[(k + 3, i)]).abs() < 1e-6, "ω {k} of joint {i}");
        }
    }
}

/// Poses the arm has (its own pose at joint positions spread around its ready pose) are
/// reached to the tolerances, within the limits, from the ready pose or one of the others.
#[test]
fn poses_the_arm_has_are_reached_within_the_limits() {
    let limits = fr3_limits();
    for k in 0..24 {
        let q_star =
            fr3_starts()[0] + Joints::from_fn(|i, _| 0.6 * ((k * 7 + i) as f64 * 1.618).sin());
        let q_star = q_star.zip_zip_map(&limits.lower, &limits.upper, |v, lo, hi| v.clamp(lo, hi));
        let target = pose(&q_star);
        let q = reach(pose, jacobian, &target, &fr3_starts(), &limits)
            .unwrap_or_else(|m| panic!("pose {k}: {m}"));
        let e = pose_error(&target, &pose(&q));
        assert!(e.fixed_rows::<3>(0).norm() <= POSITION_TOLERANCE_M, "{k}");
        assert!(e.fixed_rows::<3>(3).norm() <= ROTATION_TOLERANCE_RAD, "{k}");
        for i in 0..7 {
            assert!(
                limits.lower[i] <= q[i] && q[i] <= limits.upper[i],
                "{k}: joint {i}"
            );
        }
    }
}

/// A point beyond the arm's reach (the flange's farthest from the shoulder is under
/// 0.316 + 0.384 + 0.107 + 2 · 0.0825 + 0.088 = 1.06 m) is missed, by at least its distance
/// past that bound.
#[test]
fn a_point_past_the_reach_is_missed_by_its_distance() {
    let shoulder = Vector3::new(0.0, 0.0, 0.333);
    let bound = 0.316 + 0.384 + 0.107 + 2.0 * 0.0825 + 0.088;
    let target = (
        *Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI).matrix(),
        shoulder + Vector3::new(1.3, 0.0, 0.0),
    );
    let m = reach(pose, jacobian, &target, &fr3_starts(), &fr3_limits()).unwrap_err();
    assert!(m.position_m >= 1.3 - bound, "{m}");
}

/// The limits bound the solution: with every joint held at the ready pose but the first,
/// free within ±0.1 rad, the ready pose turned 0.5 rad about the base is missed (by about its
/// radius times the 0.4 rad the limit keeps it short of); with the first joint free within
/// ±1 rad the same solver reaches it.
#[test]
fn the_limits_are_the_ones_that_bound_it() {
    let ready = fr3_starts()[0];
    let mut q_star = ready;
    q_star[0] = 0.5;
    let target = pose(&q_star);
    let held = |first: f64| {
        let mut l = JointLimits {
            lower: ready,
            upper: ready,
        };
        l.lower[0] = -first;
        l.upper[0] = first;
        l
    };
    let m = reach(pose, jacobian, &target, &[ready], &held(0.1)).unwrap_err();
    let radius = target.1.xy().norm();
    assert!(
        (m.position_m - 2.0 * radius * (0.2_f64).sin()).abs() < 1e-3,
        "{m}, radius {radius} m"
    );
    let q = reach(pose, jacobian, &target, &[ready], &held(1.0)).unwrap();
    assert!((q[0] - 0.5).abs() < 1e-3, "{q}");
}
