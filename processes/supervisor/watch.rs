//! The supervisor's loop (every 5 ms): the streams in, the fault injector, the children
//! (reaped, restarted, killed when stalled), the status stream and the progress line.

use super::FAULT_SETTLE_S;
use super::LINK_PROCESS;
use super::child::{Ended, Launch, Proc};
use super::footprint::Footprint;
use crate::chaos::{Action, BoardView, Injector, LinkCut, ServoView};
use crate::ipc::{self, Svc};
use crate::rt;
use crate::tools::record::{Rec, RecordSummary, Recorder};
use crate::tools::view::{self, LiveView, ViewSummary};
use afs_shared::faults::FaultMonitor;
use afs_shared::join::Joiner;
use afs_shared::msg::{
    self, Board, BoardStartup, FrictionReport, LoopStats, PlantSample, ProcessState, ProcessStatus,
    SensorStats, ServoCommand, ServoSample, SupervisorStatus, WrenchFlags, WrenchSample, fixed_str,
};
use afs_shared::scenario::{Scenario, ScenarioMonitor};
use afs_shared::servo::ServoMode;
use anyhow::{Context, Result};
use iceoryx2::node::Node;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use serde::{Deserialize, Serialize};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The ports the supervisor reads and writes.
pub struct Ports {
    plant: Subscriber<Svc, PlantSample, ()>,
    servo: Subscriber<Svc, ServoSample, ()>,
    wrench: Subscriber<Svc, WrenchSample, ()>,
    /// The servo loop's statistics.
    pub stats: Subscriber<Svc, LoopStats, ()>,
    /// The sensor board's statistics.
    pub sensor_stats: Subscriber<Svc, SensorStats, ()>,
    friction: Subscriber<Svc, FrictionReport, ()>,
    startup: Subscriber<Svc, BoardStartup, ()>,
    status: Publisher<Svc, SupervisorStatus, ()>,
    command: Publisher<Svc, ServoCommand, ()>,
}

impl Ports {
    /// Opens them on the supervisor's node.
    pub fn open(node: &Node<Svc>) -> Result<Self> {
        Ok(Self {
            plant: ipc::plant(node)?
                .subscriber_builder()
                .buffer_size(ipc::TICK_BUFFER)
                .create()
                .context("creating the plant subscriber")?,
            servo: ipc::servo(node)?
                .subscriber_builder()
                .buffer_size(ipc::TICK_BUFFER)
                .create()
                .context("creating the servo subscriber")?,
            wrench: ipc::wrench(node)?
                .subscriber_builder()
                .buffer_size(ipc::WRENCH_BUFFER)
                .create()
                .context("creating the wrench subscriber")?,
            stats: ipc::loop_stats(node)?
                .subscriber_builder()
                .create()
                .context("creating the loop-statistics subscriber")?,
            sensor_stats: ipc::sensor_stats(node)?
                .subscriber_builder()
                .create()
                .context("creating the sensor-statistics subscriber")?,
            friction: ipc::friction(node)?
                .subscriber_builder()
                .create()
                .context("creating the friction subscriber")?,
            startup: ipc::startup(node)?
                .subscriber_builder()
                .create()
                .context("creating the start-up subscriber")?,
            status: ipc::supervisor(node)?
                .publisher_builder()
                .create()
                .context("creating the status publisher")?,
            command: ipc::command(node)?
                .publisher_builder()
                .create()
                .context("creating the command publisher")?,
        })
    }
}

/// Where the supervisor's samples go besides its own checks: the recording and the live view.
/// Neither can block the supervisor (both hand over through channels that drop when full).
#[derive(Default)]
pub struct Sinks {
    /// The MCAP recording (`--record`).
    pub recorder: Option<Recorder>,
    /// The Foxglove view (`--foxglove`).
    pub view: Option<LiveView>,
}

impl Sinks {
    fn any(&self) -> bool {
        self.recorder.is_some() || self.view.is_some()
    }

