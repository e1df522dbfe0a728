//! `ArmCycle::hold_at` on an arm whose closed forms are plain: the plane is the base frame, the
//! zero Jacobian `[I₆ | 0]` (joint k moves axis k, joint 7 nothing) and the mass matrix I, so
//! that `Λ = I`, the null-space projector is `diag(0, …, 0, 1)` and, at the posture and at rest,
//! the torques are the wrench itself: `τ = (f_x, f_y, f_z, m_x, m_y, m_θ, 0)`.

use super::*;
use crate::robot_guard::{Guard, GuardLimits, PlaneAxis};
use crate::task_plane::{Joints, PlanarGains};
use nalgebra::{Matrix3, Rotation3, SMatrix, Vector2, Vector3};

const K: [f64; 3] = [1000.0, 2000.0, 3.0];
const D: [f64; 3] = [50.0, 60.0, 0.2];

fn cycle() -> ArmCycle {
    let mount = Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let plane = TaskPlane::new(Matrix3::identity(), Vector3::zeros(), *mount.matrix()).unwrap();
    ArmCycle::new(
        plane,
        ArmCycleParams {
            hold: Hold::FR3,
            posture: Joints::zeros(),
            limits: TorqueLimits {
                torque_nm: Joints::repeat(1e9),
                rate_nm_per_s: Joints::repeat(1e12),
            },
            normal_target_m: 0.0,
            guard_gains: PlanarGains {
                stiffness: Vector3::from(K),
                damping: Vector3::from(D),
                natural_frequency_rad_per_s: 1.0,
            },
        },
        Guard::new(GuardLimits {
            contact_force_n: 30.0,
            workspace_m: [[-0.1, 0.1], [-0.1, 0.1], [-0.05, 0.05]],
        })
        .unwrap(),
    )
}

/// The arm with its tool at (x, y), θ, normal offset z, at rest at the posture.
fn arm(x: f64, y: f64, theta: f64, z: f64) -> ArmState {
    let mount = Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), theta);
    let mut jacobian = SMatrix::<f64, 6, 7>::zeros();
    jacobian.fixed_columns_mut::<6>(0).fill_with_identity();
    ArmState {
        q: Joints::zeros(),
        dq: Joints::zeros(),
        last_command_nm: Joints::zeros(),
        tool_rotation: *(rz * mount).matrix(),
        tool_position_m: Vector3::new(x, y, z),
        jacobian,
        mass: MassMatrix::identity(),
        coriolis: Joints::zeros(),
    }
}

/// Held 1 cm and 2 cm off in the plane, 0.1 rad in θ and 1 mm along the normal: the torques are
/// the hold's springs, `K e` and the normal's `−k_z z`, on the joints that move those axes.
#[test]
fn hold_at_pulls_the_tool_back_by_the_hold_s_springs() {
    let mut c = cycle();
    let pose = HoldPose {
        position_m: Vector2::new(0.01, 0.02),
        theta_rad: 0.1,
        normal_m: 0.0,
    };
    let out = c.hold_at(&arm(0.0, 0.0, 0.0, 0.001), &pose, 1e-3);
    assert!(out.tripped.is_none() && out.null_space);
    let want = [
        K[0] * 0.01,
        K[1] * 0.02,
        -800.0 * 0.001,
        0.0,
        0.0,
        K[2] * 0.1,
        0.0,
    ];
    for (j, w) in want.iter().enumerate() {
        assert!(
            (out.torque.torque_nm[j] - w).abs() < 1e-9,
            "joint {j}: {} against {w}",
            out.torque.torque_nm[j]
        );
    }
}

/// A tool whose first pose is 0.3 m out along the normal trips the guard and is held where it
/// is: at rest there, nothing pulls it (the old clamp to the box's face pulled with
/// 800 N/m × 0.25 m = 200 N).
#[test]
fn hold_at_holds_a_tool_that_starts_outside_the_box_where_it_is() {
    let mut c = cycle();
    let out = c.hold_at(&arm(0.0, 0.0, 0.0, 0.3), &HoldPose::default(), 1e-3);
    let Some((Trip::Workspace { axis, .. }, hold)) = out.tripped else {
        panic!("{:?}", out.tripped);
    };
    assert_eq!(axis, PlaneAxis::Normal);
    assert!((hold.normal_m - 0.3).abs() < 1e-12, "{hold:?}");
    assert!(
        out.torque.torque_nm.amax() < 1e-9,
        "{}",
        out.torque.torque_nm
    );
}
