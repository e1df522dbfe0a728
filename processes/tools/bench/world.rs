//! `afs bench world` (docs/mujoco.md, *Measured*): the world's step per servo tick on MuJoCo
//! (`mj_step` and afs's reading of it) beside the built-in plant's, interleaved in rounds of
//! 1 000 ticks under the same torques; the lockstep's real-time factor on each; and the
//! servo's wake latency in a stack on MuJoCo against one on the built-in plant, run in turn.

use super::stack::run_stack;
use super::{BenchOptions, PartReport, Series, finish_part};
use crate::hist;
use crate::rt;
use crate::stack::DEFAULT_STACK;
use afs_shared::check::Check;
use afs_shared::config::SimConfig;
use afs_shared::math::Vec2;
use afs_shared::plant::holding_torque;
use afs_shared::sim::Lockstep;
use afs_shared::world::{World, WorldKind};
use anyhow::Result;
use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// The world part's report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WorldPart {
    /// Simulated seconds per wall second of the lockstep (sensor, servo, world) on MuJoCo.
    pub lockstep_realtime_factor_mujoco: f64,
    /// The same on the built-in plant.
    pub lockstep_realtime_factor_builtin: f64,
    /// Whether both stacks passed their checks.
    pub stacks_passed: [bool; 2],
    /// Series, targets, files.
    #[serde(flatten)]
    pub part: PartReport,
}

fn world(kind: WorldKind) -> Result<(World, SimConfig)> {
    let mut cfg = SimConfig::default();
    cfg.world.kind = kind;
    let q = cfg.start_configuration().map_err(anyhow::Error::msg)?;
    Ok((World::new(&cfg, q).map_err(anyhow::Error::msg)?, cfg))
}

/// `rounds` × 1 000 steps of each world, alternating, under the torque that holds the preload
/// plus a 10 Hz tangential push that makes the tool slide back and forth.
fn steps(rounds: usize, stop: &AtomicBool) -> Result<[Histogram<u64>; 2]> {
    let mut worlds = [world(WorldKind::Builtin)?, world(WorldKind::Mujoco)?];
    let mut hists = [hist::new()?, hist::new()?];
    let dt = worlds[0].1.servo.dt();
    for round in 0..rounds {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        for ((w, _), h) in worlds.iter_mut().zip(hists.iter_mut()) {
            for k in 0..1000 {
                let t = (round * 1000 + k) as f64 * dt;
                let push = 1.2 * (std::f64::consts::TAU * 10.0 * t).sin();
                let (q, _) = w.joints();
                let tau = holding_torque(w.arm(), q, Vec2::new(push, 2.5));
                let t0 = rt::monotonic_ns();
                w.step(tau, dt);
                hist::record(h, rt::monotonic_ns() - t0);
            }
        }
    }
    Ok(hists)
}

/// Simulated seconds per wall second of the lockstep on `kind`, tracking at 5 mm/s with the
/// dither, for about `wall_s`.
fn realtime_factor(kind: WorldKind, wall_s: f64) -> Result<f64> {
    let mut cfg = SimConfig::default();
    cfg.world.kind = kind;
    let mut sim = Lockstep::new(&cfg).map_err(anyhow::Error::msg)?;
    sim.servo_mut().hybrid_mut().set_velocity(0.005);
    sim.servo_mut().set_a_omega(0.025);
    let t0 = Instant::now();
    while t0.elapsed().as_secs_f64() < wall_s {
        sim.run(1000);
    }
    Ok(sim.time() / t0.elapsed().as_secs_f64())
}

/// Runs the part.
pub(super) fn world_part(opts: &BenchOptions, stop: &AtomicBool) -> Result<WorldPart> {
    let rounds = ((opts.duration_s * 10.0) as usize).max(1);
    let [builtin, mujoco] = steps(rounds, stop)?;
    let rtf_mujoco = realtime_factor(WorldKind::Mujoco, opts.duration_s.min(10.0))?;
    let rtf_builtin = realtime_factor(WorldKind::Builtin, opts.duration_s.min(10.0))?;
    let mujoco_stack = format!("{DEFAULT_STACK}\n[sim.world]\nkind = \"mujoco\"\n");
    let mut wakes = Vec::new();
    let mut passed = [false; 2];
    for (i, text) in [DEFAULT_STACK, mujoco_stack.as_str()].iter().enumerate() {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let prefix = format!("{}w{i}", opts.prefix);
        let (run, _) = run_stack(text, &prefix, opts.duration_s, &opts.out, &[], stop, |_| ())?;
        passed[i] = run.report.passed;
        wakes.push(run.wake);
    }
    let mut series = vec![
        Series {
            name: "step_builtin",
            what: "the built-in plant's step per servo tick",
            floor: None,
            hist: builtin,
        },
        Series {
            name: "step_mujoco",
            what: "MuJoCo's step per servo tick (mj_step and afs's reading of it)",
            floor: Some("step_builtin"),
            hist: mujoco,
        },
    ];
    let mut targets = vec![
        Check::at_most(
            "mj_step_p99_us",
            "MuJoCo step per tick, p99 (µs)",
            hist::QuantilesUs::of(&series[1].hist).p99,
            20.0,
        )
        .target(),
        Check::at_least(
            "lockstep_realtime_factor_mujoco",
            "lockstep on MuJoCo, simulated s per wall s",
            rtf_mujoco,
            20.0,
        )
        .target(),
    ];
    if let [builtin_wake, mujoco_wake] = &wakes[..] {
        let ratio =
            hist::QuantilesUs::of(mujoco_wake).p99 / hist::QuantilesUs::of(builtin_wake).p99;
        targets.push(
            Check::at_most(
                "servo_wake_p99_mujoco_over_builtin",
                "servo wake p99 on MuJoCo / on the built-in plant, same run",
                ratio,
                1.2,
            )
            .target(),
        );
        let mut it = wakes.into_iter();
        if let (Some(b), Some(m)) = (it.next(), it.next()) {
            series.push(Series {
                name: "servo_wake_builtin",
                what: "servo wake latency, the stack on the built-in plant",
                floor: None,
                hist: b,
            });
            series.push(Series {
                name: "servo_wake_mujoco",
                what: "servo wake latency, the stack on MuJoCo",
                floor: Some("servo_wake_builtin"),
                hist: m,
            });
        }
    }
    let part = finish_part(
        "world",
        &series,
        &[],
        targets,
        &opts.out,
        "the world's step and the servo's wake: MuJoCo against the built-in plant",
    )?;
    Ok(WorldPart {
        lockstep_realtime_factor_mujoco: rtf_mujoco,
        lockstep_realtime_factor_builtin: rtf_builtin,
        stacks_passed: passed,
        part,
    })
}
