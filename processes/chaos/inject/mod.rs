//! The fault injector.
//!
//! The [`Injector`] lives in the supervisor's loop (every 5 ms): it decides when a planned
//! fault is due (simulated time), returns the signals to send, publishes the bad force samples
//! itself, and times the recovery (until the killed board's data flows again). A fault that
//! needs the servo to probe the tangent (mid-probe, mid-request) asks the servo for a probe
//! when it is due, or takes the probe under way, and strikes when the strokes start. One fault
//! is in progress at a time; a fault waits until its board's data has flowed for
//! [`MIN_UPTIME`]. The link's faults (docs/link.md) kill the link board, or ask the supervisor
//! to run the stack file's commands that cut the link and, [`Injector::with_cut`] later,
//! restore it.

mod record;

pub use record::{Action, BoardView, FaultRecord, ServoView};

use super::bad::BadSampleSender;
use afs_shared::faults::{Board, FaultKind, PlannedFault};
use afs_shared::msg::WrenchSample;
use afs_shared::servo::ServoMode;
use std::time::{Duration, Instant};

/// A board is only faulted again after its data has flowed this long (longer than the
/// supervisor's `HEALTHY_AFTER`, so an injected fault never looks like a crash loop).
pub const MIN_UPTIME: Duration = Duration::from_millis(500);
/// A frozen board with no stall policy gets SIGCONT after this long.
pub const THAW_AFTER: Duration = Duration::from_secs(1);
/// Most simulated time to wait for the servo to probe (mid-probe and mid-request kinds).
const PROBE_WAIT_S: f64 = 15.0;
/// Most wall time to wait for a frozen estimator to receive the request.
const REQUEST_WAIT: Duration = Duration::from_secs(15);
/// Time from seeing the servo await the estimate to the kill: the request is copied and sent
/// within a few ticks (ms).
#[doc(hidden)]
pub const REQUEST_KILL_DELAY: Duration = Duration::from_millis(50);
/// Most wall time to wait for a faulted board to be back.
pub const RECOVERY_WAIT: Duration = Duration::from_secs(20);
/// How often a due probe is asked for again while the servo tracks without starting it (a
/// restarted servo has forgotten the request; the request lapses by itself once a probe
/// starts).
const ASK_AGAIN: Duration = Duration::from_millis(200);

enum Phase {
    Idle,
    /// Waiting for the servo to probe (since this simulated time), having asked for a probe
    /// at `asked` (None: not yet).
    WaitProbe {
        since_s: f64,
        asked: Option<Instant>,
    },
    /// Estimator frozen at the probe's start; waiting for the request.
    FrozenForRequest {
        since: Instant,
    },
    /// The request is out; kill at this instant.
    KillAt {
        at: Instant,
    },
    /// Frozen; waiting for the stall policy.
    Frozen {
        board: Board,
        since: Instant,
        pid: i32,
    },
    /// Waiting for the board to be back.
    Recovering {
        board: Board,
        since: Instant,
        pid: i32,
    },
    /// The link board killed; waiting for its restart.
    LinkRecovering {
        since: Instant,
        pid: i32,
    },
    /// The link cut; restored at this instant.
    Cut {
        until: Instant,
    },
}

/// Injects the planned faults.
pub struct Injector {
    plan: Vec<PlannedFault>,
    next: usize,
    phase: Phase,
    t0: Instant,
    records: Vec<FaultRecord>,
    bad: BadSampleSender,
    /// Probes the servo cut short while the pending fault waited for one; noted in its record.
    probes_cut_short: u32,
    /// Probes asked for the pending fault.
    probes_asked: u32,
    /// How long a cut lasts.
    cut_for: Duration,
}

impl Injector {
    /// An injector for `plan` starting at `t0`, sending bad samples with `bad`.
    pub fn new(plan: Vec<PlannedFault>, bad: BadSampleSender, t0: Instant) -> Self {
        Self {
            plan,
            next: 0,
            phase: Phase::Idle,
            t0,
            records: Vec::new(),
            bad,
            probes_cut_short: 0,
            probes_asked: 0,
            cut_for: Duration::from_secs(5),
        }
    }

    /// Cuts of the link last `cut_for`.
    pub fn with_cut(self, cut_for: Duration) -> Self {
        Self { cut_for, ..self }
    }

    /// The link is cut now: the supervisor restores it if the run ends first.
    pub fn cutting(&self) -> bool {
        matches!(self.phase, Phase::Cut { .. })
    }

