//! The plant/servo board: the simulated world and the fast loop at 10 kHz on absolute-time
//! wake-ups.
//!
//! Each tick: wake, take the newest force sample through the watchdog gate, run the scenario
//! driver and one [`ServoCore`] step, advance the plant, publish the world and the controller
//! samples, move the estimator request along, keep the world snapshot, record the loop's
//! timing. Nothing in the tick allocates, locks, logs or blocks: histograms, the request
//! buffer and the probe record are allocated before the loop; iceoryx2 loans come from
//! pre-mapped shared memory.

mod link;
mod timing;

use crate::boards::Startup;
use crate::ipc;
use crate::{hist, rt};
use afs_shared::msg::{
    self, Board, Command, LoopFlags, LoopStats, PlantSample, ServoFlags, ServoSample, WorldSnapshot,
};
use afs_shared::plant::{Plant, PlantState};
use afs_shared::scenario::{self, DriverMemo, DriverState, Scenario};
use afs_shared::servo::{ServoCore, ServoInput, ServoMode};
use afs_shared::sim::SimConfig;
use afs_shared::watchdog::{GateParams, SampleGate, Verdict};
use anyhow::{Context, Result, bail};
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use link::EstimatorLink;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use timing::{Timing, publish_stats};

/// Default time the estimator has to answer before a request is re-sent (s).
pub const ESTIMATOR_TIMEOUT_S: f64 = 1.0;

/// How the servo reaches the estimator's tangent service.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EstimatorVia {
    /// iceoryx2 request-response: the estimator on the same host.
    RequestResponse,
    /// A request topic and a response topic: the estimator on the same host or, through the
    /// link board, on another (docs/link.md).
    Topics,
}

/// How the servo runs.
#[derive(Debug, Clone)]
pub struct ServoArgs {
    /// Stack prefix.
    pub prefix: String,
    /// Scenario name.
    pub scenario: String,
    /// The set-up (already with the scenario's overrides applied by `Scenario::new`).
    pub base: SimConfig,
    /// Stop after this much simulated time (s); 0 runs the scenario to its end.
    pub duration_s: f64,
    /// CPU to pin to.
    pub cpu: Option<usize>,
    /// SCHED_FIFO priority (0: normal scheduling).
    pub priority: u8,
    /// Resume the world from the supervisor's snapshot (after a servo restart).
    pub resume: bool,
    /// Largest age of force data at use (ms).
    pub max_force_age_ms: f64,
    /// Time the estimator has to answer before a request is re-sent (s).
    pub estimator_timeout_s: f64,
    /// Sends of one request before giving up and keeping the old tangent.
    pub estimator_attempts: u32,
    /// How the estimator is reached.
    pub estimator_via: EstimatorVia,
    /// Time to wait for the first force sample (s).
    pub startup_timeout_s: f64,
    /// Save the wake, execution-time and force-age histograms here at the end.
    pub histograms: Option<PathBuf>,
    /// Monotonic time `main` was entered (ns), for the start-up report.
    pub main_ns: u64,
}

/// How the servo ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServoEnd {
    /// The scenario reached its end or its duration.
    Finished,
    /// Asked to stop (SIGINT/SIGTERM).
    Stopped,
}