    fn push(&mut self, r: Rec) {
        if let Some(x) = self.recorder.as_mut() {
            x.push(r);
        }
        if let Some(v) = self.view.as_mut() {
            v.push(r);
        }
    }
}

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunEnd {
    /// The servo ran the scenario to its end (or to the run's duration).
    Finished,
    /// Stopped by a signal (SIGINT, SIGTERM).
    Interrupted,
    /// The wall-time limit passed first.
    WallLimit,
    /// The servo gave up (its restart limit).
    ServoGaveUp,
}

impl RunEnd {
    /// In words, for the report's check.
    pub fn describe(self) -> &'static str {
        match self {
            RunEnd::Finished => "ran to its end",
            RunEnd::Interrupted => "interrupted by a signal",
            RunEnd::WallLimit => "stopped by the wall-time limit",
            RunEnd::ServoGaveUp => "stopped: the servo gave up",
        }
    }
}

/// The wall time a run of `duration` simulated seconds gets by default (s): the duration
/// plus generous start-up and restart slack.
pub fn default_wall_limit_s(duration: f64) -> f64 {
    duration * 1.5 + 30.0
}

/// A running stack under watch.
pub struct Supervisor<'a> {
    /// The processes of the graph.
    pub procs: Vec<Proc>,
    launch: Launch,
    duration: f64,
    /// The ports (the loop statistics are read once more after the stop).
    pub ports: Ports,
    sinks: Sinks,
    /// The fault injector (`afs chaos`).
    pub injector: Option<Injector>,
    /// The commands that cut the link and restore it.
    link_cut: Option<LinkCut>,
    /// The scenario's figures from the samples.
    pub monitor: ScenarioMonitor,
    /// Safety figures.
    pub faults: FaultMonitor,
    /// The stack's footprint while steady before the first fault and after the last.
    pub steady: [Option<Footprint>; 2],
    /// The world and controller streams, joined.
    pub joiner: Joiner,
    /// The servo loop's newest statistics.
    pub stats: Option<LoopStats>,
    /// The sensor board's newest statistics.
    pub sensor_stats: Option<SensorStats>,
    /// The estimator's newest friction report.
    pub friction: Option<FrictionReport>,
    /// Why the run ended (None while it runs).
    pub end: Option<RunEnd>,
    /// Wall time the run may take before the supervisor stops it.
    wall_limit: Duration,
    /// Force samples received.
    pub wrench_received: u64,
    progress: bool,
    t0: Instant,
    /// When each board's data last arrived (servo: world samples; sensor: genuine force
    /// samples; estimator: friction reports), for the stall policy.
    last_data: [Instant; 3],
    last_status: Instant,
    last_progress: Instant,
    status_seq: u64,
    command_seq: u64,
    last_time_s: f64,
    servo_view: ServoView,
    /// The first tick of a restarted servo (None until its first sample arrives).
    servo_resumes_at: Option<u64>,
    genuine: Option<WrenchSample>,
    scenario_name: &'a str,
}

impl<'a> Supervisor<'a> {
    /// A supervisor of `procs` (not started yet) running `scenario` for `duration` simulated
    /// seconds, without recording, faults or progress line (see the methods below).
    pub fn new(
        procs: Vec<Proc>,
        launch: Launch,
        scenario: &'a Scenario,
        duration: f64,
        ports: Ports,
    ) -> Self {
        let now = Instant::now();
        Self {
            procs,
            launch,
            duration,
            ports,
            sinks: Sinks::default(),
            injector: None,
            link_cut: None,
            monitor: scenario.monitor(),
            faults: FaultMonitor::new(scenario.cfg.servo.hybrid.preload_n, FAULT_SETTLE_S),
            steady: [None, None],
            joiner: Joiner::default(),
            stats: None,
            sensor_stats: None,
            friction: None,
            end: None,
            wall_limit: Duration::from_secs_f64(default_wall_limit_s(duration)),
            wrench_received: 0,
            progress: false,
            t0: now,
            last_data: [now; 3],
            last_status: now,
            last_progress: now,
            status_seq: 0,
            command_seq: 0,
            last_time_s: 0.0,
            servo_view: ServoView::default(),
            servo_resumes_at: None,
            genuine: None,
            scenario_name: scenario.kind.name(),
        }
    }

