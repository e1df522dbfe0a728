//! The servo board as a tick struct: its state in one place ([`ServoBoard`]), set up by
//! [`ServoBoard::start`], stepped by [`ServoBoard::tick`], closed by [`ServoBoard::finish`].

use super::ServoArgs;
use super::link::EstimatorLink;
use super::ports::Ports;
use super::timing::{Timing, publish_stats};
use crate::boards::Startup;
use crate::ipc;
use crate::ipc::Svc;
use crate::{hist, rt};
use afs_shared::insertion::rig::InsertionRig;
use afs_shared::msg::{
    Board, Command, InsertionState, LoopFlags, LoopStats, PlantSample, ServoCommand, ServoFlags,
    ServoSample, WorldSnapshot, WrenchFlags, WrenchSample,
};
use afs_shared::scenario::{DriverState, Scenario, ScenarioDriver};
use afs_shared::sensor::Wrench;
use afs_shared::servo::{ServoCore, ServoMode};
use afs_shared::tick::{Force, Step, servo_tick};
use afs_shared::watchdog::{GateCounters, GateParams, SampleGate, Verdict};
use afs_shared::world::{World, WorldStateAny};
use anyhow::{Context, Result, bail};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use std::sync::atomic::{AtomicBool, Ordering};

mod peg;

/// What a tick did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Tick {
    /// Ran; the scenario goes on.
    Ran,
    /// The scenario reached its end or its duration (nothing was run).
    Done,
}

/// The servo board: the world, the controller, the scenario driver, the force gate, the ports
/// and the loop's statistics.
pub(super) struct ServoBoard {
    servo: ServoCore,
    plant: World,
    driver: ScenarioDriver,
    gate: SampleGate,
    /// The gate's verdicts on the samples flagged as injected (`afs chaos`).
    injected: GateCounters,
    ports: Ports,
    link: EstimatorLink,
    startup: Startup,
    timing: Timing,
    stats: LoopStats,
    /// The next tick's number; ticks past `tick_limit` are not the scenario's.
    seq: u64,
    tick_limit: u64,
    dt: f64,
    period_ns: u64,
    /// When to check the connections of ports that send rarely (every 0.1 s).
    connections: rt::Every,
    /// Why the safe state was last entered (a [`Verdict`] code).
    safe_reason: u32,
    /// A tangent estimate asked for, until the servo can start it: the number of estimations
    /// started when it was sent (it lapses once more have started).
    estimate_wanted: Option<u32>,
    last_tare: Wrench,
    /// The insertion's rig (`insertion` scenario), which the tick runs instead of the arm.
    peg: Option<InsertionRig>,
}

