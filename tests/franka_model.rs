//! The FR3's kinematics and dynamics afs will take its torques from (franka-rs's native model,
//! built from the URDF the robot serves; docs/franka.md, *The arm's model*), checked against
//! their own definitions by numerical differentiation: the Jacobian is the pose's derivative,
//! the Coriolis vector is the mass matrix's Christoffel form, the gravity vector is a gradient,
//! and a point load at the flange adds `m J_vᵀ J_v` to the mass matrix and `−m J_vᵀ g` to the
//! gravity. (tests/fci_wire.rs compares the same model with libfranka's.)

use afs_shared::task_plane::{TaskPlane, planar_gains};
use franka::model::{Frame, Model};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

type Q = SVector<f64, 7>;
type M7 = SMatrix<f64, 7, 7>;
type J6 = SMatrix<f64, 6, 7>;

const GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];
const NO_INERTIA: [f64; 9] = [0.0; 9];
const AT_FLANGE: [f64; 3] = [0.0; 3];
/// Central differences' step (rad): truncation ~h², rounding ~1e-16/h.
const H: f64 = 1e-5;

fn model() -> Model {
    Model::from_urdf(franka::model::FR3_URDF).expect("franka-rs's FR3 URDF parses")
}

/// Joint positions spread over the FR3's limits (lower, upper from its URDF), and rates.
fn states() -> Vec<(Q, Q)> {
    let lower = [-2.75, -1.79, -2.9, -3.04, -2.81, 0.55, -3.01];
    let upper = [2.75, 1.79, 2.9, -0.15, 2.81, 4.52, 3.01];
    (0..8)
        .map(|k| {
            let q = Q::from_fn(|i, _| {
                let u = 0.5 + 0.45 * ((k * 7 + i) as f64 * 1.618).sin();
                lower[i] + u * (upper[i] - lower[i])
            });
            let dq = Q::from_fn(|i, _| ((k * 5 + i) as f64 * 2.3).cos());
            (q, dq)
        })
        .collect()
}

fn arr(q: &Q) -> [f64; 7] {
    q.as_slice().try_into().unwrap()
}

fn flange_pose(m: &Model, q: &Q) -> (Matrix3<f64>, Vector3<f64>) {
    let p = m.pose_q(Frame::Flange, &arr(q), &[0.0; 16], &[0.0; 16]);
    let r = Matrix3::from_fn(|i, j| p[j * 4 + i]);
    (r, Vector3::new(p[12], p[13], p[14]))
}

fn jacobian(m: &Model, q: &Q) -> J6 {
    J6::from_column_slice(&m.zero_jacobian_q(Frame::Flange, &arr(q), &[0.0; 16], &[0.0; 16]))
}

fn mass(m: &Model, q: &Q, load_kg: f64) -> M7 {
    M7::from_column_slice(&m.mass_q(&arr(q), &NO_INERTIA, load_kg, &AT_FLANGE))
}

fn gravity(m: &Model, q: &Q, load_kg: f64) -> Q {
    Q::from_column_slice(&m.gravity_q(&arr(q), load_kg, &AT_FLANGE, &GRAVITY))
}

fn coriolis(m: &Model, q: &Q, dq: &Q) -> Q {
    Q::from_column_slice(&m.coriolis_q(&arr(q), &arr(dq), &NO_INERTIA, 0.0, &AT_FLANGE, &GRAVITY))
}

/// ∂f/∂q_k at q by central differences.
fn central<T>(f: impl Fn(&Q) -> T, q: &Q, k: usize) -> T
where
    T: std::ops::Sub<Output = T> + std::ops::Div<f64, Output = T>,
{
    (f(&step(q, k, H)) - f(&step(q, k, -H))) / (2.0 * H)
}

fn step(q: &Q, i: usize, h: f64) -> Q {
    let mut q = *q;
    q[i] += h;
    q
}