    /// Stops the run after `limit` of wall time (its report then fails `reached_end`).
    pub fn with_wall_limit(self, limit: Duration) -> Self {
        Self {
            wall_limit: limit,
            ..self
        }
    }

    /// Records every topic and shows them live with `sinks`.
    pub fn with_sinks(self, sinks: Sinks) -> Self {
        Self { sinks, ..self }
    }

    /// Injects faults with `injector`.
    pub fn injecting(self, injector: Option<Injector>) -> Self {
        Self { injector, ..self }
    }

    /// Cuts the link with `link_cut`'s commands when the injector asks.
    pub fn cutting_with(self, link_cut: Option<LinkCut>) -> Self {
        Self { link_cut, ..self }
    }

    /// Prints a progress line on stderr when `progress`.
    pub fn with_progress(self, progress: bool) -> Self {
        Self { progress, ..self }
    }

    fn proc_mut(&mut self, b: Board) -> Option<&mut Proc> {
        self.procs.iter_mut().find(|p| p.board == Some(b))
    }

    /// Starts the graph and watches it until the scenario ends, `stop` is set, the servo
    /// gives up, or the wall-clock limit passes.
    pub fn run(&mut self, stop: &AtomicBool) -> Result<()> {
        self.t0 = Instant::now();
        // Servo first (it publishes the world the sensor samples), then the others.
        for b in Board::ALL {
            if let Some(p) = self.procs.iter_mut().find(|p| p.board == Some(b)) {
                p.spawn(&self.launch, false)?;
            }
        }
        for p in self
            .procs
            .iter_mut()
            .filter(|p| p.state == ProcessState::Starting)
        {
            p.spawn(&self.launch, false)?;
        }
        let tty = std::io::stderr().is_terminal();
        let limit = self.wall_limit;
        loop {
            std::thread::sleep(Duration::from_millis(5));
            if stop.load(Ordering::Relaxed) {
                self.end = Some(RunEnd::Interrupted);
                break;
            }
            self.poll_streams();
            // The supervisor's own publishers send rarely (status) or on demand (commands):
            // drop their connections to subscribers that died (a killed servo's) as soon as
            // iceoryx2 has cleaned them; without a change this compares a counter.
            let _ = self.ports.status.update_connections();
            let _ = self.ports.command.update_connections();
            self.inject();
            if self.watch_children() {
                self.end = Some(RunEnd::Finished);
                break;
            }
            let servo_failed = self
                .procs
                .iter()
                .any(|p| p.board == Some(Board::Servo) && p.state == ProcessState::Failed);
            if servo_failed {
                self.end = Some(RunEnd::ServoGaveUp);
                break;
            }
            if self.t0.elapsed() > limit {
                eprintln!(
                    "afs: the scenario did not end within {:.1} s of wall time (the wall-time limit); stopping",
                    limit.as_secs_f64()
                );
                self.end = Some(RunEnd::WallLimit);
                break;
            }
            self.publish_status();
            self.print_progress(tty);
        }
        if self.progress && tty {
            eprintln!();
        }
        self.drain();
        Ok(())
    }