impl ServoBoard {
    /// Opens the ports, resumes the world from the supervisor's blackboard (`--resume`),
    /// publishes it until the first force sample, builds or resumes the controller, and goes
    /// real-time. None if stopped first.
    pub(super) fn start(args: &ServoArgs, stop: &AtomicBool) -> Result<Option<Self>> {
        let mut scenario = Scenario::new(&args.scenario, &args.base).map_err(anyhow::Error::msg)?;
        // A user's MJCF brings its own arm: the controller and the world both use it.
        scenario.cfg = afs_shared::world::resolve(&scenario.cfg).map_err(anyhow::Error::msg)?;
        let cfg = &scenario.cfg;
        let dt = cfg.servo.dt();
        let period_ns = (dt * 1e9).round() as u64;
        let Opened {
            duration_s: duration,
            mut startup,
            ports,
            transport,
        } = open(args, scenario.natural_duration_s)?;

        // The world: fresh, or where the last servo left it, with the counts that go on
        // across restarts.
        let q0 = cfg.start_configuration().map_err(anyhow::Error::msg)?;
        let mut plant = World::new(cfg, q0).map_err(anyhow::Error::msg)?;
        let snapshot = match (&ports.world, args.resume) {
            (Some(w), true) => w.newest()?,
            _ => None,
        };
        let gate_params = GateParams {
            max_age_ns: (args.max_force_age_ms * 1e6) as u64,
            force_limit_n: cfg.sensor.range_force_n,
            torque_limit_nm: cfg.sensor.range_torque_nm,
            ..GateParams::default()
        };
        let (mut gate, mut injected) = (SampleGate::new(gate_params), GateCounters::default());
        if let Some(s) = &snapshot {
            plant
                .restore(&WorldStateAny::from(&s.world))
                .map_err(anyhow::Error::msg)?;
            gate = SampleGate::resume(gate_params, s.gate);
            injected = s.injected;
        }
        // A resumed servo starts by sending its predecessor's last tick again, then continues
        // with the next one.
        let mut seq = snapshot.map_or(0, |s| s.seq);
        let mut input = ForceInput {
            ports: &ports,
            gate: &mut gate,
            injected: &mut injected,
        };
        let peg = peg::rig(&scenario, snapshot.as_ref())?;
        let p0 = match (&peg, &snapshot) {
            (Some(rig), None) => peg::first_sample(rig, seq),
            _ => first_world_sample(&plant, snapshot.as_ref(), seq),
        };
        seq += 1;
        let Some(first) = input.wait(p0, args, period_ns, &mut startup, stop)? else {
            return Ok(None);
        };
        let (servo, driver) = controller(&scenario, q0, &first, snapshot.as_ref(), &plant)?;
        let mut board = Self {
            servo,
            plant,
            driver,
            gate,
            injected,
            ports,
            link: EstimatorLink::new(transport, args.estimator_timeout_s, args.estimator_attempts),
            startup,
            timing: Timing::new()?,
            stats: LoopStats {
                version: LoopStats::VERSION,
                period_ns,
                ..Default::default()
            },
            seq,
            // Ticks 1..=tick_limit are the scenario's (0 is the world's first sample): the
            // same count the lockstep runs, whatever restarts happen in between.
            tick_limit: (duration / dt).round() as u64,
            dt,
            period_ns,
            connections: rt::Every::new(rt::CONNECTIONS_EVERY_NS, rt::monotonic_ns()),
            safe_reason: 0,
            estimate_wanted: None,
            last_tare: first.tare(),
            peg,
        };
        board.go_realtime(args);
        Ok(Some(board))
    }

    /// SCHED_FIFO, memory lock and pinning, each refusal a warning; then the start-up report.
    fn go_realtime(&mut self, args: &ServoArgs) {
        let rtr = rt::setup(args.priority, true, args.cpu);
        self.startup.report.rt_ns = Startup::now();
        self.startup.send();
        for w in &rtr.warnings {
            eprintln!("afs-servo: warning: {w}");
        }
        self.stats.flags.set(LoopFlags::SCHED_FIFO, rtr.fifo);
        self.stats.flags.set(LoopFlags::MLOCKED, rtr.mlocked);
        self.stats.flags.set(LoopFlags::PINNED, rtr.pinned);
    }

    /// The servo period (ns).
    pub(super) fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// Whether it runs at SCHED_FIFO.
    pub(super) fn is_fifo(&self) -> bool {
        self.stats.flags.contains(LoopFlags::SCHED_FIFO)
    }

    /// One tick, woken for `deadline`: force data through the gate, the scenario, one
    /// controller and one world step, the tick published, the estimator request moved along,
    /// the loop's statistics. Allocates nothing, takes no lock, logs nothing.
    pub(super) fn tick(&mut self, deadline: u64) -> Tick {
        let now = rt::monotonic_ns();
        let late = now.saturating_sub(deadline);
        if self.peg.is_some() {
            return self.tick_peg(now, late);
        }
        self.take_force();
        let (force, used) = self.input(now, late);
        if self.seq > self.tick_limit {
            return Tick::Done;
        }
        // The lockstep's tick routine (`Lockstep::step_with` runs it too): the scenario and the
        // commands, the controller, the world.
        let Self {
            plant,
            servo,
            driver,
            ports,
            stats,
            estimate_wanted,
            dt,
            ..
        } = self;
        let step = servo_tick(plant, servo, force, *dt, |world, servo| {
            let (t, u) = (world.time(), world.truth().surface_u_m);
            if driver.step(t, u, servo) == DriverState::Done {
                return Step::Done;
            }
            take_commands(&ports.command, stats, estimate_wanted, servo);
            Step::Ran
        });
        if step == Step::Done {
            return Tick::Done;
        }
        if self.servo.is_safe() {
            self.stats.safe_ticks += 1;
        }
        self.publish(now, used);
        self.link.tick(&mut self.servo, now);
        self.account(now, late);
        self.seq += 1;
        Tick::Ran
    }