#[test]
fn the_jacobian_is_the_flange_pose_s_derivative() {
    let m = model();
    for (q, _) in states() {
        let j = jacobian(&m, &q);
        let (r0, _) = flange_pose(&m, &q);
        for i in 0..7 {
            let (rp, pp) = flange_pose(&m, &step(&q, i, H));
            let (rm, pm) = flange_pose(&m, &step(&q, i, -H));
            let v = (pp - pm) / (2.0 * H);
            // dR/dq_i · Rᵀ = [ω_i]×, the angular column in the base frame.
            let w = (rp - rm) / (2.0 * H) * r0.transpose();
            let omega = Vector3::new(
                w[(2, 1)] - w[(1, 2)],
                w[(0, 2)] - w[(2, 0)],
                w[(1, 0)] - w[(0, 1)],
            ) / 2.0;
            let column = j.column(i);
            let dv = (column.fixed_rows::<3>(0) - v).amax();
            let dw = (column.fixed_rows::<3>(3) - omega).amax();
            assert!(
                dv < 1e-8 && dw < 1e-8,
                "q {q:?}, joint {i}: linear off by {dv:e}, angular by {dw:e}"
            );
        }
    }
}

#[test]
fn the_mass_matrix_is_symmetric_and_positive_definite() {
    let m = model();
    for (q, _) in states() {
        let a = mass(&m, &q, 0.0);
        assert!((a - a.transpose()).amax() < 1e-12, "{a}");
        assert!(
            a.cholesky().is_some(),
            "not positive definite at {q:?}: {a}"
        );
    }
}

/// `c(q, q̇) = Ṁ q̇ − ½ ∂(q̇ᵀ M q̇)/∂q`, with the mass matrix's derivatives by central
/// differences.
#[test]
fn the_coriolis_vector_is_the_mass_matrix_s_christoffel_form() {
    let m = model();
    for (q, dq) in states() {
        let dm: Vec<M7> = (0..7)
            .map(|k| central(|q| mass(&m, q, 0.0), &q, k))
            .collect();
        let m_dot: M7 = (0..7).map(|k| dm[k] * dq[k]).sum();
        let half_gradient = Q::from_fn(|i, _| 0.5 * (dq.transpose() * dm[i] * dq)[(0, 0)]);
        let expected = m_dot * dq - half_gradient;
        let got = coriolis(&m, &q, &dq);
        let d = (got - expected).amax();
        assert!(
            d < 1e-6 * (1.0 + expected.amax()),
            "q {q:?}: {got} against {expected} ({d:e})"
        );
    }
}

/// The gravity vector is the potential's gradient: its derivative is symmetric.
#[test]
fn the_gravity_vector_is_a_gradient() {
    let m = model();
    for (q, _) in states() {
        let columns: Vec<Q> = (0..7)
            .map(|k| central(|q| gravity(&m, q, 0.0), &q, k))
            .collect();
        let d = M7::from_columns(&columns);
        let asymmetry = (d - d.transpose()).amax();
        assert!(
            asymmetry < 1e-6 * (1.0 + d.amax()),
            "q {q:?}: {d} ({asymmetry:e})"
        );
    }
}

/// A point mass m at the flange's origin adds `m J_vᵀ J_v` to M and `−m J_vᵀ g` to the gravity
/// vector (V = −m gᵀ p, J_v the flange Jacobian's linear rows).
#[test]
fn a_load_at_the_flange_adds_its_closed_forms() {
    let m = model();
    let load = 2.5;
    let g = Vector3::from(GRAVITY);
    for (q, _) in states() {
        let jv = jacobian(&m, &q).fixed_rows::<3>(0).into_owned();
        let dm = mass(&m, &q, load) - mass(&m, &q, 0.0);
        let want_m = jv.transpose() * jv * load;
        assert!(
            (dm - want_m).amax() < 1e-9,
            "q {q:?}: {dm} against {want_m}"
        );
        let dg = gravity(&m, &q, load) - gravity(&m, &q, 0.0);
        let want_g = -(jv.transpose() * g) * load;
        assert!(
            (dg - want_g).amax() < 1e-9,
            "q {q:?}: {dg} against {want_g}"
        );
    }
}

