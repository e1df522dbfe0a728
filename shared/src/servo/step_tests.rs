//! The servo on a task-space drive, closed on a point-mass tool against a flat wall of
//! stiffness k_e (the surface's normal +y at y = 0, no friction): the drive's inertia is the
//! tool's, as `task_plane::planar_inertia` gives it for an arm.

use super::super::{ServoCore, ServoParams, TaskCommand, TaskDrive, TaskInput};
use crate::math::Vec2;
use crate::sensor::Wrench;
use crate::task_plane::planar_gains;
use nalgebra::Vector3;

const MASS_KG: f64 = 2.0;
const INERTIA_KGM2: f64 = 0.01;
const RATE_HZ: f64 = 1000.0;
/// Sub-steps of the tool's integration per servo tick (the command held over the tick).
const SUBSTEPS: usize = 20;

/// The tool: position, velocity, angle and its rate.
#[derive(Clone, Copy)]
struct Tool {
    p: Vec2,
    v: Vec2,
    theta: f64,
    omega: f64,
}

/// The wall's force on the tool (N, in the plane).
fn contact(k_e: f64, p: Vec2) -> Vec2 {
    Vec2::new(0.0, k_e * (-p.y).max(0.0))
}

/// What the sensor on the tool reads: the contact force in the tool's frame (angle θ).
fn reading(k_e: f64, tool: &Tool) -> Wrench {
    let f = contact(k_e, tool.p);
    let (s, c) = tool.theta.sin_cos();
    Wrench {
        force: Vec2::new(c * f.x + s * f.y, -s * f.x + c * f.y),
        torque: 0.0,
    }
}

fn drive(theta: f64) -> TaskDrive {
    let inertia = Vector3::new(MASS_KG, MASS_KG, INERTIA_KGM2);
    TaskDrive {
        inertia,
        gains: planar_gains(&inertia, 10.0, 1.0, 1.0 / RATE_HZ).unwrap(),
        theta_rad: theta,
    }
}

/// A servo told `k_e` that holds the angle `theta`, the tool pressing the wall with the
/// preload, kicked: moving at 5 mm/s along the wall, 0.02 rad short of `theta`.
fn start(k_e: f64, theta: f64) -> (ServoCore, Tool) {
    let mut params = ServoParams {
        rate_hz: RATE_HZ,
        ..ServoParams::default()
    };
    params.hybrid.stiffness_estimate_n_per_m = k_e;
    let preload = params.hybrid.preload_n;
    let tool = Tool {
        p: Vec2::new(0.01, -preload / k_e),
        v: Vec2::new(0.005, 0.0),
        theta: theta - 0.02,
        omega: 0.0,
    };
    let servo = ServoCore::new_task(params, drive(theta), tool.p, reading(k_e, &tool), 0.0)
        .expect("a valid task drive");
    (servo, tool)
}

/// Runs `seconds`, calling `each` with the time and the tool after every tick.
fn run(
    servo: &mut ServoCore,
    tool: &mut Tool,
    k_e: f64,
    seconds: f64,
    mut each: impl FnMut(f64, &Tool, &TaskCommand),
) {
    let dt = 1.0 / RATE_HZ;
    let h = dt / SUBSTEPS as f64;
    for i in 0..(seconds * RATE_HZ).round() as usize {
        let inp = TaskInput {
            position_m: tool.p,
            velocity_m_per_s: tool.v,
            theta_rad: tool.theta,
            theta_rate_rad_per_s: tool.omega,
            wrench: reading(k_e, tool),
            force_valid: true,
        };
        let out = servo.step_task(&inp, dt);
        for _ in 0..SUBSTEPS {
            let a = (out.force_n + contact(k_e, tool.p)) / MASS_KG;
            tool.v += a * h;
            tool.p += tool.v * h;
            tool.omega += out.moment_nm / INERTIA_KGM2 * h;
            tool.theta += tool.omega * h;
        }
        each((i + 1) as f64 * dt, tool, &out);
    }
}

/// Standing, on every stiffness from foam to steel, the force loop settles the contact force
/// at the preload (its integrator leaves no steady error), and the impedance brings x and θ
/// back from the kick.
#[test]
fn a_task_drive_holds_the_preload_from_1_kn_to_1_mn_per_m() {
    for k_e in [1e3, 1e4, 1e5, 1e6] {
        let (mut servo, mut tool) = start(k_e, 0.0);
        let preload = servo.params().hybrid.preload_n;
        let mut last = Vec::new();
        run(&mut servo, &mut tool, k_e, 3.0, |t, tool, _| {
            if t > 2.5 {
                last.push(contact(k_e, tool.p).y);
            }
        });
        let mean = last.iter().sum::<f64>() / last.len() as f64;
        let spread = last.iter().fold(0.0f64, |m, f| m.max((f - mean).abs()));
        assert!(
            (mean - preload).abs() < 1e-3 * preload && spread < 1e-3 * preload,
            "k_e {k_e:e}: mean force {mean} N, spread {spread} N, preload {preload} N"
        );
        assert!(
            (tool.p.x - 0.01).abs() < 1e-6,
            "k_e {k_e:e}: x {}",
            tool.p.x
        );
        assert!(tool.theta.abs() < 1e-6, "k_e {k_e:e}: θ {}", tool.theta);
    }
}

