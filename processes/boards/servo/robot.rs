//! The servo board as the FCI client of a robot (issue 48, docs/franka-cell.md, *The servo on the
//! robot*): the same controller, scenario driver, force gate, estimator link and streams as
//! the simulated board, on an arm that the robot's packets clock instead of a world it steps.
//!
//! Each packet: the state in, every new force sample through the gate (its age in the
//! robot's time, `RobotClockAge`), the scenario driver at the robot's time, the commands, one
//! [`ArmCycle::cycle`] (the guard, the servo on the task drive, the torques within the arm's
//! limits), the torques out, then the tick's samples and the estimator's request moved along.
//! The loop blocks only in the robot's receive.

use super::board::{ForceInput, Opened, open, take_commands};
use super::link::EstimatorLink;
use super::ports::Ports;
use super::timing::{Timing, publish_stats};
use super::{ServoArgs, ServoEnd};
use crate::boards::Startup;
use crate::robot::{CYCLE_S, RobotLost, Session, next_packet};
use crate::stack::RobotTable;
use crate::{hist, rt};
use afs_shared::config::SimConfig;
use afs_shared::msg::{
    InsertionState, LoopFlags, LoopStats, PlantSample, ServoFlags, ServoSample, WorldSnapshot,
    WorldState, WrenchSample,
};
use afs_shared::robot_cycle::{ArmCycle, CycleOutput};
use afs_shared::robot_guard::HoldPose;
use afs_shared::scenario::{DriverState, Scenario, ScenarioDriver};
use afs_shared::sensor::Wrench;
use afs_shared::servo::{ServoCore, TaskDrive, to_plane};
use afs_shared::watchdog::{GateCounters, GateParams, RobotClockAge, SampleGate, Verdict};
use anyhow::{Context, Result, anyhow};
use franka::{RobotState, Torques, motion_finished};
use std::sync::atomic::{AtomicBool, Ordering};

/// Runs the scenario of `args` on the robot of `table` until its end, its duration or `stop`.
///
/// # Errors
/// The robot (unreachable, refusing, ending the motion), the ports, or no force data.
pub fn run(args: &ServoArgs, table: &RobotTable, stop: &AtomicBool) -> Result<ServoEnd> {
    let scenario = Scenario::new(&args.scenario, &args.base).map_err(anyhow::Error::msg)?;
    let mut cfg = scenario.cfg.clone();
    // The part where the tool starts: the task frame's origin (the cell builds the same,
    // `stack::cell`).
    cfg.surface = afs_shared::cell::surface_through(&cfg, afs_shared::math::Vec2::zeros());
    let Opened {
        duration_s: duration,
        mut startup,
        ports,
        transport,
    } = open(args, scenario.natural_duration_s)?;
    // Real-time before the robot and the first force sample: locking the memory takes tens of
    // milliseconds, which would otherwise pass between the first sample and the first packet.
    let rtr = rt::setup(args.priority, true, args.cpu);
    startup.report.rt_ns = Startup::now();
    for w in &rtr.warnings {
        eprintln!("afs-servo: warning: {w}");
    }
    let Some(mut session) = connect(table, args.resume, args.startup_timeout_s, stop)? else {
        return Ok(ServoEnd::Stopped);
    };
    let gate_params = GateParams {
        max_age_ns: (args.max_force_age_ms * 1e6) as u64,
        force_limit_n: cfg.sensor.range_force_n,
        torque_limit_nm: cfg.sensor.range_torque_nm,
        ..GateParams::default()
    };
    // A restarted servo carries on where its predecessor left the scenario (the supervisor's
    // world blackboard): the controller, the driver, the tick count and the scenario's time.
    let snapshot = match (&ports.world, args.resume) {
        (Some(w), true) => w.newest()?,
        _ => None,
    };
    let (mut gate, mut injected) = (SampleGate::new(gate_params), GateCounters::default());
    if let Some(s) = &snapshot {
        gate = SampleGate::resume(gate_params, s.gate);
        injected = s.injected;
    }
    let mut input = ForceInput {
        ports: &ports,
        gate: &mut gate,
        injected: &mut injected,
    };
    // The first sample: after a restart the predecessor's last tick again (its successor
    // then goes on with the next), otherwise the tool where it starts, tick 0.
    let p0 = snapshot
        .filter(|s| s.plant.version == PlantSample::VERSION && s.plant.seq == s.seq)
        .map_or_else(
            || plant_sample(&cfg, &session.start, Wrench::default(), 0, 0.0),
            |s| s.plant,
        );
    let Some(first) = input.wait(p0, args, (CYCLE_S * 1e9) as u64, &mut startup, stop)? else {
        return Ok(ServoEnd::Stopped);
    };
    let (servo, driver) = controller(&scenario, &cfg, &session, &first, snapshot.as_ref())?;
    let mut board = RobotBoard {
        servo,
        driver,
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
        seq: snapshot.map_or(1, |s| s.seq + 1),
        time_s: snapshot.map_or(0.0, |s| s.world.time_s),
        duration_s: duration,
        estimate_wanted: None,
        last_tare: first.tare(),
        ports,
        age: RobotClockAge::default(),
        connections: rt::Every::new(rt::CONNECTIONS_EVERY_NS, rt::monotonic_ns()),
    };
    startup.send();
    board.stats.flags.set(LoopFlags::SCHED_FIFO, rtr.fifo);
    board.stats.flags.set(LoopFlags::MLOCKED, rtr.mlocked);
    board.stats.flags.set(LoopFlags::PINNED, rtr.pinned);
    let end = board
        .drive(&mut session, stop)
        .with_context(|| format!("[robot] address = \"{}\"", table.address))?;
    board.finish(args.histograms.as_deref())?;
    Ok(end)
}