/// The ready pose, and the task plane through the flange there: horizontal, θ = 0 at the
/// flange's orientation.
const READY: [f64; 7] = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
const THETA_TARGET: f64 = 0.2;

/// The planar gains of a loop: stiffness and damping along x, y and about the normal, from the
/// plane, the Jacobian and the mass matrix at the current pose.
type Gains = dyn Fn(&TaskPlane, &J6, &M7) -> (Vector3<f64>, Vector3<f64>);

/// Fixed gains: 600 N/m and 50 N·s/m in the plane, θ's as given.
fn fixed(theta: (f64, f64)) -> impl Fn(&TaskPlane, &J6, &M7) -> (Vector3<f64>, Vector3<f64>) {
    move |_, _, _| {
        (
            Vector3::new(600.0, 600.0, theta.0),
            Vector3::new(50.0, 50.0, theta.1),
        )
    }
}

/// The task-plane torque law (`afs_shared::task_plane`, docs/franka.md) closed on this model
/// for `cycles` at 1 kHz, from the ready pose, gravity compensated as the robot does,
/// `M q̈ = τ − c`: a planar PD (standing in for the thesis's controller; θ's stiffness and
/// damping given) toward 3 cm, −2 cm and 0.2 rad, the hold on height, tilt and the null
/// space, every command through the FR3's limits. Returns the last state and the largest θ
/// error after the first 0.1 s.
fn close_the_loop(gains: &Gains, cycles: usize) -> (afs_shared::task_plane::PlanarState, f64) {
    use afs_shared::task_plane::{Hold, TorqueLimits, joint_torques, limit_torques};
    use nalgebra::Vector2;
    let m = model();
    let ready = Q::from(READY);
    let (r0, p0) = flange_pose(&m, &ready);
    let plane = TaskPlane::new(Matrix3::identity(), p0, r0).expect("rotations");
    let hold = Hold::FR3;
    let target = Vector2::new(0.03, -0.02);
    let limits = TorqueLimits::fr3();
    let dt = 1e-3;
    let (mut q, mut dq, mut last) = (ready, Q::zeros(), Q::zeros());
    let (mut state, mut worst) = (None, 0.0_f64);
    for k in 0..cycles {
        let (r, p) = flange_pose(&m, &q);
        let j = jacobian(&m, &q);
        let s = plane.planar(&r, &p, &j, &dq);
        let mass = mass(&m, &q, 0.0);
        let (kp, kd) = gains(&plane, &j, &mass);
        let force = (target - s.position_m).component_mul(&kp.xy())
            - s.velocity_m_per_s.component_mul(&kd.xy());
        let moment = (THETA_TARGET - s.theta_rad) * kp.z - s.theta_rate_rad_per_s * kd.z;
        let w = plane.wrench(&s, force, moment, 0.0, &hold);
        let c = coriolis(&m, &q, &dq);
        let (tau, full) = joint_torques(&j, &mass, &c, &q, &dq, &ready, &w, &hold);
        if !full {
            break;
        }
        let out = limit_torques(&tau, &last, &limits, dt);
        last = out.torque_nm;
        let ddq = mass.cholesky().expect("M > 0").solve(&(last - c));
        dq += ddq * dt;
        q += dq * dt;
        if k >= 100 {
            worst = worst.max((s.theta_rad - THETA_TARGET).abs());
        }
        state = Some(s);
    }
    (state.expect("at least one cycle"), worst)
}

/// The loop above moves the flange 3 cm, −2 cm and 0.2 rad in its plane within 3 s while the
/// hold keeps its height and tilt.
#[test]
fn the_task_plane_law_moves_the_fr3_in_its_plane_and_holds_the_rest() {
    let (s, _) = close_the_loop(&fixed((2.0, 0.1)), 3000);
    assert!(
        (s.position_m - nalgebra::Vector2::new(0.03, -0.02)).amax() < 1e-3,
        "{s:?}"
    );
    assert!((s.theta_rad - THETA_TARGET).abs() < 5e-3, "{s:?}");
    assert!(s.normal_m.abs() < 1e-3, "{s:?}");
    assert!(s.tilt_rad.amax() < 5e-3, "{s:?}");
    assert!(s.velocity_m_per_s.amax() < 1e-3, "{s:?}");
}