    /// Notes `what` on the newest fault's record (a command that failed, say).
    pub fn note(&mut self, what: &str) {
        if let Some(r) = self.records.last_mut() {
            if !r.note.is_empty() {
                r.note.push_str("; ");
            }
            r.note.push_str(what);
        }
    }

    /// No fault in progress.
    pub fn idle(&self) -> bool {
        matches!(self.phase, Phase::Idle)
    }

    /// A faulted board is on its way back: frozen until its stall policy kills it, or killed
    /// and not yet serving again. The supervisor lets it come back before it ends a run whose
    /// scenario is over ([`RECOVERY_WAIT`] at most).
    pub fn bringing_back(&self) -> bool {
        matches!(
            self.phase,
            Phase::Frozen { .. } | Phase::Recovering { .. } | Phase::LinkRecovering { .. }
        )
    }

    /// Every planned fault injected and over.
    pub fn done(&self) -> bool {
        self.idle() && self.next >= self.plan.len()
    }

    /// The plan.
    pub fn plan(&self) -> &[PlannedFault] {
        &self.plan
    }

    /// The faults injected so far.
    pub fn records(&self) -> &[FaultRecord] {
        &self.records
    }

    /// The bad samples sent.
    pub fn bad_samples(&self) -> &BadSampleSender {
        &self.bad
    }

    /// Planned faults on `board` (the restarts they cost are not held against its budget).
    pub fn planned_for(&self, board: Board) -> u32 {
        self.plan
            .iter()
            .filter(|f| f.kind.target() == Some(board))
            .count() as u32
    }

    /// Planned kills of the link board (the restarts they cost are not held against its
    /// budget).
    pub fn planned_link_kills(&self) -> u32 {
        self.plan
            .iter()
            .filter(|f| f.kind == FaultKind::KillLink)
            .count() as u32
    }

    /// One supervisor iteration at `now`, as `at` sees the stack: simulated time, the servo's
    /// controller, the boards, the link board, the newest genuine force sample. Returns what
    /// to do.
    pub fn step(&mut self, now: Instant, at: &Moment<'_>) -> Vec<Action> {
        self.bad.update_connections();
        let mut out = Vec::new();
        let phase = std::mem::replace(&mut self.phase, Phase::Idle);
        self.phase = match phase {
            Phase::Idle => self.start_next(now, at, &mut out),
            Phase::Cut { until } if now >= until => {
                out.push(Action::CutLink(false));
                self.note(&format!(
                    "restored after {:.1} s",
                    self.cut_for.as_secs_f64()
                ));
                self.next += 1;
                Phase::Idle
            }
            p @ Phase::Cut { .. } => p,
            Phase::LinkRecovering { since, pid } => self.link_recovering(now, at, since, pid),
            Phase::WaitProbe { since_s, asked } => {
                self.wait_probe(now, at, since_s, asked, &mut out)
            }
            Phase::FrozenForRequest { since } => self.frozen_for_request(now, at, since, &mut out),
            // Still held when killed: the supervisor lifts the hold when it reaps the process,
            // so its stall policy does not count this kill as a stall of its own.
            Phase::KillAt { at: kill_at } if now >= kill_at => {
                self.kill(Board::Estimator, now, at, &mut out, "")
            }
            p @ Phase::KillAt { .. } => p,
            Phase::Frozen { board, since, pid } => {
                self.frozen(now, at, board, since, pid, &mut out)
            }
            Phase::Recovering { board, since, pid } => self.recovering(now, at, board, since, pid),
        };
        out
    }

    /// The next fault, if it is due and its board ready.
    fn start_next(&mut self, now: Instant, at: &Moment<'_>, out: &mut Vec<Action>) -> Phase {
        let Some(f) = self.plan.get(self.next).copied() else {
            return Phase::Idle;
        };
        // Bad samples go to a servo whose data flows (their count comes back in its
        // statistics).
        let target = match f.kind {
            FaultKind::BadSamples => Some(Board::Servo),
            k => k.target(),
        };
        if at.sim_s < f.at_s
            || target.is_some_and(|b| !at.ready(b, now))
            || (f.kind.needs_link() && !up(at.link, now))
        {
            return Phase::Idle;
        }
        match f.kind {
            FaultKind::Kill(b) => self.kill(b, now, at, out, ""),
            FaultKind::Freeze(b) => {
                let v = at.board(b);
                self.record(now, at, v.pid, "");
                out.push(Action::Signal(b, libc::SIGSTOP));
                Phase::Frozen {
                    board: b,
                    since: now,
                    pid: v.pid,
                }
            }
            FaultKind::KillMidProbe(_) | FaultKind::KillEstimatorMidRequest => Phase::WaitProbe {
                since_s: at.sim_s,
                asked: None,
            },
            FaultKind::BadSamples => {
                if let Some(g) = at.genuine {
                    self.record(now, at, 0, "");
                    self.bad.burst(g, at.board(Board::Servo).pid);
                    self.next += 1;
                }
                Phase::Idle
            }
            FaultKind::KillLink => {
                self.record(now, at, at.link.pid, "");
                out.push(Action::SignalLink(libc::SIGKILL));
                Phase::LinkRecovering {
                    since: now,
                    pid: at.link.pid,
                }
            }
            FaultKind::CutLink => {
                self.record(now, at, 0, "");
                out.push(Action::CutLink(true));
                Phase::Cut {
                    until: now + self.cut_for,
                }
            }
        }
    }

