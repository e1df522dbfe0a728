//! The servo board as the FCI client of a robot (issue 48, docs/franka.md, *The servo on the
//! robot*): the same controller, scenario driver, force gate, estimator link and streams as
//! the simulated board, on an arm that the robot's packets clock instead of a world it steps.
//!
//! Each packet: the state in, every new force sample through the gate, the scenario driver
//! at the robot's time, the commands, one [`ArmCycle::cycle`] (the guard, the servo on the
//! task drive, the torques within the arm's limits), the torques out, then the tick's samples
//! and the estimator's request moved along. The loop blocks only in the robot's receive.

use super::board::{ForceInput, take_commands};
use super::link::EstimatorLink;
use super::ports::Ports;
use super::timing::{Timing, publish_stats};
use super::{ServoArgs, ServoEnd};
use crate::boards::Startup;
use crate::robot::{CYCLE_S, Session};
use crate::stack::RobotTable;
use crate::{hist, ipc, rt};
use afs_shared::config::SimConfig;
use afs_shared::msg::{Board, LoopFlags, LoopStats, PlantSample, ServoFlags, ServoSample};
use afs_shared::robot_cycle::CycleOutput;
use afs_shared::scenario::{DriverState, Scenario, ScenarioDriver};
use afs_shared::sensor::Wrench;
use afs_shared::servo::{ServoCore, TaskDrive, to_plane};
use afs_shared::watchdog::{GateCounters, GateParams, SampleGate};
use anyhow::{Result, anyhow};
use franka::{RobotState, Torques, motion_finished};
use std::sync::atomic::{AtomicBool, Ordering};

/// Runs the scenario of `args` on the robot of `table` until its end, its duration or `stop`.
///
/// # Errors
/// The robot (unreachable, refusing, ending the motion), the ports, or no force data.
pub fn run(args: &ServoArgs, table: &RobotTable, stop: &AtomicBool) -> Result<ServoEnd> {
    let scenario = Scenario::new(&args.scenario, &args.base).map_err(anyhow::Error::msg)?;
    let cfg = scenario.cfg.clone();
    let duration = if args.duration_s > 0.0 {
        args.duration_s.min(scenario.natural_duration_s)
    } else {
        scenario.natural_duration_s
    };
    let mut startup = Startup::new(Board::Servo, args.main_ns);
    let node = ipc::node(&args.prefix, Board::Servo.name())?;
    startup.report.node_ns = Startup::now();
    let (ports, transport) = Ports::open(&node, args)?;
    startup.open(&node)?;
    startup.report.ports_ns = Startup::now();
    let mut session = Session::open(table)?;
    let gate_params = GateParams {
        max_age_ns: (args.max_force_age_ms * 1e6) as u64,
        force_limit_n: cfg.sensor.range_force_n,
        torque_limit_nm: cfg.sensor.range_torque_nm,
        ..GateParams::default()
    };
    let (mut gate, mut injected) = (SampleGate::new(gate_params), GateCounters::default());
    let mut input = ForceInput {
        ports: &ports,
        gate: &mut gate,
        injected: &mut injected,
    };
    let p0 = plant_sample(&cfg, &session.start, Wrench::default(), 0, 0.0);
    let Some(first) = input.wait(p0, args, (CYCLE_S * 1e9) as u64, &mut startup, stop)? else {
        return Ok(ServoEnd::Stopped);
    };
    let drive = TaskDrive {
        inertia: session.inertia,
        gains: session.gains,
        theta_rad: session.start.theta_rad,
    };
    let tangent0 = cfg.surface.tangent_angle_at(cfg.start_u_m) + cfg.tangent_error_rad;
    let mut servo = ServoCore::new_task(
        cfg.servo_params(),
        drive,
        session.start.position_m,
        first.wrench().tared(first.tare()),
        tangent0,
    )
    .map_err(|e| anyhow!("[sim.servo] {e}"))?;
    servo.set_tare(first.tare());
    let mut board = RobotBoard {
        servo,
        driver: scenario.driver(),
        cfg,
        gate,
        injected,
        link: EstimatorLink::new(transport, args.estimator_timeout_s, args.estimator_attempts),
        timing: Timing::new()?,
        stats: LoopStats {
            version: LoopStats::VERSION,
            period_ns: (CYCLE_S * 1e9) as u64,
            ..Default::default()
        },
        seq: 1,
        time_s: 0.0,
        duration_s: duration,
        estimate_wanted: None,
        last_tare: first.tare(),
        ports,
    };
    let rtr = rt::setup(args.priority, true, args.cpu);
    startup.report.rt_ns = Startup::now();
    startup.send();
    for w in &rtr.warnings {
        eprintln!("afs-servo: warning: {w}");
    }
    board.stats.flags.set(LoopFlags::SCHED_FIFO, rtr.fifo);
    board.stats.flags.set(LoopFlags::MLOCKED, rtr.mlocked);
    board.stats.flags.set(LoopFlags::PINNED, rtr.pinned);
    let end = board.drive(&mut session, stop)?;
    board.finish(args.histograms.as_deref())?;
    Ok(end)
}