/// θ's damping is bounded by the bare flange's inertia about the plane's normal,
/// `Λ_θθ = [(J M⁻¹ Jᵀ)⁻¹]_θθ` (docs/franka.md): a damper sampled every Δt is stable while
/// `d < 2 Λ_θθ/Δt`. At the ready pose Λ_θθ is 1.19e-4 kg·m², the bound 0.24 N·m·s/rad at
/// 1 kHz: 0.1 (below it) converges, 1 N·m·s/rad swings θ far from its target.
#[test]
fn the_theta_damping_is_bounded_by_the_flanges_inertia() {
    let m = model();
    let ready = Q::from(READY);
    let j = jacobian(&m, &ready);
    let lambda_inv = j * mass(&m, &ready, 0.0)
        .cholesky()
        .unwrap()
        .solve(&j.transpose());
    let lambda_tt = lambda_inv.try_inverse().unwrap()[(5, 5)];
    assert!((lambda_tt - 1.19e-4).abs() < 0.01e-4, "{lambda_tt:e}");
    let bound = 2.0 * lambda_tt / 1e-3;
    assert!(0.1 < bound && bound < 1.0, "{bound}");
    let (_, worst) = close_the_loop(&fixed((15.0, 1.0)), 500);
    assert!(worst > 0.2, "θ's largest error {worst} rad");
}

/// A point load at the flange adds its mass to the planar inertia along x and y and nothing
/// about the normal: `Λ' = Λ + diag(m I₃, 0)` (push-through: `(Λ⁻¹ − Λ⁻¹ (D⁻¹ + Λ⁻¹)⁻¹ Λ⁻¹)⁻¹
/// = Λ + D` for `M' = M + Jᵀ D J`), so the planar gains grow with the tool.
#[test]
fn a_flange_load_adds_its_mass_to_the_planar_inertia() {
    let m = model();
    let ready = Q::from(READY);
    let (r0, p0) = flange_pose(&m, &ready);
    let plane = TaskPlane::new(Matrix3::identity(), p0, r0).expect("rotations");
    let j = jacobian(&m, &ready);
    let bare = plane.planar_inertia(&j, &mass(&m, &ready, 0.0)).unwrap();
    let loaded = plane.planar_inertia(&j, &mass(&m, &ready, 2.0)).unwrap();
    assert!(
        (loaded.x - bare.x - 2.0).abs() < 1e-6,
        "{bare:?} {loaded:?}"
    );
    assert!(
        (loaded.y - bare.y - 2.0).abs() < 1e-6,
        "{bare:?} {loaded:?}"
    );
    assert!((loaded.z - bare.z).abs() < 1e-9, "{bare:?} {loaded:?}");
    assert!((bare.z - 1.19e-4).abs() < 0.01e-4, "{bare:?}");
}