    /// Every new force sample through the gate.
    fn take_force(&mut self) {
        ForceInput {
            ports: &self.ports,
            gate: &mut self.gate,
            injected: &mut self.injected,
        }
        .take();
    }

    /// The force the tick uses, from the newest accepted force sample (its tare handed to the
    /// controller when it changed), and that sample with its age at `now` (None: none young
    /// enough, the safe state's reason noted).
    ///
    /// The sample's age is judged at the wake-up at SCHED_FIFO, where the sensor (above the
    /// servo) samples first after any stall, and at the tick's due time (`late` before `now`)
    /// at normal priority. There a servo that woke late (something else held its CPU) finds the
    /// data as old as its own lateness, its sensor, stalled with it on the same CPU, not having
    /// sampled since: that is the servo's stall, not the sensor's, and it does not put the
    /// servo in its safe state. A sensor that stops while the servo keeps time still does,
    /// at the limit after its last sample (docs/stack.md).
    fn input(&mut self, now: u64, late: u64) -> (Force, Option<(WrenchSample, u64)>) {
        let due = if self.is_fifo() {
            now
        } else {
            now.saturating_sub(late)
        };
        let mut input = Force::default();
        match self.gate.current(due) {
            Ok((w, _)) => {
                let age = now.saturating_sub(w.sample_ns);
                input.reading = w.wrench();
                input.valid = true;
                let tare = w.tare();
                if tare != self.last_tare {
                    self.servo.set_tare(tare);
                    self.last_tare = tare;
                }
                hist::record(&mut self.timing.age, age);
                (input, Some((w, age)))
            }
            Err(v) => {
                if v == Verdict::Stale {
                    self.stats.stale_ticks += 1;
                }
                if !self.servo.is_safe() {
                    self.safe_reason = v as u32;
                }
                (input, None)
            }
        }
    }

    /// The world snapshot first, then the world and controller samples: a servo killed
    /// between the two leaves a tick its successor sends again, never one that is sent twice
    /// with different contents.
    fn publish(&mut self, now: u64, used: Option<(WrenchSample, u64)>) {
        let p = PlantSample::of_tick(self.plant.truth(), self.seq, now);
        let s = ServoSample::of_tick(&self.servo, self.seq, now, self.plant.time());
        self.send(p, s, used, InsertionState::default());
    }

    /// Sends a tick's world and controller samples (`used`: the force sample the controller
    /// used, with its age), the world snapshot with `insertion` written first.
    fn send(
        &mut self,
        mut p: PlantSample,
        mut s: ServoSample,
        used: Option<(WrenchSample, u64)>,
        insertion: InsertionState,
    ) {
        s.safe_reason = self.safe_reason;
        if let Some((w, age)) = used {
            s.flags |= ServoFlags::FORCE_VALID;
            s.wrench_seq = w.seq;
            s.wrench_sample_ns = w.sample_ns;
            s.force_age_ns = age;
        }
        p.publish_ns = rt::monotonic_ns();
        if let Some(world) = &self.ports.world {
            let mut snapshot = self.snapshot(p);
            snapshot.insertion = insertion;
            world.write(snapshot);
        }
        if self.ports.plant.send_copy(p).is_err() {
            self.stats.publish_failures += 1;
        }
        s.publish_ns = rt::monotonic_ns();
        if self.ports.servo.send_copy(s).is_err() {
            self.stats.publish_failures += 1;
        }
    }