/// The controller on the task drive at the arm's first state and the scenario's driver; after
/// a restart, given their predecessor's state (a controller that will not take it starts
/// afresh, with a warning).
fn controller(
    scenario: &Scenario,
    cfg: &SimConfig,
    session: &Session,
    first: &afs_shared::msg::WrenchSample,
    snapshot: Option<&WorldSnapshot>,
) -> Result<(ServoCore, ScenarioDriver)> {
    let drive = TaskDrive {
        inertia: session.inertia,
        gains: session.gains,
        theta_rad: session.start.theta_rad,
    };
    let tangent0 = cfg.surface.tangent_angle_at(cfg.start_u_m) + cfg.tangent_error_rad;
    let new = || {
        ServoCore::new_task(
            cfg.servo_params(),
            drive,
            session.start.position_m,
            first.wrench().tared(first.tare()),
            tangent0,
        )
        .map_err(|e| anyhow!("[sim.servo] {e}"))
    };
    let mut servo = new()?;
    let mut driver = scenario.driver();
    if let Some(s) = snapshot {
        driver.resume(s.world.time_s, (&s.driver).into());
        if let Err(e) = servo.restore(&s.controller) {
            eprintln!("afs-servo: warning: {e}; the controller starts afresh");
            servo = new()?;
        }
    }
    servo.set_tare(first.tare());
    Ok((servo, driver))
}

/// How long a restarted servo asks the robot again before it counts as lost (s): the robot
/// answered its predecessor, so it is up, and takes a new client at once.
pub const RESUME_CONNECT_S: f64 = 2.0;

/// The robot's session, once it answers: a robot the graph starts itself (the simulated cell)
/// comes up beside the servo, so a robot that does not answer is asked again every 0.2 s for
/// `timeout_s`; then the last refusal is the error. A restarted servo (`resumed`) asks for
/// [`RESUME_CONNECT_S`] only, and then the robot was lost ([`RobotLost`]). None if stopped
/// first.
fn connect(
    table: &RobotTable,
    resumed: bool,
    timeout_s: f64,
    stop: &AtomicBool,
) -> Result<Option<Session>> {
    let t0 = std::time::Instant::now();
    let timeout_s = if resumed { RESUME_CONNECT_S } else { timeout_s };
    loop {
        match Session::open(table) {
            Ok(s) => return Ok(Some(s)),
            Err(e) if t0.elapsed().as_secs_f64() >= timeout_s => {
                return Err(if resumed {
                    anyhow::Error::new(RobotLost(format!(
                        "it did not answer the restarted servo for {timeout_s} s ({e:#})"
                    )))
                } else {
                    e
                });
            }
            Err(_) if stop.load(Ordering::Relaxed) => return Ok(None),
            Err(_) => std::thread::sleep(std::time::Duration::from_millis(200)),
        }
    }
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
    /// Force data's age in the robot's time.
    age: RobotClockAge,
    /// When to check the connections of ports that send rarely (every 0.1 s).
    connections: rt::Every,
}