    /// A killed link board: over when another one runs.
    fn link_recovering(
        &mut self,
        now: Instant,
        at: &Moment<'_>,
        since: Instant,
        pid: i32,
    ) -> Phase {
        let link = at.link;
        if link.pid != 0 && link.pid != pid {
            if let Some(r) = self.records.last_mut() {
                r.back_ms = link
                    .data_since
                    .map(|t| t.saturating_duration_since(since).as_secs_f64() * 1e3);
            }
            self.next += 1;
            Phase::Idle
        } else if now.duration_since(since) > RECOVERY_WAIT {
            self.note(&format!(
                "the link board not back within {} s",
                RECOVERY_WAIT.as_secs()
            ));
            self.next += 1;
            Phase::Idle
        } else {
            Phase::LinkRecovering { since, pid }
        }
    }

    /// A fault that strikes while the servo probes: ask for a probe, then strike.
    fn wait_probe(
        &mut self,
        now: Instant,
        at: &Moment<'_>,
        since_s: f64,
        asked: Option<Instant>,
        out: &mut Vec<Action>,
    ) -> Phase {
        let f = self.plan[self.next];
        let mode = at.servo.mode;
        let probing = mode == Some(ServoMode::Probing);
        let late = at.sim_s - since_s > PROBE_WAIT_S;
        let note = if probing {
            ""
        } else {
            "the servo did not probe in time; injected anyway"
        };
        match f.kind {
            FaultKind::KillMidProbe(b) if (probing || late) && at.board(b).pid != 0 => {
                self.kill(b, now, at, out, note)
            }
            FaultKind::KillEstimatorMidRequest if probing => {
                out.push(Action::Hold(Board::Estimator, true));
                out.push(Action::Signal(Board::Estimator, libc::SIGSTOP));
                Phase::FrozenForRequest { since: now }
            }
            FaultKind::KillEstimatorMidRequest if late => {
                self.kill(Board::Estimator, now, at, out, note)
            }
            // Tracking: ask for a probe (again, if a restarted servo forgot it).
            _ if mode == Some(ServoMode::Track)
                && at.board(Board::Servo).pid != 0
                && asked.is_none_or(|t| now.duration_since(t) >= ASK_AGAIN) =>
            {
                out.push(Action::AskProbe {
                    started_before: at.servo.started,
                });
                self.probes_asked += 1;
                Phase::WaitProbe {
                    since_s,
                    asked: Some(now),
                }
            }
            // Stopping, settling, resuming or restarting: the probe comes.
            _ => Phase::WaitProbe { since_s, asked },
        }
    }

    /// The estimator frozen at the probe's start: kill it once the request is out.
    fn frozen_for_request(
        &mut self,
        now: Instant,
        at: &Moment<'_>,
        since: Instant,
        out: &mut Vec<Action>,
    ) -> Phase {
        let mode = at.servo.mode;
        if mode == Some(ServoMode::AwaitingEstimate) {
            Phase::KillAt {
                at: now + REQUEST_KILL_DELAY,
            }
        } else if mode != Some(ServoMode::Probing) {
            // The servo cut the probe short (its safe state: a late force sample) and will
            // send no request for it: let the estimator go and ask for another.
            out.push(Action::Signal(Board::Estimator, libc::SIGCONT));
            out.push(Action::Hold(Board::Estimator, false));
            self.probes_cut_short += 1;
            Phase::WaitProbe {
                since_s: at.sim_s,
                asked: None,
            }
        } else if now.duration_since(since) > REQUEST_WAIT {
            out.push(Action::Signal(Board::Estimator, libc::SIGCONT));
            out.push(Action::Hold(Board::Estimator, false));
            self.record(
                now,
                at,
                at.board(Board::Estimator).pid,
                "no request came while the estimator was frozen; thawed",
            );
            if let Some(r) = self.records.last_mut() {
                r.thawed = true;
            }
            self.next += 1;
            Phase::Idle
        } else {
            Phase::FrozenForRequest { since }
        }
    }