    /// What a restarted servo resumes from.
    fn snapshot(&self, plant: PlantSample) -> WorldSnapshot {
        WorldSnapshot {
            version: WorldSnapshot::VERSION,
            reserved: 0,
            seq: plant.seq,
            world: (&self.plant.state()).into(),
            driver: self.driver.memo().into(),
            controller: self.servo.state(),
            gate: self.gate.counters(),
            injected: self.injected,
            insertion: Default::default(),
            plant,
        }
    }

    /// Every 1000 ticks the statistics, and every 0.1 s between requests (at any rate, and
    /// never in the statistics' tick) the connections of ports that send rarely; then the
    /// tick's wake latency, execution time and miss. The execution time runs from the wake
    /// (`now`, the clock read after the sleep) to the end of these chores: all of the tick's
    /// own work, so the heaviest ticks show as execution time, not as the next tick's
    /// lateness (docs/stack.md, *The servo board*). Statistics published in a tick cover the
    /// ticks before it.
    fn account(&mut self, now: u64, late: u64) {
        self.stats.ticks += 1;
        if self.stats.ticks.is_multiple_of(1000) {
            self.publish_stats();
        } else if self.link.is_idle() && self.connections.due(now) {
            // Drop the connections of an estimator that died (a file pair per dead server)
            // and connect a restarted one. Without a change this only reads the service's
            // port list; with one it maps or unmaps a segment, as the next send would.
            self.link.update_connections();
            self.startup.update_connections();
        }
        let exec = rt::monotonic_ns().saturating_sub(now);
        hist::record(&mut self.timing.wake, late);
        hist::record(&mut self.timing.exec, exec);
        if late >= self.period_ns || exec >= self.period_ns {
            self.stats.misses += 1;
        }
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

    /// The last statistics, and the histograms saved if asked for.
    pub(super) fn finish(mut self, histograms: Option<&std::path::Path>) -> Result<()> {
        self.publish_stats();
        if let Some(dir) = histograms {
            self.timing.save(dir).context("saving the histograms")?;
        }
        Ok(())
    }
}

/// What either form of the board opens first.
pub(super) struct Opened {
    /// The scenario's length on this run (s): `--duration`, at most its natural one.
    pub(super) duration_s: f64,
    /// The start-up report, its node and ports phases stamped.
    pub(super) startup: Startup,
    /// The board's ports.
    pub(super) ports: Ports,
    /// The estimator's service.
    pub(super) transport: super::link::Transport,
}

/// The node, the ports and the start-up report's publisher of a servo board whose scenario
/// takes `natural_duration_s`.
pub(super) fn open(args: &ServoArgs, natural_duration_s: f64) -> Result<Opened> {
    let duration_s = if args.duration_s > 0.0 {
        args.duration_s.min(natural_duration_s)
    } else {
        natural_duration_s
    };
    let mut startup = Startup::new(Board::Servo, args.main_ns);
    let node = ipc::node(&args.prefix, Board::Servo.name())?;
    startup.report.node_ns = Startup::now();
    let (ports, transport) = Ports::open(&node, args)?;
    startup.open(&node)?;
    startup.report.ports_ns = Startup::now();
    Ok(Opened {
        duration_s,
        startup,
        ports,
        transport,
    })
}

/// The force samples' way in: the subscriber, the gate, and the count of injected samples.
pub(super) struct ForceInput<'a> {
    pub(super) ports: &'a Ports,
    pub(super) gate: &'a mut SampleGate,
    pub(super) injected: &'a mut GateCounters,
}