impl RobotBoard {
    /// The motion: one [`RobotBoard::packet`] per state the robot sends, until the scenario
    /// ends or `stop`; the last command ends the motion through FCI's own finish.
    fn drive(&mut self, session: &mut Session, stop: &AtomicBool) -> Result<ServoEnd> {
        let Session { fr3, cycle, .. } = session;
        let mut control = fr3.torque_control()?;
        loop {
            // A robot that stops sending while the stack stops (the supervisor ends a run whose
            // cell died) is not an error of the servo's.
            let (state, dt) = match next_packet(&mut control) {
                Ok(p) => p,
                Err(_) if stop.load(Ordering::Relaxed) => return Ok(ServoEnd::Stopped),
                Err(e) => return Err(e),
            };
            let now = rt::monotonic_ns();
            if dt > 1.5 * CYCLE_S {
                self.stats.misses += ((dt / CYCLE_S).round() as u64).saturating_sub(1);
            }
            self.time_s += dt;
            let (out, used, done) = self.packet(fr3, cycle, &state, dt.max(CYCLE_S), now);
            let stopped = stop.load(Ordering::Relaxed);
            let torques = Torques::new(out.torque.torque_nm.into());
            let sent = if done || stopped {
                control.write_once(&motion_finished(torques))
            } else {
                control.write_once(&torques)
            };
            sent.map_err(|e| anyhow!("[robot] the command was refused: {e}"))?;
            self.after(&out, used, now);
            if done {
                return Ok(ServoEnd::Finished);
            }
            if stopped {
                return Ok(ServoEnd::Stopped);
            }
        }
    }

    /// One packet's command: the force through the gate, the scenario, the cycle; with the
    /// force sample used and its age at `now` (ns, on the wall clock), and `done` when the
    /// scenario has ended (the command then holds the tool where it is).
    fn packet(
        &mut self,
        fr3: &crate::robot::Fr3,
        cycle: &mut ArmCycle,
        state: &RobotState,
        dt: f64,
        now: u64,
    ) -> (CycleOutput, Option<(WrenchSample, u64)>, bool) {
        ForceInput {
            ports: &self.ports,
            gate: &mut self.gate,
            injected: &mut self.injected,
        }
        .take();
        // Judged by the robot's time (`RobotClockAge`); the age recorded is the wall clock's,
        // the data's real age at use.
        let due = self.age.due_ns(self.gate.newest(), self.time_s, now);
        let used = match self.gate.current(due) {
            Ok((w, _)) => {
                let age = now.saturating_sub(w.sample_ns);
                hist::record(&mut self.timing.age, age);
                let tare = w.tare();
                if tare != self.last_tare {
                    self.servo.set_tare(tare);
                    self.last_tare = tare;
                }
                Some((w, age))
            }
            Err(v) => {
                self.stats.stale_ticks += u64::from(v == Verdict::Stale);
                None
            }
        };
        let (wrench, valid) = used.map_or((Wrench::default(), false), |(w, _)| (w.wrench(), true));
        let arm = fr3.arm_state(state);
        let planar = cycle.planar(&arm);
        let u = self.cfg.surface.to_local(planar.position_m).0;
        let done = self.time_s >= self.duration_s
            || self.driver.step(self.time_s, u, &mut self.servo) == DriverState::Done;
        if done {
            let hold = cycle.hold_at(&arm, &HoldPose::of(&planar), dt);
            return (hold, used, true);
        }
        take_commands(
            &self.ports.command,
            &mut self.stats,
            &mut self.estimate_wanted,
            &mut self.servo,
        );
        let out = cycle.cycle(&mut self.servo, &arm, wrench, valid, dt);
        (out, used, false)
    }