/// Runs the board until the scenario ends, the duration passes or `stop` is set.
pub fn run(args: &ServoArgs, stop: &AtomicBool) -> Result<ServoEnd> {
    let scenario = Scenario::new(&args.scenario, &args.base).map_err(anyhow::Error::msg)?;
    let cfg = &scenario.cfg;
    let dt = cfg.servo.dt();
    let period_ns = (dt * 1e9).round() as u64;
    let duration = if args.duration_s > 0.0 {
        args.duration_s.min(scenario.natural_duration_s)
    } else {
        scenario.natural_duration_s
    };

    let mut startup = Startup::new(Board::Servo, args.main_ns);
    let node = ipc::node(&args.prefix, msg::Board::Servo.name())?;
    startup.report.node_ns = Startup::now();
    let plant_pub = ipc::plant(&node)?
        .publisher_builder()
        .backpressure_strategy(ipc::BACKPRESSURE)
        .create()
        .context("plant publisher")?;
    let servo_pub = ipc::servo(&node)?
        .publisher_builder()
        .backpressure_strategy(ipc::BACKPRESSURE)
        .create()
        .context("servo publisher")?;
    let stats_pub = ipc::loop_stats(&node)?
        .publisher_builder()
        .create()
        .context("loop-stats publisher")?;
    let wrench_sub = ipc::wrench(&node)?
        .subscriber_builder()
        .buffer_size(256)
        .create()
        .context("wrench subscriber")?;
    let transport = match args.estimator_via {
        EstimatorVia::RequestResponse => link::Transport::RequestResponse(
            ipc::tangent(&node)?
                .client_builder()
                .initial_max_slice_len(ipc::MAX_PROBE_SAMPLES)
                .allocation_strategy(AllocationStrategy::Static)
                .create()
                .context("tangent client")?,
        ),
        EstimatorVia::Topics => link::Transport::Topics {
            requests: ipc::tangent_requests(&node)?
                .publisher_builder()
                .initial_max_slice_len(ipc::MAX_PROBE_SAMPLES)
                .allocation_strategy(AllocationStrategy::Static)
                .backpressure_strategy(ipc::BACKPRESSURE)
                .max_loaned_samples(1)
                .create()
                .context("tangent request publisher")?,
            responses: ipc::tangent_responses(&node)?
                .subscriber_builder()
                .create()
                .context("tangent response subscriber")?,
        },
    };
    let command_sub = ipc::command(&node)?
        .subscriber_builder()
        .buffer_size(16)
        .create()
        .context("command subscriber")?;
    let world = ipc::open_world(&node);
    if world.is_none() {
        eprintln!(
            "afs-servo: warning: no world blackboard (not started by `afs run`?); a restart will start the world afresh"
        );
    }
    let world_writer = match &world {
        Some(w) => Some(w.writer_builder().create().context("world writer")?),
        None => None,
    };
    let world_entry = match &world_writer {
        Some(w) => Some(
            (0..ipc::WORLD_SLOTS)
                .find_map(|k| w.entry::<WorldSnapshot>(&k).ok())
                .with_context(|| {
                    format!(
                        "no free entry in the world blackboard ({} servo incarnations used them all)",
                        ipc::WORLD_SLOTS
                    )
                })?,
        ),
        None => None,
    };
    startup.open(&node)?;
    startup.report.ports_ns = Startup::now();

    // The world: fresh, or where the last servo left it.
    let q0 = cfg.start_configuration().map_err(anyhow::Error::msg)?;
    let mut plant = Plant::new(cfg.plant.clone(), cfg.surface.clone(), q0);
    let mut snapshot = None;
    if args.resume
        && let Some(w) = &world
    {
        let reader = w.reader_builder().create().context("world reader")?;
        // The newest snapshot any earlier incarnation left.
        let mut newest: Option<WorldSnapshot> = None;
        for k in 0..ipc::WORLD_SLOTS {
            let s = *reader
                .entry::<WorldSnapshot>(&k)
                .with_context(|| format!("world entry {k}"))?
                .get();
            if s.version == msg::VERSION && newest.is_none_or(|n| s.seq > n.seq) {
                newest = Some(s);
            }
        }
        if let Some(s) = newest {
            let face = |f: u64| usize::try_from(f).unwrap_or(usize::MAX);
            plant.restore(&PlantState {
                time_s: s.time_s,
                q: s.q_rad,
                qd: s.qd_rad_per_s,
                friction: [
                    (face(s.friction_face[0]), s.friction_deflection_m[0]),
                    (face(s.friction_face[1]), s.friction_deflection_m[1]),
                ],
            });
            snapshot = Some(s);
        }
    }
    // A resumed servo starts by sending its predecessor's last tick again (below), then
    // continues with the next one.
    let mut seq = snapshot.map_or(0, |s| s.seq);
    // Ticks 1..=tick_limit are the scenario's (0 is the world's first sample): the same count
    // the lockstep runs, whatever restarts happen in between.
    let tick_limit = (duration / dt).round() as u64;
    let tangent0 = cfg.surface.tangent_angle_at(cfg.start_u_m) + cfg.tangent_error_rad;

    // Publish the world until the sensor answers.
    let mut gate = SampleGate::new(GateParams {
        max_age_ns: (args.max_force_age_ms * 1e6) as u64,
        force_limit_n: cfg.sensor.range_force_n,
        torque_limit_nm: cfg.sensor.range_torque_nm,
        ..GateParams::default()
    });
    // The world's first sample, published once (a sensor that connects later gets it as the
    // service's history); every later sample has the next sequence number. After a restart it
    // is the last tick of the previous servo, bit for bit as that one wrote it to the world
    // blackboard before sending it: if the previous servo died between the two, the tick is
    // delivered now; if not, subscribers recognise the repeat (docs/reliability.md).
    let t_wait = rt::monotonic_ns();
    let p0 = match snapshot {
        Some(s) if s.plant.version == msg::VERSION && s.plant.seq == s.seq => s.plant,
        _ => {
            let mut p = PlantSample::of_tick(plant.truth(), seq, t_wait);
            p.publish_ns = rt::monotonic_ns();
            p
        }
    };
    startup.report.prepared_ns = t_wait;
    let _ = plant_pub.send_copy(p0);
    startup.report.data_ns = Startup::now();
    seq += 1;
    let mut next = t_wait;
    let first = loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(ServoEnd::Stopped);
        }
        let now = rt::monotonic_ns();
        let _ = plant_pub.update_connections();
        // Judged against the clock at receipt, as in the loop below: the sensor board may
        // publish between the clock read above and this receive.
        while let Ok(Some(s)) = wrench_sub.receive() {
            gate.offer(s.payload(), rt::monotonic_ns());
        }
        if let Ok((w, _)) = gate.current(now) {
            startup.report.input_ns = now;
            break w;
        }
        if now - t_wait > (args.startup_timeout_s * 1e9) as u64 {
            bail!(
                "no force data within {:.1} s; is afs-sensor running with --prefix {}?",
                args.startup_timeout_s,
                args.prefix
            );
        }
        next += period_ns;
        rt::sleep_until(next);
    };
    let mut wrench0 = first.wrench();
    wrench0.force -= first.tare().force;
    wrench0.torque -= first.tare().torque;
    // Built as the first servo was (same start, so the same gains and stiffness), then given
    // its predecessor's state: a restarted servo carries on with the controller, not only
    // with the world.
    let mut servo = ServoCore::new(
        cfg.servo,
        cfg.plant.arm,
        cfg.plant.elbow,
        q0,
        wrench0,
        tangent0,
    )
    .map_err(anyhow::Error::msg)?;
    let mut driver = scenario.driver();
    if let Some(s) = snapshot {
        driver.resume(
            s.time_s,
            DriverMemo {
                leg: (s.driver_leg != u32::MAX).then_some(s.driver_leg),
                leg_start_s: s.driver_leg_start[0],
                leg_start_u: s.driver_leg_start[1],
            },
        );
        if let Err(e) = servo.restore(&s.controller) {
            // The world carries on; the controller starts afresh from it.
            eprintln!("afs-servo: warning: {e}; the controller starts afresh");
            let (q, _) = plant.joints();
            servo = ServoCore::new(
                cfg.servo,
                cfg.plant.arm,
                cfg.plant.elbow,
                q,
                wrench0,
                tangent0,
            )
            .map_err(anyhow::Error::msg)?;
        }
    }
    servo.set_tare(first.tare());
    let mut link = EstimatorLink::new(transport, args.estimator_timeout_s, args.estimator_attempts);
    let mut timing = Timing::new()?;
    let rtr = rt::setup(args.priority, true, args.cpu);
    startup.report.rt_ns = Startup::now();
    startup.send();
    for w in &rtr.warnings {
        eprintln!("afs-servo: warning: {w}");
    }
    let mut flags = LoopFlags::empty();
    flags.set(LoopFlags::SCHED_FIFO, rtr.fifo);
    flags.set(LoopFlags::MLOCKED, rtr.mlocked);
    flags.set(LoopFlags::PINNED, rtr.pinned);

    let mut stats = LoopStats {
        version: msg::VERSION,
        flags,
        period_ns,
        ..Default::default()
    };
    let mut safe_reason = 0u32;
    // A tangent estimate asked for, until the servo can start it: the number of estimations
    // started when it was sent (it lapses once more have started).
    let mut estimate_wanted: Option<u32> = None;
    let mut last_tare = first.tare();
    let start_ns = rt::monotonic_ns() + period_ns;
    let mut deadline = start_ns;
    let mut end = ServoEnd::Finished;
    loop {
        rt::sleep_until(deadline);
        let now = rt::monotonic_ns();
        let late = now.saturating_sub(deadline);
        if stop.load(Ordering::Relaxed) {
            end = ServoEnd::Stopped;
            break;
        }
        // Force data through the gate, judged against the clock at receipt: the sensor board
        // outranks the servo on its core and may publish after this tick woke.
        while let Ok(Some(s)) = wrench_sub.receive() {
            gate.offer(s.payload(), rt::monotonic_ns());
        }
        let current = gate.current(now);
        let (q, qd) = plant.joints();
        let mut input = ServoInput {
            q,
            qd,
            ..Default::default()
        };
        let mut used = None;
        match current {
            Ok((w, age)) => {
                input.wrench = w.wrench();
                input.force_valid = true;
                let tare = w.tare();
                if tare != last_tare {
                    servo.set_tare(tare);
                    last_tare = tare;
                }
                hist::record(&mut timing.age, age);
                used = Some((w, age));
            }
            Err(v) => {
                if v == Verdict::Stale {
                    stats.stale_ticks += 1;
                }
                if !servo.is_safe() {
                    safe_reason = v as u32;
                }
            }
        }
        // Scenario, control, world.
        let t = plant.time();
        if seq > tick_limit
            || driver.step(t, plant.truth().surface_u_m, &mut servo) == DriverState::Done
        {
            break;
        }
        while let Ok(Some(c)) = command_sub.receive() {
            let c = *c.payload();
            stats.commands += 1;
            if c.version == msg::VERSION
                && Command::try_from(c.command) == Ok(Command::EstimateTangent)
            {
                estimate_wanted = Some(c.started_before);
            } else {
                stats.bad_commands += 1;
            }
        }
        if let Some(before) = estimate_wanted {
            let started = u32::try_from(servo.counters().started).unwrap_or(u32::MAX);
            if started > before {
                estimate_wanted = None;
            } else if servo.mode() == ServoMode::Track {
                // The lockstep reference replays this at the same tick (`Replay::requested`).
                servo.request_tangent_estimate();
                estimate_wanted = None;
            }
        }
        let tau = servo.step(&input, dt);
        plant.step(tau, dt);
        if servo.is_safe() {
            stats.safe_ticks += 1;
        }

        // Publish the tick.
        let mut p = PlantSample::of_tick(plant.truth(), seq, now);
        let mut s = ServoSample::of_tick(&servo, seq, now, plant.time());
        s.safe_reason = safe_reason;
        if let Some((w, age)) = used {
            s.flags |= ServoFlags::FORCE_VALID;
            s.wrench_seq = w.seq;
            s.wrench_sample_ns = w.sample_ns;
            s.force_age_ns = age;
        }
        p.publish_ns = rt::monotonic_ns();
        // The world first, then the sample: a servo killed between the two leaves a tick its
        // successor sends again, never one that is sent twice with different contents.
        if let Some(e) = &world_entry {
            e.update_with_copy(snapshot_of(&plant, &servo, &driver, p));
        }
        if plant_pub.send_copy(p).is_err() {
            stats.publish_failures += 1;
        }
        s.publish_ns = rt::monotonic_ns();
        if servo_pub.send_copy(s).is_err() {
            stats.publish_failures += 1;
        }
        link.tick(&mut servo, now);

        // Loop statistics.
        let exec = rt::monotonic_ns().saturating_sub(now);
        hist::record(&mut timing.wake, late);
        hist::record(&mut timing.exec, exec);
        stats.ticks += 1;
        if late >= period_ns || exec >= period_ns {
            stats.misses += 1;
        }
        if stats.ticks.is_multiple_of(1000) {
            publish_stats(&mut stats, &timing, &gate, &link, &servo, &stats_pub);
        } else if stats.ticks % 1000 == 500 && link.is_idle() {
            // Every 0.1 s, between requests: drop the connections of an estimator that died
            // (a file pair per dead server) and connect a restarted one. Without a change
            // this only reads the service's port list; with one it maps or unmaps a segment,
            // as the next send would.
            link.update_connections();
            startup.update_connections();
        }
        seq += 1;
        deadline += period_ns;
        // Far behind (stopped in a debugger, machine suspended): re-anchor instead of
        // running a burst of ticks back to back.
        let now2 = rt::monotonic_ns();
        if now2 > deadline + 100 * period_ns {
            deadline = now2 + period_ns;
        }
    }
    publish_stats(&mut stats, &timing, &gate, &link, &servo, &stats_pub);
    if let Some(dir) = &args.histograms {
        timing.save(dir)?;
    }
    Ok(end)
}

fn snapshot_of(
    plant: &Plant,
    servo: &ServoCore,
    driver: &scenario::ScenarioDriver,
    plant_sample: PlantSample,
) -> WorldSnapshot {
    let st = plant.state();
    let memo = driver.memo();
    let face = |f: usize| u64::try_from(f).unwrap_or(u64::MAX);
    WorldSnapshot {
        version: msg::VERSION,
        driver_leg: memo.leg.unwrap_or(u32::MAX),
        seq: plant_sample.seq,
        time_s: st.time_s,
        q_rad: st.q,
        qd_rad_per_s: st.qd,
        friction_face: [face(st.friction[0].0), face(st.friction[1].0)],
        friction_deflection_m: [st.friction[0].1, st.friction[1].1],
        driver_leg_start: [memo.leg_start_s, memo.leg_start_u],
        controller: servo.state(),
        plant: plant_sample,
    }
}