/// The sensor turns with the tool: at θ = 0.4 rad, the reading in the tool's frame is turned
/// back into the plane, and the loop holds the same preload (read without the turn, the
/// force along the normal would read cos 0.4 of it and the loop would settle 8 % high).
#[test]
fn a_task_drive_turns_the_sensor_reading_into_the_plane() {
    let k_e = 1e4;
    let (mut servo, mut tool) = start(k_e, 0.4);
    let preload = servo.params().hybrid.preload_n;
    run(&mut servo, &mut tool, k_e, 3.0, |_, _, _| {});
    let f = contact(k_e, tool.p).y;
    assert!((f - preload).abs() < 1e-3 * preload, "force {f} N");
    assert!((tool.theta - 0.4).abs() < 1e-6, "θ {}", tool.theta);
}

/// Moving along the wall at 5 mm/s, the tool follows the nominal motion and keeps the contact
/// force within 5 % of the preload once the start's ramp is over.
#[test]
fn a_task_drive_tracks_along_the_wall_under_force_control() {
    for k_e in [1e3, 1e5] {
        let (mut servo, mut tool) = start(k_e, 0.0);
        let preload = servo.params().hybrid.preload_n;
        servo.hybrid_mut().set_velocity(0.005);
        let mut worst = 0.0f64;
        run(&mut servo, &mut tool, k_e, 3.0, |t, tool, _| {
            if t > 0.5 {
                worst = worst.max((contact(k_e, tool.p).y - preload).abs() / preload);
            }
        });
        assert!(worst < 0.05, "k_e {k_e:e}: worst deviation {worst}");
        let set_point = servo.diag().set_point.x;
        assert!(
            (tool.p.x - set_point).abs() < 1e-4 && tool.p.x > 0.01 + 0.014,
            "k_e {k_e:e}: x {} against the set-point {set_point}",
            tool.p.x
        );
    }
}

/// A sample that is not a number freezes the force loop and leaves the command finite; an
/// inertia of zero is refused when the servo is built.
#[test]
fn a_task_drive_refuses_bad_input() {
    let (mut servo, tool) = start(1e4, 0.0);
    let mut inp = TaskInput {
        position_m: tool.p,
        velocity_m_per_s: tool.v,
        theta_rad: 0.0,
        theta_rate_rad_per_s: 0.0,
        wrench: Wrench {
            force: Vec2::new(f64::NAN, 2.5),
            torque: 0.0,
        },
        force_valid: true,
    };
    let out = servo.step_task(&inp, 1.0 / RATE_HZ);
    assert!(out.force_n.iter().all(|f| f.is_finite()) && out.moment_nm.is_finite());
    inp.position_m.x = f64::NAN;
    let out = servo.step_task(&inp, 1.0 / RATE_HZ);
    assert_eq!(out, TaskCommand::default());
    let mut bad = drive(0.0);
    bad.inertia.x = 0.0;
    let err = ServoCore::new_task(
        ServoParams::default(),
        bad,
        Vec2::zeros(),
        Wrench::default(),
        0.0,
    )
    .unwrap_err();
    assert!(err.to_string().contains("inertia"), "{err}");
}

/// The contact mode's arm side along a normal: `1/(nᵀ G⁻¹ n)` of each diagonal gain, here at
/// 30° between an x and a y axis that differ.
#[test]
fn a_task_drive_s_contact_mode_is_its_gains_along_the_normal() {
    let mut d = drive(0.0);
    d.inertia = Vector3::new(1.0, 4.0, 0.01);
    d.gains.stiffness = Vector3::new(100.0, 400.0, 1.0);
    d.gains.damping = Vector3::new(10.0, 20.0, 1.0);
    let (s, c) = 30f64.to_radians().sin_cos();
    let n = Vec2::new(c, s);
    let want = |gx: f64, gy: f64| 1.0 / (c * c / gx + s * s / gy);
    let got = d.along(n);
    for (g, w) in got
        .iter()
        .zip([want(1.0, 4.0), want(10.0, 20.0), want(100.0, 400.0)])
    {
        assert!((g - w).abs() < 1e-12 * w, "{got:?}");
    }
}