    /// Reads every stream: world and controller samples (joined, monitored, recorded), force
    /// samples, start-up reports, loop statistics, friction reports.
    fn poll_streams(&mut self) {
        while let Ok(Some(s)) = self.ports.plant.receive() {
            let p = *s.payload();
            self.last_data[Board::Servo as usize] = Instant::now();
            self.servo_sample_seen(&p);
            if self.joiner.is_repeat(&p) {
                continue;
            }
            self.last_time_s = p.time_s;
            self.sinks.push(Rec::Plant(p));
            self.joiner.push_plant(p);
        }
        while let Ok(Some(s)) = self.ports.servo.receive() {
            let v = *s.payload();
            self.servo_view = ServoView {
                mode: ServoMode::try_from(v.mode).ok(),
                started: v.estimations_started,
            };
            self.sinks.push(Rec::Servo(v));
            self.joiner.push_servo(v);
        }
        self.pair();
        while let Ok(Some(s)) = self.ports.wrench.receive() {
            let w = *s.payload();
            self.wrench_received += 1;
            if !w.flags.contains(WrenchFlags::INJECTED) {
                let now = Instant::now();
                self.last_data[Board::Sensor as usize] = now;
                let new_epoch = self.genuine.is_none_or(|g| w.epoch_ns != g.epoch_ns);
                self.genuine = Some(w);
                if new_epoch
                    && let Some(sn) = self.proc_mut(Board::Sensor)
                    && sn.state == ProcessState::Running
                {
                    sn.data_flowing(now, rt::monotonic_ns());
                }
            }
            self.sinks.push(Rec::Wrench(w));
        }
        while let Ok(Some(s)) = self.ports.startup.receive() {
            let r = *s.payload();
            if let Some(p) = self
                .procs
                .iter_mut()
                .find(|p| p.state == ProcessState::Running && p.pid() == r.pid)
            {
                p.started_up(&r);
                // The estimator has no stream of its own: it serves once its ports are open.
                if p.board == Some(Board::Estimator) && p.data_since.is_none() {
                    p.data_flowing(Instant::now(), rt::monotonic_ns());
                }
            }
        }
        while let Ok(Some(s)) = self.ports.sensor_stats.receive() {
            self.sensor_stats = Some(*s.payload());
            self.sinks.push(Rec::SensorStats(*s.payload()));
        }
        while let Ok(Some(s)) = self.ports.stats.receive() {
            self.stats = Some(*s.payload());
            self.sinks.push(Rec::Stats(*s.payload()));
        }
        while let Ok(Some(s)) = self.ports.friction.receive() {
            self.last_data[Board::Estimator as usize] = Instant::now();
            self.friction = Some(*s.payload());
            self.sinks.push(Rec::Friction(*s.payload()));
        }
    }

    /// A world sample arrived: it may be a (restarted) servo's data starting to flow. A
    /// restarted servo's first sample is its predecessor's last tick again (from the snapshot
    /// it resumes): its own ticks, and the world going on, start at the next one.
    fn servo_sample_seen(&mut self, p: &PlantSample) {
        let now = Instant::now();
        let Some(sv) = self
            .procs
            .iter_mut()
            .find(|q| q.board == Some(Board::Servo))
        else {
            return;
        };
        if sv.data_since.is_some() || sv.state != ProcessState::Running {
            return;
        }
        let flowing = sv.restarts == 0 || {
            let first = *self.servo_resumes_at.get_or_insert_with(|| {
                self.faults.servo_restarted_at(p.seq + 1);
                self.monitor.servo_restarted_at(p.seq + 1);
                p.seq + 1
            });
            p.seq >= first
        };
        if flowing {
            sv.data_flowing(now, rt::monotonic_ns());
        }
    }

    /// Feeds the ticks with both samples to the monitors.
    fn pair(&mut self) {
        let (monitor, faults, sinks) = (&mut self.monitor, &mut self.faults, &mut self.sinks);
        let live = sinks.any();
        self.joiner.pairs(|p, s| {
            monitor.push(p, s);
            faults.push(p, s);
            if live && let Some(r) = view::live(p, s) {
                sinks.push(r);
            }
        });
    }

