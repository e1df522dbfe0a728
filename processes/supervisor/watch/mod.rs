//! The supervisor's loop (every 5 ms): the streams in (`streams`), the fault injector
//! (`faults`), the children (reaped, restarted, killed when stalled), the status stream and the
//! progress line (`progress`).

mod faults;
mod progress;
mod streams;

pub use streams::{Ports, Sinks};

use super::child::{Ended, Launch, Proc};
use crate::chaos::{Injector, LinkCut, ServoView};
use crate::ipc;
use crate::observe::record::RecordSummary;
use crate::observe::view::{LiveView, ViewSummary};
use crate::rt;
use crate::stack::Footprint;
use afs_shared::faults::FaultMonitor;
use afs_shared::join::Joiner;
use afs_shared::msg::{
    self, Board, FrictionReport, LoopStats, ProcessState, SensorStats, WrenchSample,
};
use afs_shared::scenario::{Scenario, ScenarioMonitor};
use anyhow::Result;
use iceoryx2::port::update_connections::UpdateConnections;
use serde::{Deserialize, Serialize};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The first contact's transient is not a fault's: the normal force counts from here (s).
const FAULT_SETTLE_S: f64 = 0.5;

/// The force the safety figures are measured against (N): the preload while tracking, the
/// insertion force in an insertion.
pub(super) fn nominal_force_n(scenario: &Scenario) -> f64 {
    scenario
        .insertion
        .map_or(scenario.cfg.servo.hybrid.preload_n, |o| {
            o.controller_params().insertion_force_n
        })
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
    /// The robot was lost: the simulated cell's process ended, or the servo found the robot
    /// silent ([`crate::robot::ROBOT_LOST_EXIT`]).
    RobotLost,
}

impl RunEnd {
    /// In words, for the report's check.
    pub fn describe(self) -> &'static str {
        match self {
            RunEnd::Finished => "ran to its end",
            RunEnd::Interrupted => "interrupted by a signal",
            RunEnd::WallLimit => "stopped by the wall-time limit",
            RunEnd::ServoGaveUp => "stopped: the servo gave up",
            RunEnd::RobotLost => "stopped: the robot was lost",
        }
    }
}

/// The wall time a run of `duration` simulated seconds gets by default (s): the duration
/// plus generous start-up and restart slack.
pub fn default_wall_limit_s(duration: f64) -> f64 {
    duration * 1.5 + 30.0
}

/// A running stack under watch.
pub struct Supervisor {
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
    /// Why the robot was lost, once it was (the run then ends).
    robot_lost: Option<String>,
    genuine: Option<WrenchSample>,
    scenario_name: &'static str,
}

impl Supervisor {
    /// A supervisor of `procs` (not started yet) running `scenario` for `duration` simulated
    /// seconds, without recording, faults or progress line (see the methods below).
    pub fn new(
        procs: Vec<Proc>,
        launch: Launch,
        scenario: &Scenario,
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
            faults: FaultMonitor::new(nominal_force_n(scenario), FAULT_SETTLE_S)
                .with_period_ns((1e9 / scenario.cfg.servo.rate_hz).round() as u64),
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
            robot_lost: None,
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
        // When the servo finished its scenario (the run ends once no faulted board is on its
        // way back).
        let mut finished: Option<Instant> = None;
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
            // Past the scenario's end, only a fault already under way goes on: a board frozen
            // or killed near the end is let back (its recovery is the fault's record), and no
            // other fault starts.
            let recovering = self
                .injector
                .as_ref()
                .is_some_and(crate::chaos::Injector::bringing_back);
            if finished.is_none() || recovering {
                self.inject();
                // The injector may take a while (the steady footprint reads /proc and the
                // shared-memory files: over 100 ms on a loaded machine), and the streams went
                // unread meanwhile: read them again, or the stall policy below takes the
                // supervisor's own pause for a board's silence.
                self.poll_streams();
            }
            if self.watch_children() {
                finished = Some(Instant::now());
            }
            if let Some(at) = finished {
                let recovering = self
                    .injector
                    .as_ref()
                    .is_some_and(crate::chaos::Injector::bringing_back);
                if !recovering || at.elapsed() > crate::chaos::RECOVERY_WAIT {
                    self.end = Some(RunEnd::Finished);
                    break;
                }
            }
            if let Some(why) = self.robot_lost.take() {
                eprintln!("afs: the robot was lost ({why}); stopping the run");
                self.end = Some(RunEnd::RobotLost);
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
                if ended == Ended::RobotLost {
                    self.robot_lost = Some(format!(
                        "process '{}' ended: {}",
                        p.spec.name,
                        p.exits.last().map_or("", |e| e.status.as_str())
                    ));
                }
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