/// θ's gains from the flange's inertia ([`planar_gains`], recomputed every cycle): asked for
/// 300 Hz, they are held to the sampling's limit (`d Δt / Λ_θθ` = 0.5, about 40 Hz at 1 kHz)
/// and the loop takes θ to its target; the same gains computed as if sampled a thousand times
/// faster (`d Δt / Λ_θθ` ≈ 3.8 at the real 1 kHz) swing θ far off, as 1 N·m·s/rad did above.
#[test]
fn theta_gains_from_the_inertia_hold_the_sampling_limit() {
    let theta_from = |dt: f64| {
        move |plane: &TaskPlane, j: &J6, m: &M7| {
            // A pose the diverging loop flings to a singularity gets no θ gains.
            let (k, d) = plane
                .planar_inertia(j, m)
                .and_then(|inertia| planar_gains(&inertia, 300.0, 1.0, dt))
                .map_or((0.0, 0.0), |g| (g.stiffness.z, g.damping.z));
            (Vector3::new(600.0, 600.0, k), Vector3::new(50.0, 50.0, d))
        }
    };
    let (s, _) = close_the_loop(&theta_from(1e-3), 3000);
    assert!((s.theta_rad - THETA_TARGET).abs() < 5e-3, "{s:?}");
    assert!(
        (s.position_m - nalgebra::Vector2::new(0.03, -0.02)).amax() < 1e-3,
        "{s:?}"
    );
    let (_, worst) = close_the_loop(&theta_from(1e-6), 500);
    assert!(worst > 0.2, "θ's largest error {worst} rad");
}

/// The thesis's controller on the FR3, one cycle at a time through `ArmCycle` (docs/franka.md,
/// *One cycle on the arm*): the servo's task drive presses the flange against a frictionless
/// wall in the plane (normal +y, stiffness `k_e`) with the preload, and moves along it at
/// `speed` (m/s) for 3 s at 1 kHz, guarded by `limits`. The wall's force reaches the arm
/// through `Jᵀ`, and a sensor on the flange reads it in its own frame. At the start the wall
/// is pressed with 1.5 times the preload, and the flange moves along x at `kick` (m/s).
struct Pressed {
    /// The contact force after every cycle (N).
    forces: Vec<f64>,
    /// The last planar state.
    state: afs_shared::task_plane::PlanarState,
    /// The guard's trip, if it tripped.
    tripped: Option<(
        afs_shared::robot_guard::Trip,
        afs_shared::robot_guard::HoldPose,
    )>,
    /// The planar stiffness the hold and the drive use (N/m, x and y; N·m/rad).
    stiffness: Vector3<f64>,
    /// The largest change of a joint's command from one cycle to the next (N·m).
    largest_step_nm: f64,
    /// Cycles in which the rate limit cut a joint's command.
    rate_limited_cycles: usize,
}