    /// One step of the fault injector, and what it asks for.
    fn inject(&mut self) {
        let Some(inj) = self.injector.as_mut() else {
            return;
        };
        let mut views = [BoardView::default(); 3];
        for b in Board::ALL {
            if let Some(p) = self.procs.iter().find(|p| p.board == Some(b)) {
                views[b as usize] = p.view();
            }
        }
        // The link board has no data stream here: it counts as up from its start.
        let link = self
            .procs
            .iter()
            .find(|p| p.spec.name == LINK_PROCESS)
            .map_or_else(BoardView::default, Proc::view_from_start);
        // Every board of this graph up (on a two-host stack the estimator is elsewhere).
        let all_up = Board::ALL
            .iter()
            .filter(|b| self.procs.iter().any(|p| p.board == Some(**b)))
            .all(|b| {
                let v = views[*b as usize];
                v.pid != 0
                    && v.data_since
                        .is_some_and(|t| t.elapsed() > Duration::from_millis(500))
            });
        if all_up && inj.idle() {
            let slot = if inj.records().is_empty() {
                Some(0)
            } else if inj.done() {
                Some(1)
            } else {
                None
            };
            if let Some(slot) = slot
                && self.steady[slot].is_none()
            {
                self.steady[slot] = Some(Footprint::now(&self.launch.prefix, &self.procs, self.t0));
            }
        }
        if let Some(c) = self.link_cut.as_mut() {
            for e in c.poll() {
                eprintln!("afs: warning: {e}");
                inj.note(&e);
            }
        }
        let actions = inj.step(
            self.last_time_s,
            self.servo_view,
            &views,
            link,
            self.genuine.as_ref(),
        );
        for a in actions {
            match a {
                Action::Signal(b, sig) => {
                    if let Some(p) = self.proc_mut(b) {
                        p.signal(sig);
                    }
                }
                Action::Hold(b, h) => {
                    if let Some(p) = self.proc_mut(b) {
                        p.held = h;
                    }
                }
                Action::SignalLink(sig) => {
                    if let Some(p) = self.procs.iter().find(|p| p.spec.name == LINK_PROCESS) {
                        p.signal(sig);
                    }
                }
                Action::CutLink(cut) => {
                    // The plan has no cut without the commands (chaos::plan).
                    if let Some(c) = self.link_cut.as_mut()
                        && let Err(e) = c.start(cut)
                    {
                        eprintln!("afs: warning: {e}");
                        if let Some(inj) = self.injector.as_mut() {
                            inj.note(&e);
                        }
                    }
                }
                Action::AskProbe { started_before } => {
                    self.command_seq += 1;
                    let _ = self.ports.command.send_copy(ServoCommand {
                        version: msg::VERSION,
                        command: msg::Command::EstimateTangent.into(),
                        seq: self.command_seq,
                        publish_ns: rt::monotonic_ns(),
                        started_before,
                        reserved: 0,
                    });
                }
            }
        }
    }

    /// Reaps, restarts and stall-kills the children; true once the servo finished.
    fn watch_children(&mut self) -> bool {
        let now = Instant::now();
        let at_s = self.t0.elapsed().as_secs_f64();
        let prefix = self.launch.prefix.clone();
        let mut servo_done = false;
        for p in self.procs.iter_mut() {
            if let Some(st) = p.try_reap() {
                // Its node is dead: remove its stale resources before anything replaces it.
                let ended = p.ended(st, now, at_s, rt::monotonic_ns(), || {
                    let _ = ipc::census(&prefix, true);
                });
                servo_done |= ended == Ended::ServoFinished;
                continue;
            }
            if let Some(b) = p.board {
                p.kill_if_stalled(now, self.last_data[b as usize]);
            }
            if p.restart_due(now) {
                if p.board == Some(Board::Servo) {
                    self.servo_resumes_at = None;
                }
                p.restart(&self.launch);
                // The new process gets its own start-up grace before stall checks.
                if let Some(b) = p.board {
                    self.last_data[b as usize] = Instant::now();
                }
            }
        }
        servo_done
    }

    /// Publishes (and records) the supervisor's status every 0.5 s.
    fn publish_status(&mut self) {
        if self.last_status.elapsed() < Duration::from_millis(500) {
            return;
        }
        self.send_status(msg::SupervisorPhase::Running);
    }

    /// Publishes (and records) the supervisor's status now.
    fn send_status(&mut self, phase: msg::SupervisorPhase) {
        self.last_status = Instant::now();
        self.status_seq += 1;
        let mut st = SupervisorStatus {
            version: msg::VERSION,
            process_count: self.procs.len() as u32,
            seq: self.status_seq,
            publish_ns: rt::monotonic_ns(),
            pid: std::process::id() as i32,
            phase: phase.into(),
            scenario: fixed_str(self.scenario_name),
            elapsed_s: self.last_time_s,
            duration_s: self.duration,
            ..Default::default()
        };
        for (i, p) in self.procs.iter().enumerate().take(msg::MAX_PROCESSES) {
            st.processes[i] = ProcessStatus {
                name: fixed_str(&p.spec.name),
                pid: p.pid(),
                state: p.state.into(),
                restarts: p.restarts,
                last_exit: p.last_exit.unwrap_or(i32::MIN),
            };
        }
        let _ = self.ports.status.send_copy(st);
        self.sinks.push(Rec::Status(st));
    }