impl ForceInput<'_> {
    /// Every new force sample through the gate, judged against the clock at receipt: the
    /// sensor board outranks the servo on its core and may publish after this tick woke.
    pub(super) fn take(&mut self) {
        while let Ok(Some(s)) = self.ports.wrench.receive() {
            let w = s.payload();
            let v = self.gate.offer(w, rt::monotonic_ns());
            if w.flags.contains(WrenchFlags::INJECTED) {
                self.injected.count(v);
            }
        }
    }

    /// Publishes the world's first sample `p0` and waits for the first good force sample.
    /// None if stopped first.
    pub(super) fn wait(
        &mut self,
        p0: PlantSample,
        args: &ServoArgs,
        period_ns: u64,
        startup: &mut Startup,
        stop: &AtomicBool,
    ) -> Result<Option<WrenchSample>> {
        let t_wait = rt::monotonic_ns();
        startup.report.prepared_ns = t_wait;
        let _ = self.ports.plant.send_copy(p0);
        startup.report.data_ns = Startup::now();
        let mut next = t_wait;
        loop {
            if stop.load(Ordering::Relaxed) {
                return Ok(None);
            }
            let now = rt::monotonic_ns();
            let _ = self.ports.plant.update_connections();
            // Judged against the clock at receipt, as in the tick: the sensor board may
            // publish between the clock read above and this receive.
            self.take();
            if let Ok((w, _)) = self.gate.current(now) {
                startup.report.input_ns = now;
                return Ok(Some(w));
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
        }
    }
}

/// The world's first sample: after a restart, the last tick of the previous servo, bit for
/// bit as that one wrote it to the world blackboard before sending it (if it died between the
/// two, the tick is delivered now; if not, subscribers recognise the repeat,
/// docs/reliability.md); otherwise the world as it stands, tick `seq`.
fn first_world_sample(plant: &World, snapshot: Option<&WorldSnapshot>, seq: u64) -> PlantSample {
    match snapshot {
        Some(s) if s.plant.version == PlantSample::VERSION && s.plant.seq == s.seq => s.plant,
        _ => {
            let now = rt::monotonic_ns();
            let mut p = PlantSample::of_tick(plant.truth(), seq, now);
            p.publish_ns = rt::monotonic_ns();
            p
        }
    }
}

/// The controller built as the first servo's was (same start, so the same gains and
/// stiffness), then given its predecessor's state, and the scenario driver where it was: a
/// restarted servo carries on with the controller, not only with the world.
fn controller(
    scenario: &Scenario,
    q0: afs_shared::math::Vec2,
    first: &WrenchSample,
    snapshot: Option<&WorldSnapshot>,
    plant: &World,
) -> Result<(ServoCore, ScenarioDriver)> {
    let cfg = &scenario.cfg;
    let tangent0 = cfg.surface.tangent_angle_at(cfg.start_u_m) + cfg.tangent_error_rad;
    let wrench0 = first.wrench().tared(first.tare());
    let new = |q| {
        ServoCore::new(
            cfg.servo_params(),
            cfg.plant.arm,
            cfg.plant.elbow,
            q,
            wrench0,
            tangent0,
        )
        .map_err(anyhow::Error::msg)
    };
    let mut servo = new(q0)?;
    let mut driver = scenario.driver();
    if let Some(s) = snapshot {
        driver.resume(s.world.time_s, (&s.driver).into());
        if let Err(e) = servo.restore(&s.controller) {
            // The world carries on; the controller starts afresh from it.
            eprintln!("afs-servo: warning: {e}; the controller starts afresh");
            servo = new(plant.joints().0)?;
        }
    }
    servo.set_tare(first.tare());
    Ok((servo, driver))
}

/// Commands: a tangent estimate asked for (`wanted`: the number of estimations started when it
/// was sent) starts once the servo tracks (the lockstep reference replays it at the same tick,
/// `Replay::requested`), unless one started since.
pub(super) fn take_commands(
    command: &Subscriber<Svc, ServoCommand, ()>,
    stats: &mut LoopStats,
    wanted: &mut Option<u32>,
    servo: &mut ServoCore,
) {
    while let Ok(Some(c)) = command.receive() {
        let c = *c.payload();
        stats.commands += 1;
        if c.version == ServoCommand::VERSION
            && Command::try_from(c.command) == Ok(Command::EstimateTangent)
        {
            *wanted = Some(c.started_before);
        } else {
            stats.bad_commands += 1;
        }
    }
    if let Some(before) = *wanted {
        if servo.counters().started > before {
            *wanted = None;
        } else if servo.mode() == ServoMode::Track {
            servo.request_tangent_estimate();
            *wanted = None;
        }
    }
}
