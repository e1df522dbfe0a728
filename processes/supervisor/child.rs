//! One supervised process: starting it, seeing it end, stopping it, and the timeline of each
//! (re)start (`BoardStartup` reports and the supervisor's own stamps).

use super::policy;
use crate::chaos::BoardView;
use crate::rt;
use crate::stack::{ProcessSpec, Timeline, resolve_binary};
use afs_shared::msg::{Board, BoardStartup, ProcessState};
use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// One end of a process.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExitRecord {
    /// Wall time since the stack started (s).
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub at_s: f64,
    /// The process that ended.
    pub pid: i32,
    /// `exit N` or `signal N`.
    pub status: String,
    /// Started again.
    pub restarted: bool,
    /// From the exit being seen to the restarted process's data flowing (ms).
    pub back_ms: Option<f64>,
    /// Where the restart's time went (restarted processes only).
    pub restart: Option<Timeline>,
    /// Monotonic time the exit was seen (ns): the timeline's zero.
    #[serde(skip)]
    seen_ns: u64,
    /// The process started in its place (0: none yet).
    #[serde(skip)]
    next_pid: i32,
}

/// What every board is started with.
#[derive(Debug, Clone)]
pub struct Launch {
    /// Stack prefix.
    pub prefix: String,
    /// Scenario name.
    pub scenario: String,
    /// Noise seed.
    pub seed: u64,
    /// The `[sim]` overrides, written to a file the boards read.
    pub sim_file: Option<PathBuf>,
    /// Simulated seconds (the servo's `--duration`).
    pub duration: f64,
    /// The `[robot]` table, written to a file the servo reads (`--robot-config`).
    pub robot_file: Option<PathBuf>,
    /// The simulated cell's part, written to a file the cell reads (`--cell-config`).
    pub cell_file: Option<PathBuf>,
}

/// How a process ended, as the supervisor handles it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// The servo finished its scenario (exit 0): the run is over.
    ServoFinished,
    /// To be started again after its backoff.
    Restarting,
    /// Not to be started again (its policy, or its restart budget spent).
    Stays,
    /// The robot is gone: the run's robot process (the simulated cell) ended, or the servo
    /// found the robot silent ([`crate::robot::ROBOT_LOST_EXIT`]). Not started again, and the
    /// run is over.
    RobotLost,
}

/// A supervised process.
pub struct Proc {
    /// Its table of the stack file.
    pub spec: ProcessSpec,
    /// The board it is (None: another process).
    pub board: Option<Board>,
    path: PathBuf,
    child: Option<Child>,
    /// Running, waiting to restart, ended.
    pub state: ProcessState,
    /// Restarts so far.
    pub restarts: u32,
    restart_at: Option<Instant>,
    /// Its last exit status (−signal when killed).
    pub last_exit: Option<i32>,
    /// Every end.
    pub exits: Vec<ExitRecord>,
    started: Instant,
    /// Times the stall policy killed it.
    pub stalls: u32,
    /// Consecutive deaths before coming up healthy: the backoff's exponent.
    streak: u32,
    /// When the current process's data started to flow.
    pub data_since: Option<Instant>,
    /// Frozen on purpose by the fault injector: no stall policy ([`Proc::hold`]).
    pub held: bool,
    /// When the injector last let it go: its silence counts from there.
    released: Option<Instant>,
    /// Restarts that injected faults cost, not held against `max_restarts`.
    pub injected_budget: u32,
    /// Monotonic time of the first spawn (ns), and that start's timeline.
    first_spawn_ns: u64,
    /// The first start's timeline.
    pub first_start: Timeline,
    /// It is the run's robot (the simulated cell, started with `--cell-config`): nothing runs
    /// the scenario on without it, so its end is the robot lost, never restarted.
    robot: bool,
}

fn exit_code(st: &ExitStatus) -> i32 {
    st.code().unwrap_or_else(|| -st.signal().unwrap_or(0))
}

fn describe(st: &ExitStatus) -> String {
    match (st.code(), st.signal()) {
        (Some(c), _) => format!("exit {c}"),
        (None, Some(s)) => format!("signal {s}"),
        _ => "unknown".into(),
    }
}

impl Proc {
    /// A process of the graph, not started yet (its binary must exist).
    pub fn new(spec: &ProcessSpec) -> Result<Self> {
        Ok(Self {
            board: spec.board(),
            path: resolve_binary(&spec.binary)?,
            spec: spec.clone(),
            child: None,
            state: ProcessState::Starting,
            restarts: 0,
            restart_at: None,
            last_exit: None,
            exits: Vec::new(),
            started: Instant::now(),
            stalls: 0,
            streak: 0,
            data_since: None,
            held: false,
            released: None,
            injected_budget: 0,
            first_spawn_ns: 0,
            first_start: Timeline::default(),
            robot: false,
        })
    }