/// The board's state between packets.
struct RobotBoard {
    servo: ServoCore,
    driver: ScenarioDriver,
    cfg: SimConfig,
    gate: SampleGate,
    injected: GateCounters,
    link: EstimatorLink,
    timing: Timing,
    stats: LoopStats,
    seq: u64,
    /// The robot's time since the motion started (s).
    time_s: f64,
    duration_s: f64,
    estimate_wanted: Option<u32>,
    last_tare: Wrench,
    ports: Ports,
}

impl RobotBoard {
    /// The motion: one [`RobotBoard::packet`] per state the robot sends, until the scenario
    /// ends or `stop`; the last command ends the motion through FCI's own finish.
    fn drive(&mut self, session: &mut Session, stop: &AtomicBool) -> Result<ServoEnd> {
        let Session { fr3, cycle, .. } = session;
        let mut control = fr3
            .robot()
            .start_torque_control()
            .map_err(|e| anyhow!("[robot] torque control refused: {e}"))?;
        loop {
            let (state, period) = control
                .read_once()
                .map_err(|e| anyhow!("[robot] the motion ended: {e}"))?;
            let now = rt::monotonic_ns();
            let dt = period.as_secs_f64();
            if dt > 1.5 * CYCLE_S {
                self.stats.misses += ((dt / CYCLE_S).round() as u64).saturating_sub(1);
            }
            self.time_s += dt;
            let (out, done) = self.packet(fr3, cycle, &state, dt.max(CYCLE_S), now);
            let stopped = stop.load(Ordering::Relaxed);
            let torques = Torques::new(out.torque.torque_nm.into());
            let sent = if done || stopped {
                control.write_once(&motion_finished(torques))
            } else {
                control.write_once(&torques)
            };
            sent.map_err(|e| anyhow!("[robot] the command was refused: {e}"))?;
            self.after(&out, now);
            if done {
                return Ok(ServoEnd::Finished);
            }
            if stopped {
                return Ok(ServoEnd::Stopped);
            }
        }
    }

    /// One packet's command: the force through the gate, the scenario, the cycle. `done`
    /// when the scenario has ended (the command then holds the tool where it is).
    fn packet(
        &mut self,
        fr3: &crate::robot::Fr3,
        cycle: &mut afs_shared::robot_cycle::ArmCycle,
        state: &RobotState,
        dt: f64,
        now: u64,
    ) -> (CycleOutput, bool) {
        ForceInput {
            ports: &self.ports,
            gate: &mut self.gate,
            injected: &mut self.injected,
        }
        .take();
        let (wrench, valid) = match self.gate.current(now) {
            Ok((w, _)) => {
                hist::record(&mut self.timing.age, now.saturating_sub(w.sample_ns));
                let tare = w.tare();
                if tare != self.last_tare {
                    self.servo.set_tare(tare);
                    self.last_tare = tare;
                }
                (w.wrench(), true)
            }
            Err(_) => {
                self.stats.stale_ticks += 1;
                (Wrench::default(), false)
            }
        };
        let arm = fr3.arm_state(state);
        let u = self.servo.state().track.odometer_total_m;
        let done = self.time_s >= self.duration_s
            || self.driver.step(self.time_s, u, &mut self.servo) == DriverState::Done;
        if done {
            let hold = cycle.planar(&arm);
            let pose = afs_shared::robot_guard::HoldPose {
                position_m: hold.position_m,
                theta_rad: hold.theta_rad,
                normal_m: hold.normal_m,
            };
            return (cycle.hold_at(&arm, &pose, dt), true);
        }
        take_commands(
            &self.ports.command,
            &mut self.stats,
            &mut self.estimate_wanted,
            &mut self.servo,
        );
        (cycle.cycle(&mut self.servo, &arm, wrench, valid, dt), false)
    }