    /// A frozen board: the stall policy kills it, or (none) it is thawed.
    fn frozen(
        &mut self,
        now: Instant,
        at: &Moment<'_>,
        board: Board,
        since: Instant,
        pid: i32,
        out: &mut Vec<Action>,
    ) -> Phase {
        let v = at.board(board);
        if v.pid != pid {
            // The stall policy killed it.
            if let Some(r) = self.records.last_mut() {
                r.detected_ms = Some(now.duration_since(since).as_secs_f64() * 1e3);
            }
            Phase::Recovering { board, since, pid }
        } else if !v.stall_policy && now.duration_since(since) > THAW_AFTER {
            out.push(Action::Signal(board, libc::SIGCONT));
            if let Some(r) = self.records.last_mut() {
                r.note = "no stall policy: thawed with SIGCONT".into();
                r.thawed = true;
            }
            self.next += 1;
            Phase::Idle
        } else {
            Phase::Frozen { board, since, pid }
        }
    }

    /// A killed board: back when another process's data flows.
    fn recovering(
        &mut self,
        now: Instant,
        at: &Moment<'_>,
        board: Board,
        since: Instant,
        pid: i32,
    ) -> Phase {
        let v = at.board(board);
        let back = v.pid != 0 && v.pid != pid;
        match v.data_since {
            Some(t) if back && t >= since => {
                if let Some(r) = self.records.last_mut() {
                    r.back_ms = Some(t.duration_since(since).as_secs_f64() * 1e3);
                }
                self.next += 1;
                Phase::Idle
            }
            _ if now.duration_since(since) > RECOVERY_WAIT => {
                if let Some(r) = self.records.last_mut() {
                    r.note = format!(
                        "{} not back within {} s",
                        board.name(),
                        RECOVERY_WAIT.as_secs()
                    );
                }
                self.next += 1;
                Phase::Idle
            }
            _ => Phase::Recovering { board, since, pid },
        }
    }

    fn record(&mut self, now: Instant, at: &Moment<'_>, pid: i32, note: &str) {
        let f = self.plan[self.next];
        let note = match std::mem::take(&mut self.probes_cut_short) {
            0 => note.to_string(),
            n => {
                let first = format!("the servo cut {n} probe(s) short first; waited for the next");
                if note.is_empty() {
                    first
                } else {
                    format!("{first}; {note}")
                }
            }
        };
        self.records.push(FaultRecord {
            kind: f.kind.name().into(),
            due_s: f.at_s,
            injected_at_s: at.sim_s,
            wall_s: now.saturating_duration_since(self.t0).as_secs_f64(),
            pid,
            servo_mode: at.servo.mode,
            probes_asked: std::mem::take(&mut self.probes_asked),
            detected_ms: None,
            back_ms: None,
            thawed: false,
            note,
            restart: None,
        });
    }

    fn kill(
        &mut self,
        b: Board,
        now: Instant,
        at: &Moment<'_>,
        out: &mut Vec<Action>,
        note: &str,
    ) -> Phase {
        let pid = at.board(b).pid;
        self.record(now, at, pid, note);
        out.push(Action::Signal(b, libc::SIGKILL));
        Phase::Recovering {
            board: b,
            since: now,
            pid,
        }
    }
}

/// What the injector sees of the stack at one supervisor iteration.
#[derive(Debug, Clone, Copy)]
pub struct Moment<'a> {
    /// Simulated time (s).
    pub sim_s: f64,
    /// The servo's controller.
    pub servo: ServoView,
    /// The boards, servo, sensor and estimator.
    pub boards: &'a [BoardView; 3],
    /// The link board (pid 0 when none; its data counts as flowing from its start).
    pub link: BoardView,
    /// The newest genuine force sample.
    pub genuine: Option<&'a WrenchSample>,
}

impl Moment<'_> {
    fn board(&self, b: Board) -> BoardView {
        self.boards[b as usize]
    }

    /// The board runs and its data has flowed for [`MIN_UPTIME`].
    fn ready(&self, b: Board, now: Instant) -> bool {
        up(self.board(b), now)
    }
}

/// Running, and its data flowing for [`MIN_UPTIME`].
fn up(v: BoardView, now: Instant) -> bool {
    v.pid != 0
        && v.data_since
            .is_some_and(|t| now.saturating_duration_since(t) >= MIN_UPTIME)
}