    /// Starts it (a restarted servo with `--resume`); it gets SIGTERM if the supervisor dies.
    pub fn spawn(&mut self, l: &Launch, resume: bool) -> Result<()> {
        let mut cmd = Command::new(&self.path);
        cmd.args(["--prefix", &l.prefix, "--scenario", &l.scenario])
            .args(["--seed", &l.seed.to_string()]);
        if let Some(f) = &l.sim_file {
            cmd.arg("--sim-config").arg(f);
        }
        if let Some(c) = self.spec.cpu {
            cmd.args(["--cpu", &c.to_string()]);
        }
        cmd.args(["--priority", &self.spec.priority.to_string()]);
        if self.board == Some(Board::Servo) {
            cmd.args(["--duration", &l.duration.to_string()]);
            if resume {
                cmd.arg("--resume");
            }
            if let Some(f) = &l.robot_file {
                cmd.arg("--robot-config").arg(f);
            }
        }
        if self.spec.name == crate::stack::cell::CELL_PROCESS
            && let Some(f) = &l.cell_file
        {
            cmd.arg("--cell-config").arg(f);
            self.robot = true;
        }
        cmd.args(&self.spec.args);
        cmd.stdin(Stdio::null()).stdout(Stdio::null());
        // SAFETY: getpid is async-signal-safe; the closure only calls prctl/getppid/_exit.
        let parent = unsafe { libc::getpid() };
        unsafe {
            cmd.pre_exec(move || rt::die_with_parent(parent));
        }
        let called_ns = rt::monotonic_ns();
        let child = cmd
            .spawn()
            .with_context(|| format!("starting {} ({})", self.spec.name, self.path.display()))?;
        let spawned_ns = rt::monotonic_ns();
        let pid = child.id() as i32;
        self.child = Some(child);
        self.state = ProcessState::Running;
        self.started = Instant::now();
        self.held = false;
        self.released = None;
        self.data_since = None;
        match self.restarting() {
            Some(e) => {
                e.next_pid = pid;
                e.restart.get_or_insert_default().spawned_ms = Timeline::ms(e.seen_ns, spawned_ns);
            }
            None => {
                self.first_spawn_ns = called_ns;
                self.first_start.spawned_ms = Timeline::ms(called_ns, spawned_ns);
            }
        }
        Ok(())
    }

    /// The exit record of the process the current one replaced, if it is a restart.
    fn restarting(&mut self) -> Option<&mut ExitRecord> {
        self.exits.last_mut().filter(|e| e.restarted)
    }

    /// The current process's start-up report arrived.
    pub fn started_up(&mut self, r: &BoardStartup) {
        let pid = self.pid();
        match self.exits.last_mut() {
            Some(e) if e.restarted && e.next_pid == pid => {
                let zero = e.seen_ns;
                e.restart.get_or_insert_default().board(zero, r);
            }
            Some(_) => {}
            None => self.first_start.board(self.first_spawn_ns, r),
        }
    }

    /// The current process's data started to flow at `t` (`t_ns` on the monotonic clock).
    pub fn data_flowing(&mut self, t: Instant, t_ns: u64) {
        self.data_since = Some(t);
        match self.exits.last_mut() {
            Some(e) if e.restarted && e.back_ms.is_none() => {
                e.back_ms = Timeline::ms(e.seen_ns, t_ns);
                e.restart.get_or_insert_default().seen_ms = e.back_ms;
            }
            Some(_) => {}
            None => self.first_start.seen_ms = Timeline::ms(self.first_spawn_ns, t_ns),
        }
    }

    /// What the fault injector sees of it.
    pub fn view(&self) -> BoardView {
        BoardView {
            pid: if self.state == ProcessState::Running {
                self.pid()
            } else {
                0
            },
            data_since: self.data_since,
            stall_policy: self.spec.stall_ms > 0,
        }
    }

    /// What the fault injector sees of a process without a data stream of its own (the link
    /// board): its data counts as flowing from its start.
    pub fn view_from_start(&self) -> BoardView {
        let v = self.view();
        BoardView {
            data_since: (v.pid != 0).then_some(self.started),
            ..v
        }
    }

    /// Its pid (0: none).
    pub fn pid(&self) -> i32 {
        self.child.as_ref().map_or(0, |c| c.id() as i32)
    }

    /// Sends it a signal.
    pub fn signal(&self, sig: i32) {
        if let Some(c) = &self.child {
            // SAFETY: kill on our own child's pid.
            unsafe {
                libc::kill(c.id() as i32, sig);
            }
        }
    }

    /// Its exit status, if it has ended since the last look (reaped).
    pub fn try_reap(&mut self) -> Option<ExitStatus> {
        if self.state != ProcessState::Running {
            return None;
        }
        let st = self.child.as_mut()?.try_wait().ok().flatten()?;
        Some(st)
    }