    /// After the command went out: the tick's samples, the estimator's request, the timing.
    fn after(&mut self, out: &CycleOutput, now: u64) {
        if self.servo.is_safe() {
            self.stats.safe_ticks += 1;
        }
        let reading = match self.gate.current(now) {
            Ok((w, _)) => w.wrench().tared(self.last_tare),
            Err(_) => Wrench::default(),
        };
        let mut p = plant_sample(&self.cfg, &out.planar, reading, self.seq, self.time_s);
        p.tick_ns = now;
        p.publish_ns = rt::monotonic_ns();
        if self.ports.plant.send_copy(p).is_err() {
            self.stats.publish_failures += 1;
        }
        let mut s = ServoSample::of_tick(&self.servo, self.seq, now, self.time_s);
        if let Ok((w, _)) = self.gate.current(now) {
            s.flags |= ServoFlags::FORCE_VALID;
            s.wrench_seq = w.seq;
            s.wrench_sample_ns = w.sample_ns;
            s.force_age_ns = now.saturating_sub(w.sample_ns);
        }
        s.publish_ns = rt::monotonic_ns();
        if self.ports.servo.send_copy(s).is_err() {
            self.stats.publish_failures += 1;
        }
        self.link.tick(&mut self.servo, now);
        self.stats.ticks += 1;
        if self.stats.ticks.is_multiple_of(1000) {
            self.publish_stats();
        }
        let exec = rt::monotonic_ns().saturating_sub(now);
        hist::record(&mut self.timing.exec, exec);
        self.seq += 1;
    }

    fn publish_stats(&mut self) {
        self.stats.injected = self.injected;
        publish_stats(
            &mut self.stats,
            &self.timing,
            &self.gate,
            &self.link,
            &self.servo,
            &self.ports.stats,
        );
    }

    fn finish(mut self, histograms: Option<&std::path::Path>) -> Result<()> {
        self.publish_stats();
        if let Some(dir) = histograms {
            self.timing.save(dir)?;
        }
        Ok(())
    }
}

/// The tick's world sample on a robot: what afs can know of it. The tool's planar pose and
/// velocity are the robot's. The force is the sensor's (tared, turned into the plane by θ),
/// standing in for the contact's: its component along the configured surface's normal is the
/// normal force, and a contact is one above the approach's touch (half the preload). The
/// surface coordinate is the tool's x and the tangent the configured surface's there
/// (`[sim.surface]`, the part as the cell or the user placed it). Joint fields are zero (seven
/// joints do not fit the planar arm's two).
fn plant_sample(
    cfg: &SimConfig,
    s: &afs_shared::task_plane::PlanarState,
    reading: Wrench,
    seq: u64,
    time_s: f64,
) -> PlantSample {
    let (sin, cos) = s.theta_rad.sin_cos();
    let f = to_plane(sin, cos, reading);
    let u = s.position_m.x;
    let tangent = cfg.surface.tangent_angle_at(u);
    let normal = afs_shared::math::perp(afs_shared::math::unit(tangent));
    let pushed = f.dot(&normal);
    let touch = cfg.servo.approach.touch_fraction * cfg.servo.hybrid.preload_n;
    PlantSample {
        version: PlantSample::VERSION,
        contact_count: u32::from(pushed > touch),
        seq,
        time_s,
        tip_m: [s.position_m.x, s.position_m.y],
        tip_velocity_m_per_s: [s.velocity_m_per_s.x, s.velocity_m_per_s.y],
        contact_force_n: [f.x, f.y],
        sensor_force_n: [reading.force.x, reading.force.y],
        sensor_torque_nm: reading.torque,
        normal_force_n: pushed,
        friction_force_n: f.dot(&afs_shared::math::unit(tangent)),
        sliding_velocity_m_per_s: s.velocity_m_per_s.dot(&afs_shared::math::unit(tangent)),
        tangent_angle_rad: tangent,
        surface_u_m: u,
        ..Default::default()
    }
}