fn press_the_wall(
    k_e: f64,
    speed: f64,
    kick: f64,
    limits: afs_shared::robot_guard::GuardLimits,
) -> Pressed {
    use afs_shared::robot_cycle::{ArmCycle, ArmCycleParams, ArmState};
    use afs_shared::robot_guard::Guard;
    use afs_shared::sensor::Wrench;
    use afs_shared::servo::{ServoCore, ServoParams, TaskDrive};
    use afs_shared::task_plane::{Hold, TorqueLimits};
    use nalgebra::Vector2;
    const SUBSTEPS: usize = 10;
    let m = model();
    let ready = Q::from(READY);
    let (r0, p0) = flange_pose(&m, &ready);
    let plane = TaskPlane::new(Matrix3::identity(), p0, r0).expect("rotations");
    let dt = 1e-3;
    let mut params = ServoParams {
        rate_hz: 1.0 / dt,
        ..ServoParams::default()
    };
    params.hybrid.stiffness_estimate_n_per_m = k_e;
    let preload = params.hybrid.preload_n;
    // The wall stands where the flange presses it with 1.5 times the preload.
    let wall_y = 1.5 * preload / k_e;
    let contact = |y: f64| k_e * (wall_y - y).max(0.0);
    let reading = |f: f64, theta: f64| {
        let (s, c) = theta.sin_cos();
        Wrench {
            force: Vector2::new(s * f, c * f),
            torque: 0.0,
        }
    };
    let j0 = jacobian(&m, &ready);
    let inertia = plane.planar_inertia(&j0, &mass(&m, &ready, 0.0)).unwrap();
    let gains = planar_gains(&inertia, 10.0, 1.0, dt).unwrap();
    let drive = TaskDrive {
        inertia,
        gains,
        theta_rad: 0.0,
    };
    let mut servo = ServoCore::new_task(
        params,
        drive,
        Vector2::zeros(),
        reading(1.5 * preload, 0.0),
        0.0,
    )
    .expect("a valid task drive");
    servo.hybrid_mut().set_velocity(speed);
    let mut cycle = ArmCycle::new(
        plane,
        ArmCycleParams {
            hold: Hold::FR3,
            posture: ready,
            limits: TorqueLimits::fr3(),
            normal_target_m: 0.0,
            guard_gains: gains,
        },
        Guard::new(limits).expect("valid limits"),
    );
    // The joint rates that move the flange along x at `kick` and nothing else: J⁺ (kick, 0…).
    let twist = SVector::<f64, 6>::new(kick, 0.0, 0.0, 0.0, 0.0, 0.0);
    let dq0 = j0.transpose() * (j0 * j0.transpose()).cholesky().unwrap().solve(&twist);
    let (mut q, mut dq, mut last) = (ready, dq0, Q::zeros());
    let (mut forces, mut state, mut tripped) = (Vec::new(), None, None);
    let (mut largest_step_nm, mut rate_limited_cycles) = (0.0_f64, 0);
    for _ in 0..3000 {
        let (r, p) = flange_pose(&m, &q);
        let arm = ArmState {
            q,
            dq,
            last_command_nm: last,
            tool_rotation: r,
            tool_position_m: p,
            jacobian: jacobian(&m, &q),
            mass: mass(&m, &q, 0.0),
            coriolis: coriolis(&m, &q, &dq),
        };
        // The sensor turns with the tool: its reading is in the tool's θ.
        let now = plane.planar(&r, &p, &arm.jacobian, &dq);
        let y0 = now.position_m.y;
        let out = cycle.cycle(
            &mut servo,
            &arm,
            reading(contact(y0), now.theta_rad),
            true,
            dt,
        );
        assert!(out.null_space, "the arm reached a singularity");
        largest_step_nm = largest_step_nm.max((out.torque.torque_nm - last).amax());
        rate_limited_cycles += usize::from(out.torque.rate_limited != 0);
        last = out.torque.torque_nm;
        // The wall's force, sub-stepped on the flange's y in the plane, linear in q over the
        // cycle (the plane's y axis is the base frame's).
        let m_chol = arm.mass.cholesky().expect("M > 0");
        let j = arm.jacobian;
        let q_cycle = q;
        for _ in 0..SUBSTEPS {
            let y = y0 + (j.fixed_rows::<1>(1) * (q - q_cycle))[0];
            let wall = SVector::<f64, 6>::new(0.0, contact(y), 0.0, 0.0, 0.0, 0.0);
            let ddq = m_chol.solve(&(last + j.transpose() * wall - arm.coriolis));
            dq += ddq * (dt / SUBSTEPS as f64);
            q += dq * (dt / SUBSTEPS as f64);
        }
        forces.push(contact(y0));
        state = Some(out.planar);
        tripped = out.tripped;
    }
    Pressed {
        forces,
        state: state.expect("cycles ran"),
        tripped,
        stiffness: gains.stiffness,
        largest_step_nm,
        rate_limited_cycles,
    }
}

/// The guard's limits of a stack file's `[robot.limits]` defaults.
fn roomy() -> afs_shared::robot_guard::GuardLimits {
    afs_shared::robot_guard::GuardLimits {
        contact_force_n: 30.0,
        workspace_m: [[-0.15, 0.15], [-0.15, 0.15], [-0.05, 0.05]],
    }
}

fn preload() -> f64 {
    afs_shared::servo::ServoParams::default().hybrid.preload_n
}

