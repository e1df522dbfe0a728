//! Micro-benchmarks of the in-process hot paths.
//!
//! ```text
//! cargo bench --bench core
//! ```
//! `servo_tick` is one fast-loop tick (hybrid control, dither, tuner, IK, PID); `lockstep_step`
//! adds the plant and the sensor; `lockstep_10s` simulates 10 s at 10 kHz (the real-time factor
//! is 10 s divided by its time); `tuner_step/{cost,thesis}` is one tick of each dither tuner;
//! `tangent_estimate` is the estimator's answer to a two-probe record (200 hold samples and
//! two probes of 2 000 samples, the size the servo sends at 1 kHz). `insertion_control_tick`
//! is the insertion servo's tick (contact-state estimator and insertion controller) half-way
//! into the hole; `insertion_rig_tick` adds the peg's plant (its contact sub-steps).
//! `insertion_arm_control_tick` and `insertion_arm_rig_tick` are the same with the three-joint
//! arm carrying the wrist (`drive = "arm"`): the servo's tick adds the arm's joint servos
//! (interpolator, inverse kinematics, Jacobian, inverse dynamics, three PIDs), the plant's the
//! arm's dynamics in every sub-step. Built with `--features mujoco`,
//! `insertion_mujoco_rig_tick` and `insertion_mujoco_arm_rig_tick` are the rig's tick on
//! MuJoCo's peg (4 MuJoCo steps a tick), the latter with MuJoCo's arm carrying it (4 more).

use afs_shared::config::SimConfig;
use afs_shared::friction::FrictionLaw;
use afs_shared::insertion::controller::Phase;
use afs_shared::insertion::drive::Drive;
use afs_shared::insertion::rig::{InsertionOptions, InsertionRig};
use afs_shared::servo::ServoInput;
use afs_shared::sim::Lockstep;
use afs_shared::tangent::{self, ProbeModel, TangentParams};
use afs_shared::tuner::{ThesisTunerParams, Tuner, TunerConfig, TunerInput};
use afs_shared::world::WorldConfig;
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Duration;

fn running_sim() -> Lockstep {
    let cfg = SimConfig {
        start_u_m: -0.05,
        ..SimConfig::default()
    };
    let mut sim = Lockstep::new(&cfg).expect("default set-up");
    sim.servo_mut().hybrid_mut().set_velocity(0.01);
    sim.servo_mut().set_a_omega(0.05);
    sim.servo_mut().set_tuning(true);
    sim.run(5_000);
    sim
}

/// An insertion (default fit, seed 1, the flange driven by `drive`, in the world `world`)
/// run on noiseless readings until the peg is 5 mm in.
fn inserting_rig(drive: Drive, world: &WorldConfig) -> InsertionRig {
    let o = InsertionOptions {
        drive,
        ..InsertionOptions::default()
    };
    let mut rig = InsertionRig::on_world(&o, 1, world, 1e-4).expect("default insertion");
    while !(rig.phase() == Phase::Insert && rig.truth().depth_m > 0.005) {
        rig.step(Some(rig.sensor_wrench()), 1e-4);
        assert!(rig.time_s() < 10.0, "the insertion never got 5 mm in");
    }
    rig
}

fn benches(c: &mut Criterion) {
    let sim = running_sim();
    let (q, qd) = sim.world().joints();
    let input = ServoInput {
        q,
        qd,
        wrench: sim.truth().sensor_wrench,
        force_valid: true,
    };
    let mut servo = sim.servo().clone();
    c.bench_function("servo_tick", |b| {
        b.iter(|| black_box(servo.step(black_box(&input), 1e-4)))
    });

    // What the servo board writes to the world blackboard every tick besides the plant.
    c.bench_function("servo_state_snapshot", |b| {
        b.iter(|| black_box(black_box(&servo).state()))
    });

    let mut stepping = running_sim();
    c.bench_function("lockstep_step", |b| b.iter(|| stepping.step()));

    let mut g = c.benchmark_group("lockstep_10s");
    g.sample_size(10).measurement_time(Duration::from_secs(8));
    g.bench_function("100k_ticks", |b| {
        b.iter_batched(running_sim, |mut s| s.run(100_000), BatchSize::LargeInput)
    });
    g.finish();

    let ctx = *sim.servo().tuner_context();
    for (name, config) in [
        ("cost", TunerConfig::default()),
        ("thesis", TunerConfig::Thesis(ThesisTunerParams::default())),
    ] {
        let mut tuner = Tuner::new(&config, &ctx, 0.02);
        let mut k = 0u64;
        c.bench_function(&format!("tuner_step/{name}"), |b| {
            b.iter(|| {
                k += 1;
                let phase = (k % 1000) as f64 * std::f64::consts::TAU / 1000.0;
                let inp = TunerInput {
                    friction_n: 0.5 + 0.3 * phase.sin(),
                    velocity_m_per_s: 0.01 + 0.05 * phase.cos(),
                    nominal_m_per_s: 0.01,
                    phase,
                    period_end: k.is_multiple_of(1000),
                    normal_n: 2.5,
                };
                black_box(tuner.update(&ctx, black_box(&inp)))
            })
        });
    }

    let params = TangentParams::default();
    let plan = params.first_plan();
    let model = ProbeModel {
        alpha0: 3f64.to_radians(),
        base: 0.3,
        k: 1400.0,
        noise: 0.02,
        friction: 0.0,
        preload: 2.5,
        travel: 1.0,
        share: 1.0,
    };
    let (rec, base) = (model.record(&plan, 1), model.base);
    c.bench_function("tangent_estimate", |b| {
        b.iter(|| {
            black_box(tangent::estimate(
                black_box(&rec),
                &plan,
                base,
                &params,
                false,
            ))
        })
    });

    // Each iteration one tick from the same state half-way in (a rig left running would reach
    // the depth and idle there).
    for (drive, name) in [(Drive::Ideal, "insertion"), (Drive::Arm, "insertion_arm")] {
        let mid = inserting_rig(drive, &WorldConfig::default());
        let reading = Some(mid.sensor_wrench());
        c.bench_function(&format!("{name}_control_tick"), |b| {
            b.iter_batched_ref(
                || mid.clone(),
                |r| black_box(r.control(black_box(reading), 1e-4)),
                BatchSize::SmallInput,
            )
        });
        c.bench_function(&format!("{name}_rig_tick"), |b| {
            b.iter_batched_ref(
                || mid.clone(),
                |r| r.step(black_box(reading), 1e-4),
                BatchSize::SmallInput,
            )
        });
    }

    #[cfg(feature = "mujoco")]
    for (drive, name) in [
        (Drive::Ideal, "insertion_mujoco"),
        (Drive::Arm, "insertion_mujoco_arm"),
    ] {
        let mujoco = WorldConfig {
            kind: afs_shared::world::WorldKind::Mujoco,
            ..WorldConfig::default()
        };
        let mid = inserting_rig(drive, &mujoco);
        let reading = Some(mid.sensor_wrench());
        c.bench_function(&format!("{name}_rig_tick"), |b| {
            b.iter_batched_ref(
                || mid.clone(),
                |r| r.step(black_box(reading), 1e-4),
                BatchSize::SmallInput,
            )
        });
    }

    let law = FrictionLaw::THESIS;
    c.bench_function("friction_cycle_closed_form", |b| {
        b.iter(|| black_box(law.cycle(black_box(0.01), black_box(0.05))))
    });
}

criterion_group!(core, benches);
criterion_main!(core);
