//! One plant + sensor + controller step allocates nothing, with either tuner running (the
//! cost tuner's once-per-period model minimisation included), and neither does taking the
//! controller's snapshot, which the servo board does every tick.

use afs_shared::config::SimConfig;
use afs_shared::sim::Lockstep;
use afs_shared::tuner::{CostTunerParams, ThesisTunerParams, TunerConfig};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    // Per thread, so tests running in parallel do not count each other's allocations.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn count() {
    // `try_with`: the allocator may run while this thread's locals are being torn down.
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations_during_steps(tuner: TunerConfig) -> usize {
    let cfg = SimConfig {
        servo: afs_shared::servo::ServoParams {
            tuner,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut sim = Lockstep::new(&cfg).expect("default set-up is valid");
    sim.servo_mut().hybrid_mut().set_velocity(0.01);
    sim.servo_mut().set_a_omega(0.002);
    sim.servo_mut().set_tuning(true);
    sim.run(100);
    let before = ALLOCATIONS.with(Cell::get);
    // 1.5 s: 15 dither periods, so the cost tuner's per-period update runs several times.
    for _ in 0..15_000 {
        sim.step();
        std::hint::black_box(sim.servo().state());
    }
    ALLOCATIONS.with(Cell::get) - before
}

#[test]
fn a_step_allocates_nothing_with_the_thesis_tuner() {
    assert_eq!(
        allocations_during_steps(TunerConfig::Thesis(ThesisTunerParams::default())),
        0
    );
}

#[test]
fn a_step_allocates_nothing_with_the_cost_tuner() {
    assert_eq!(
        allocations_during_steps(TunerConfig::Cost(CostTunerParams::default())),
        0
    );
}

/// On MuJoCo too (its own C code works in its preallocated arena; this counts Rust's side:
/// the torques in, the truth and the contact forces out, the curved surface's tangent plane).
#[cfg(feature = "mujoco")]
#[test]
fn a_step_on_mujoco_allocates_nothing() {
    for shape in [
        afs_shared::surface::Shape::Plane,
        afs_shared::surface::Shape::Sinusoid {
            amplitude_m: 0.003,
            wavelength_m: 0.12,
        },
    ] {
        let mut cfg = SimConfig::default();
        cfg.world.kind = afs_shared::world::WorldKind::Mujoco;
        cfg.world.mujoco.applied_friction = true;
        cfg.surface.shape = shape;
        let mut sim = Lockstep::new(&cfg).expect("default set-up is valid");
        sim.servo_mut().hybrid_mut().set_velocity(0.01);
        sim.servo_mut().set_a_omega(0.02);
        sim.run(100);
        let before = ALLOCATIONS.with(Cell::get);
        for _ in 0..5_000 {
            sim.step();
            std::hint::black_box(sim.world().state());
        }
        assert_eq!(ALLOCATIONS.with(Cell::get) - before, 0);
    }
}

/// The seven-joint arm's cycle: its planar coordinates, the wrench, the joint torques with the
/// null-space projection (two Cholesky factorisations) and the limits.
#[test]
fn the_task_plane_cycle_allocates_nothing() {
    use afs_shared::task_plane::{
        Hold, Jacobian, Joints, MassMatrix, TaskPlane, TorqueLimits, joint_torques, limit_torques,
    };
    use nalgebra::{Matrix3, Vector2, Vector3};
    let plane = TaskPlane::new(Matrix3::identity(), Vector3::zeros(), Matrix3::identity())
        .expect("rotations");
    let hold = Hold::FR3;
    let j = Jacobian::from_fn(|r, c| ((r * 7 + c) as f64 * 0.7).sin());
    let a = MassMatrix::from_fn(|r, c| ((r * 7 + c) as f64 * 1.3).cos());
    let mass = a * a.transpose() + MassMatrix::identity();
    let limits = TorqueLimits::fr3();
    let mut last = Joints::zeros();
    let before = ALLOCATIONS.with(Cell::get);
    for k in 0..1000 {
        let q = Joints::repeat(f64::from(k) * 1e-4);
        let (r, p) = plane.pose(Vector2::new(0.01, 0.0), 0.1, 0.0);
        let s = plane.planar(&r, &p, &j, &q);
        let w = plane.wrench(&s, Vector2::new(1.0, 2.0), 0.1, 0.0, &hold);
        let (tau, _) = joint_torques(&j, &mass, &q, &q, &q, &Joints::zeros(), &w, &hold);
        last = limit_torques(&tau, &last, &limits, 1e-3).torque_nm;
        std::hint::black_box(last);
    }
    assert_eq!(ALLOCATIONS.with(Cell::get) - before, 0);
}