    /// A progress line on stderr every second (rewritten in place on a terminal).
    fn print_progress(&mut self, tty: bool) {
        if !self.progress || self.last_progress.elapsed() < Duration::from_secs(1) {
            return;
        }
        self.last_progress = Instant::now();
        let r = self.monitor.report();
        let restarts: u32 = self.procs.iter().map(|p| p.restarts).sum();
        let (jit, age) = self.stats.as_ref().map_or((0.0, 0.0), |st| {
            (
                st.wake_latency.p99 as f64 / 1000.0,
                st.force_age.p99 as f64 / 1000.0,
            )
        });
        let line = format!(
            "afs: {:6.1}/{:.0} s  travelled {:5.1} mm  tangent err RMS {:4.2}°  estimates {}  safe ticks {}  wake p99 {jit:5.1} µs  force age p99 {age:5.1} µs  restarts {restarts}",
            self.last_time_s,
            self.duration,
            r.tracking.travelled_m * 1e3,
            r.tracking.tangent_error_rms_deg,
            r.tracking.estimations.estimates,
            r.safe_ticks,
        );
        if tty {
            eprint!("\r{line}\x1b[K");
        } else {
            eprintln!("{line}");
        }
    }

    /// What is still in flight after the loop.
    fn drain(&mut self) {
        while let Ok(Some(s)) = self.ports.plant.receive() {
            let p = *s.payload();
            if self.joiner.is_repeat(&p) {
                continue;
            }
            self.sinks.push(Rec::Plant(p));
            self.joiner.push_plant(p);
        }
        while let Ok(Some(s)) = self.ports.servo.receive() {
            self.sinks.push(Rec::Servo(*s.payload()));
            self.joiner.push_servo(*s.payload());
        }
        self.pair();
        while let Ok(Some(s)) = self.ports.friction.receive() {
            self.friction = Some(*s.payload());
        }
    }

    /// Stops the graph in order: the servo first (it holds the world), then the estimator and
    /// the sensor, then the rest. Reads the servo's last statistics. Returns the wall time the
    /// run took (s).
    pub fn shut_down(&mut self) -> f64 {
        let wall_s = self.t0.elapsed().as_secs_f64();
        // A cut outlasting the run is restored first: the link is the machine's, not the run's.
        if let (Some(inj), Some(c)) = (self.injector.as_mut(), self.link_cut.as_mut())
            && inj.cutting()
        {
            inj.note("restored at the run's end");
            for e in c.restore_now() {
                eprintln!("afs: warning: {e}");
                inj.note(&e);
            }
        }
        // Observers (`afs view`) leave on this, before the prefix is released.
        self.send_status(msg::SupervisorPhase::Stopping);
        for b in [Board::Servo, Board::Estimator, Board::Sensor] {
            if let Some(p) = self.proc_mut(b) {
                p.stop(Duration::from_secs(2));
            }
        }
        for p in self.procs.iter_mut() {
            p.stop(Duration::from_secs(2));
        }
        // The servo's and the sensor's last words.
        while let Ok(Some(s)) = self.ports.stats.receive() {
            self.stats = Some(*s.payload());
        }
        while let Ok(Some(s)) = self.ports.sensor_stats.receive() {
            self.sensor_stats = Some(*s.payload());
        }
        wall_s
    }

    /// Ends the recording and the live view, if any.
    pub fn finish_sinks(&mut self) -> Result<(Option<RecordSummary>, Option<ViewSummary>)> {
        let view = self.sinks.view.take().map(LiveView::finish);
        let record = self.sinks.recorder.take().map(|r| r.finish()).transpose()?;
        Ok((record, view))
    }
}