/// Standing on 10 kN/m and 100 kN/m, from 1.5 times the preload and a kick along the wall, the
/// force loop settles the preload on the FR3 (mean of the last 0.5 s within 1 %) while the
/// impedance brings x back and holds the height and the tilt. The first cycles, from no torque
/// to the preload's, are cut by the FR3's rate limit: no joint's command changes by more than
/// 1 N·m per cycle.
#[test]
fn the_thesis_s_force_loop_holds_the_preload_on_the_fr3() {
    for k_e in [1e4, 1e5] {
        let run = press_the_wall(k_e, 0.0, 0.005, roomy());
        let tail = &run.forces[2500..];
        let mean = tail.iter().sum::<f64>() / tail.len() as f64;
        assert!(
            (mean - preload()).abs() < 0.01 * preload(),
            "k_e {k_e:e}: {mean} N"
        );
        let s = run.state;
        assert!(s.position_m.x.abs() < 1e-4, "k_e {k_e:e}: {s:?}");
        assert!(s.normal_m.abs() < 1e-3 && s.tilt_rad.amax() < 5e-3, "{s:?}");
        assert!(run.tripped.is_none(), "{:?}", run.tripped);
        assert!(run.rate_limited_cycles > 0, "the rate limit never cut");
        assert!(
            run.largest_step_nm <= 1.0 + 1e-12,
            "{} N·m",
            run.largest_step_nm
        );
    }
}

/// Moving at 5 mm/s along the wall, the FR3's flange keeps the contact force within 10 % of the
/// preload after the first 0.5 s and travels the set-point's distance.
#[test]
fn the_thesis_s_force_loop_tracks_along_a_wall_on_the_fr3() {
    for k_e in [1e4, 1e5] {
        let run = press_the_wall(k_e, 0.005, 0.0, roomy());
        let worst = run.forces[500..]
            .iter()
            .fold(0.0_f64, |w, f| w.max((f - preload()).abs() / preload()));
        assert!(worst < 0.1, "k_e {k_e:e}: worst deviation {worst}");
        assert!(
            run.state.position_m.x > 0.014,
            "k_e {k_e:e}: {:?}",
            run.state
        );
    }
}

/// Moving along the wall into the workspace box's x face at 8 mm, the guard trips there, names
/// the axis, and the hold keeps the flange on the face (within 0.5 mm after the rest of 3 s).
#[test]
fn the_guard_holds_the_fr3_on_the_workspace_s_face() {
    use afs_shared::robot_guard::{PlaneAxis, Trip};
    let mut limits = roomy();
    limits.workspace_m[0] = [-0.15, 0.008];
    let run = press_the_wall(1e4, 0.005, 0.0, limits);
    let Some((Trip::Workspace { axis, .. }, hold)) = run.tripped else {
        panic!("no workspace trip: {:?}", run.tripped);
    };
    assert_eq!(axis, PlaneAxis::X);
    assert_eq!(hold.position_m.x, 0.008);
    assert!(
        (run.state.position_m.x - 0.008).abs() < 5e-4,
        "{:?}",
        run.state
    );
}

/// A contact force above the limit (3.75 N against 3 N, at the first cycle) trips the guard,
/// which holds the pose where it tripped: the force falls to the stiffnesses in series,
/// `F₀ k_h/(k_h + k_e)` (docs/franka.md, *The guard*), here with the hold's k_h along y on
/// 10 kN/m, to 1e-6, and the normal offset stays at the hold pose's.
#[test]
fn the_guard_s_force_trip_relaxes_the_contact_on_the_fr3() {
    use afs_shared::robot_guard::Trip;
    let k_e = 1e4;
    let mut limits = roomy();
    limits.contact_force_n = 3.0;
    let run = press_the_wall(k_e, 0.0, 0.0, limits);
    let Some((Trip::ContactForce { force_n, .. }, hold)) = run.tripped else {
        panic!("no force trip: {:?}", run.tripped);
    };
    assert!((force_n - 1.5 * preload()).abs() < 1e-9, "{force_n}");
    let k_h = run.stiffness.y;
    let want = force_n * k_h / (k_h + k_e);
    let got = run.forces[2999];
    assert!(
        (got - want).abs() < 1e-6 * want,
        "{got} N, closed form {want} N (k_h {k_h} N/m)"
    );
    assert!(
        (run.state.normal_m - hold.normal_m).abs() < 1e-4,
        "{:?}",
        run.state
    );
}
