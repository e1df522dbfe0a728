//! Micro-benchmarks of the in-process hot paths.
//!
//! ```text
//! cargo bench --bench core
//! ```
//! `servo_tick` is one fast-loop tick (hybrid control, dither, tuner, IK, PID); `lockstep_step`
//! adds the plant and the sensor; `lockstep_10s` simulates 10 s at 10 kHz (the real-time factor
//! is 10 s divided by its time).

use afs_shared::friction::FrictionLaw;
use afs_shared::servo::ServoInput;
use afs_shared::sim::{Lockstep, SimConfig};
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

fn benches(c: &mut Criterion) {
    let sim = running_sim();
    let (q, qd) = sim.plant().joints();
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

    let mut stepping = running_sim();
    c.bench_function("lockstep_step", |b| b.iter(|| stepping.step()));

    let mut g = c.benchmark_group("lockstep_10s");
    g.sample_size(10).measurement_time(Duration::from_secs(8));
    g.bench_function("100k_ticks", |b| {
        b.iter_batched(running_sim, |mut s| s.run(100_000), BatchSize::LargeInput)
    });
    g.finish();

    let law = FrictionLaw::THESIS;
    c.bench_function("friction_cycle_closed_form", |b| {
        b.iter(|| black_box(law.cycle(black_box(0.01), black_box(0.05))))
    });
}

criterion_group!(core, benches);
criterion_main!(core);