    /// After the command went out: the tick's samples (`used`: the force sample the cycle
    /// used, with its age), the estimator's request, the timing.
    fn after(&mut self, out: &CycleOutput, used: Option<(WrenchSample, u64)>, now: u64) {
        if self.servo.is_safe() {
            self.stats.safe_ticks += 1;
        }
        // The world's force is the sensor's newest reading: while the sensor is silent, its last
        // one (the servo's sample then says the controller had none: no FORCE_VALID). A world
        // sample of zero force would count the outage as the tool off the part.
        let reading = used
            .map(|(w, _)| w)
            .or_else(|| self.gate.newest().copied())
            .map_or_else(Wrench::default, |w| w.wrench().tared(self.last_tare));
        let mut p = plant_sample(&self.cfg, &out.planar, reading, self.seq, self.time_s);
        p.tick_ns = now;
        p.publish_ns = rt::monotonic_ns();
        // The snapshot first, then the samples: a servo killed between the two leaves a tick
        // its successor sends again, never one sent twice with different contents.
        if let Some(world) = &self.ports.world {
            world.write(WorldSnapshot {
                version: WorldSnapshot::VERSION,
                reserved: 0,
                seq: self.seq,
                world: WorldState {
                    time_s: self.time_s,
                    ..WorldState::default()
                },
                driver: self.driver.memo().into(),
                controller: self.servo.state(),
                gate: self.gate.counters(),
                injected: self.injected,
                insertion: InsertionState::default(),
                plant: p,
            });
        }
        if self.ports.plant.send_copy(p).is_err() {
            self.stats.publish_failures += 1;
        }
        let mut s = ServoSample::of_tick(&self.servo, self.seq, now, self.time_s);
        if let Some((w, age)) = used {
            s.flags |= ServoFlags::FORCE_VALID;
            s.wrench_seq = w.seq;
            s.wrench_sample_ns = w.sample_ns;
            s.force_age_ns = age;
        }
        s.publish_ns = rt::monotonic_ns();
        if self.ports.servo.send_copy(s).is_err() {
            self.stats.publish_failures += 1;
        }
        self.link.tick(&mut self.servo, now);
        self.stats.ticks += 1;
        if self.stats.ticks.is_multiple_of(1000) {
            self.publish_stats();
        } else if self.link.is_idle() && self.connections.due(now) {
            // Drop the connections of an estimator that died (a file pair per dead server)
            // and connect a restarted one, as the planar board does: without it a killed or
            // frozen estimator's connection files stayed until the servo's end.
            self.link.update_connections();
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

/// The smallest push that counts as contact on a robot (N), whatever the sensor's noise.
pub const CONTACT_FLOOR_N: f64 = 0.05;

/// The tick's world sample on a robot: what afs can know of it. The tool's planar pose and
/// velocity are the robot's. The force is the sensor's (tared, turned into the plane by θ),
/// standing in for the contact's: its component along the surface's normal is the normal
/// force, and a contact is a push above five of the sensor noise's standard deviations (at
/// least [`CONTACT_FLOOR_N`]). The surface
/// coordinate is the tool's on the scenario's surface as placed in the plane
/// (`afs_shared::cell::surface_through`, the part the cell builds) and the tangent the
/// surface's there. Joint fields are zero (seven
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
    let (u, _) = cfg.surface.to_local(s.position_m);
    let tangent = cfg.surface.tangent_angle_at(u);
    let normal = afs_shared::math::perp(afs_shared::math::unit(tangent));
    let pushed = f.dot(&normal);
    // In contact: a push the sensor's noise cannot make (five of its standard deviations).
    let touch = (5.0 * cfg.sensor.noise_force_n).max(CONTACT_FLOOR_N);
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