    /// It ended with `st` (seen at `now`, `at_s` into the run, `seen_ns` on the monotonic
    /// clock): records the exit and applies the restart policy. `clean_up` removes what its
    /// node left (run before anything replaces it, and timed).
    pub fn ended(
        &mut self,
        st: ExitStatus,
        now: Instant,
        at_s: f64,
        seen_ns: u64,
        clean_up: impl FnOnce(),
    ) -> Ended {
        let pid = self.pid();
        let healthy = self
            .data_since
            .is_some_and(|t| now.duration_since(t) >= policy::HEALTHY_AFTER);
        self.child = None;
        self.last_exit = Some(exit_code(&st));
        self.data_since = None;
        self.held = false;
        let ok = st.code() == Some(0);
        let servo_finished = self.board == Some(Board::Servo) && ok;
        let robot_lost = self.robot
            || (self.board == Some(Board::Servo)
                && st.code() == Some(i32::from(crate::robot::ROBOT_LOST_EXIT)));
        let restart = !servo_finished
            && !robot_lost
            && policy::restarts(
                self.spec.restart,
                ok,
                self.restarts,
                self.spec.max_restarts + self.injected_budget,
            );
        let mut record = ExitRecord {
            at_s,
            pid,
            status: describe(&st),
            restarted: restart,
            back_ms: None,
            restart: None,
            seen_ns,
            next_pid: 0,
        };
        if servo_finished {
            self.state = ProcessState::Exited;
            self.exits.push(record);
            return Ended::ServoFinished;
        }
        clean_up();
        let mut timeline = Timeline {
            cleaned_ms: Timeline::ms(seen_ns, rt::monotonic_ns()),
            ..Timeline::default()
        };
        let ended = if restart {
            let (wait, streak) = policy::backoff(self.spec.backoff_ms, self.streak, healthy);
            self.streak = streak;
            timeline.backoff_ms = Some(wait.as_secs_f64() * 1e3);
            self.state = ProcessState::Restarting;
            self.restart_at = Some(now + wait);
            record.restart = Some(timeline);
            Ended::Restarting
        } else {
            self.state = if ok {
                ProcessState::Exited
            } else {
                ProcessState::Failed
            };
            eprintln!(
                "afs: {} ended ({}) and will not be restarted",
                self.spec.name, record.status
            );
            if robot_lost {
                Ended::RobotLost
            } else {
                Ended::Stays
            }
        };
        self.exits.push(record);
        ended
    }

    /// True when its backoff is over and it is to be started again.
    pub fn restart_due(&self, now: Instant) -> bool {
        self.state == ProcessState::Restarting && self.restart_at.is_some_and(|t| now >= t)
    }

    /// Starts it again (counted); a failure to start leaves it failed.
    pub fn restart(&mut self, l: &Launch) {
        self.restarts += 1;
        self.restart_at = None;
        if let Err(e) = self.spawn(l, self.board == Some(Board::Servo)) {
            eprintln!("afs: restarting {}: {e:#}", self.spec.name);
            self.state = ProcessState::Failed;
        }
    }

    /// Holds it (frozen on purpose by the fault injector: no stall policy) or lets it go at
    /// `now` (its stall limit then counts from `now`).
    pub fn hold(&mut self, held: bool, now: Instant) {
        if self.held && !held {
            self.released = Some(now);
        }
        self.held = held;
    }

    /// Kills it if it is alive but has been silent beyond its stall limit; `last_data` is when
    /// its data last arrived.
    pub fn kill_if_stalled(&mut self, now: Instant, last_data: Instant) {
        if self.state != ProcessState::Running {
            return;
        }
        let from = policy::silent_since(last_data, self.data_since, self.started, self.released);
        if policy::stalled(
            Duration::from_millis(self.spec.stall_ms),
            now.duration_since(from),
            self.data_since.is_some(),
            self.started.elapsed(),
            self.spec
                .start_grace_ms
                .map_or_else(|| policy::start_grace(self.board), Duration::from_millis),
            self.held,
        ) {
            eprintln!(
                "afs: {} (pid {}) is alive but silent for {} ms; killing it",
                self.spec.name,
                self.pid(),
                self.spec.stall_ms
            );
            self.stalls += 1;
            self.signal(libc::SIGKILL);
            // Until it is reaped (a stopped process takes a moment to die), it is not a stall
            // again.
            self.held = true;
        }
    }

    /// Stops the process: SIGTERM, then SIGKILL after `grace`. Reaps it.
    pub fn stop(&mut self, grace: Duration) {
        let Some(mut c) = self.child.take() else {
            return;
        };
        // SAFETY: kill on our own child's pid.
        unsafe {
            libc::kill(c.id() as i32, libc::SIGTERM);
        }
        let t0 = Instant::now();
        loop {
            match c.try_wait() {
                Ok(Some(st)) => {
                    self.last_exit = Some(exit_code(&st));
                    break;
                }
                Ok(None) if t0.elapsed() < grace => std::thread::sleep(Duration::from_millis(5)),
                _ => {
                    let _ = c.kill();
                    if let Ok(st) = c.wait() {
                        self.last_exit = Some(exit_code(&st));
                    }
                    break;
                }
            }
        }
        self.state = ProcessState::Exited;
    }
}
