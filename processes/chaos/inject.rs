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

use crate::ipc::Svc;
use crate::rt;
use crate::supervisor::Timeline;
use afs_shared::faults::{BadCounts, BadSample, Board, FaultKind, PlannedFault};
use afs_shared::msg::WrenchSample;
use afs_shared::servo::ServoMode;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::update_connections::UpdateConnections;
use serde::Deserialize;
use serde::Serialize;
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
const REQUEST_KILL_DELAY: Duration = Duration::from_millis(50);
/// Most wall time to wait for a faulted board to be back.
const RECOVERY_WAIT: Duration = Duration::from_secs(20);
/// How often a due probe is asked for again while the servo tracks without starting it (a
/// restarted servo has forgotten the request; the request lapses by itself once a probe
/// starts).
const ASK_AGAIN: Duration = Duration::from_millis(200);

/// What the supervisor knows of the servo's controller, from its newest sample.
#[derive(Debug, Clone, Copy, Default)]
pub struct ServoView {
    /// Its mode (None before the first sample, or an unknown code).
    pub mode: Option<ServoMode>,
    /// Estimations it has started.
    pub started: u32,
}

/// What the supervisor knows of a board.
#[derive(Debug, Clone, Copy, Default)]
pub struct BoardView {
    /// Its pid (0: none running).
    pub pid: i32,
    /// When the current process's data started to flow (sensor: its first wrench sample;
    /// servo: its first world tick, a restarted one's first new tick; estimator: its ports
    /// open, from its start-up report).
    pub data_since: Option<Instant>,
    /// The supervisor kills it when silent (`stall_ms` > 0).
    pub stall_policy: bool,
}

/// What the supervisor is asked to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Send a signal to the board's process.
    Signal(Board, i32),
    /// Exempt the board from the stall policy (the injector holds it frozen on purpose) or not;
    /// the supervisor lifts the hold when the process ends.
    Hold(Board, bool),
    /// Ask the servo to estimate the tangent (stop, probe), unless more than `started_before`
    /// estimations have started by the time it can.
    AskProbe {
        /// The servo's estimations started, as last seen.
        started_before: u32,
    },
    /// Send a signal to the link board.
    SignalLink(i32),
    /// Cut the link (true) or restore it (false) with the stack file's commands.
    CutLink(bool),
}

/// One fault as it went.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FaultRecord {
    /// The kind's name.
    pub kind: String,
    /// Planned simulated time (s).
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub due_s: f64,
    /// Simulated time of the injection (s).
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub injected_at_s: f64,
    /// Wall time of the injection since the stack started (s).
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub wall_s: f64,
    /// The process signalled.
    pub pid: i32,
    /// The servo's mode at the injection.
    pub servo_mode: Option<ServoMode>,
    /// Probes the injector asked the servo for, for this fault.
    pub probes_asked: u32,
    /// A frozen board: time until the supervisor's stall policy killed it (ms).
    pub detected_ms: Option<f64>,
    /// Time from the fault to the board's data flowing again (ms).
    pub back_ms: Option<f64>,
    /// Frozen and let go again (SIGCONT), not killed: nothing to come back.
    pub thawed: bool,
    /// Anything unusual.
    pub note: String,
    /// Where the faulted board's restart spent its time (from the supervisor's exit record of
    /// `pid`).
    pub restart: Option<Timeline>,
}

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
    publisher: Publisher<Svc, WrenchSample, ()>,
    records: Vec<FaultRecord>,
    bad: BadCounts,
    /// Probes the servo cut short while the pending fault waited for one; noted in its record.
    probes_cut_short: u32,
    /// Probes asked for the pending fault.
    probes_asked: u32,
    /// How long a cut lasts.
    cut_for: Duration,
}

impl Injector {
    /// An injector for `plan`, publishing bad samples with `publisher`.
    pub fn new(plan: Vec<PlannedFault>, publisher: Publisher<Svc, WrenchSample, ()>) -> Self {
        Self {
            plan,
            next: 0,
            phase: Phase::Idle,
            t0: Instant::now(),
            publisher,
            records: Vec::new(),
            bad: BadCounts::default(),
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

    /// Bad samples sent.
    pub fn bad_samples(&self) -> BadCounts {
        self.bad
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

    /// One supervisor iteration: simulated time, the servo's controller, the boards (servo,
    /// sensor, estimator), the link board (pid 0 when none; its data counts as flowing from
    /// its start), the newest genuine force sample. Returns what to do.
    pub fn step(
        &mut self,
        sim_s: f64,
        servo: ServoView,
        boards: &[BoardView; 3],
        link: BoardView,
        genuine: Option<&WrenchSample>,
    ) -> Vec<Action> {
        let now = Instant::now();
        // The burst publisher sends rarely: drop its connections to dead subscribers (a killed
        // servo's) as soon as iceoryx2 has cleaned them, not at the next burst.
        let _ = self.publisher.update_connections();
        let view = |b: Board| boards[b as usize];
        // Running, and its data flowing for MIN_UPTIME.
        let up = |v: BoardView| {
            v.pid != 0
                && v.data_since
                    .is_some_and(|t| now.duration_since(t) >= MIN_UPTIME)
        };
        let ready = |b: Board| up(view(b));
        let mode = servo.mode;
        let mut out = Vec::new();
        let phase = std::mem::replace(&mut self.phase, Phase::Idle);
        self.phase = match phase {
            Phase::Idle => {
                let Some(f) = self.plan.get(self.next).copied() else {
                    return out;
                };
                if sim_s < f.at_s
                    || f.kind.target().is_some_and(|b| !ready(b))
                    || (f.kind.needs_link() && !up(link))
                {
                    return out;
                }
                match f.kind {
                    FaultKind::Kill(b) => self.kill(b, sim_s, mode, boards, &mut out, ""),
                    FaultKind::Freeze(b) => {
                        let v = view(b);
                        self.record(sim_s, mode, v.pid, "");
                        out.push(Action::Signal(b, libc::SIGSTOP));
                        Phase::Frozen {
                            board: b,
                            since: now,
                            pid: v.pid,
                        }
                    }
                    FaultKind::KillMidProbe(_) | FaultKind::KillEstimatorMidRequest => {
                        Phase::WaitProbe {
                            since_s: sim_s,
                            asked: None,
                        }
                    }
                    FaultKind::BadSamples => match genuine {
                        Some(g) => {
                            self.record(sim_s, mode, 0, "");
                            self.burst(g);
                            self.next += 1;
                            Phase::Idle
                        }
                        None => Phase::Idle,
                    },
                    FaultKind::KillLink => {
                        self.record(sim_s, mode, link.pid, "");
                        out.push(Action::SignalLink(libc::SIGKILL));
                        Phase::LinkRecovering {
                            since: now,
                            pid: link.pid,
                        }
                    }
                    FaultKind::CutLink => {
                        self.record(sim_s, mode, 0, "");
                        out.push(Action::CutLink(true));
                        Phase::Cut {
                            until: now + self.cut_for,
                        }
                    }
                }
            }
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
            Phase::LinkRecovering { since, pid } => {
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
            Phase::WaitProbe { since_s, asked } => {
                let f = self.plan[self.next];
                let probing = mode == Some(ServoMode::Probing);
                let late = sim_s - since_s > PROBE_WAIT_S;
                let note = if probing {
                    ""
                } else {
                    "the servo did not probe in time; injected anyway"
                };
                match f.kind {
                    FaultKind::KillMidProbe(b) if (probing || late) && view(b).pid != 0 => {
                        self.kill(b, sim_s, mode, boards, &mut out, note)
                    }
                    FaultKind::KillEstimatorMidRequest if probing => {
                        out.push(Action::Hold(Board::Estimator, true));
                        out.push(Action::Signal(Board::Estimator, libc::SIGSTOP));
                        Phase::FrozenForRequest { since: now }
                    }
                    FaultKind::KillEstimatorMidRequest if late => {
                        self.kill(Board::Estimator, sim_s, mode, boards, &mut out, note)
                    }
                    // Tracking: ask for a probe (again, if a restarted servo forgot it).
                    _ if mode == Some(ServoMode::Track)
                        && view(Board::Servo).pid != 0
                        && asked.is_none_or(|t| now.duration_since(t) >= ASK_AGAIN) =>
                    {
                        out.push(Action::AskProbe {
                            started_before: servo.started,
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
            Phase::FrozenForRequest { since } => {
                if mode == Some(ServoMode::AwaitingEstimate) {
                    Phase::KillAt {
                        at: now + REQUEST_KILL_DELAY,
                    }
                } else if mode != Some(ServoMode::Probing) {
                    // The servo cut the probe short (its safe state: a late force sample) and
                    // will send no request for it: let the estimator go and ask for another.
                    out.push(Action::Signal(Board::Estimator, libc::SIGCONT));
                    out.push(Action::Hold(Board::Estimator, false));
                    self.probes_cut_short += 1;
                    Phase::WaitProbe {
                        since_s: sim_s,
                        asked: None,
                    }
                } else if now.duration_since(since) > REQUEST_WAIT {
                    out.push(Action::Signal(Board::Estimator, libc::SIGCONT));
                    out.push(Action::Hold(Board::Estimator, false));
                    self.record(
                        sim_s,
                        mode,
                        view(Board::Estimator).pid,
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
            // Still held when killed: the supervisor lifts the hold when it reaps the process,
            // so its stall policy does not count this kill as a stall of its own.
            Phase::KillAt { at } if now >= at => {
                self.kill(Board::Estimator, sim_s, mode, boards, &mut out, "")
            }
            p @ Phase::KillAt { .. } => p,
            Phase::Frozen {
                board: b,
                since,
                pid,
            } => {
                let v = view(b);
                if v.pid != pid {
                    // The stall policy killed it.
                    if let Some(r) = self.records.last_mut() {
                        r.detected_ms = Some(now.duration_since(since).as_secs_f64() * 1e3);
                    }
                    Phase::Recovering {
                        board: b,
                        since,
                        pid,
                    }
                } else if !v.stall_policy && now.duration_since(since) > THAW_AFTER {
                    out.push(Action::Signal(b, libc::SIGCONT));
                    if let Some(r) = self.records.last_mut() {
                        r.note = "no stall policy: thawed with SIGCONT".into();
                        r.thawed = true;
                    }
                    self.next += 1;
                    Phase::Idle
                } else {
                    Phase::Frozen {
                        board: b,
                        since,
                        pid,
                    }
                }
            }
            Phase::Recovering { board, since, pid } => {
                let v = view(board);
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
        };
        out
    }

    fn record(&mut self, sim_s: f64, servo_mode: Option<ServoMode>, pid: i32, note: &str) {
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
            injected_at_s: sim_s,
            wall_s: self.t0.elapsed().as_secs_f64(),
            pid,
            servo_mode,
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
        sim_s: f64,
        servo_mode: Option<ServoMode>,
        boards: &[BoardView; 3],
        out: &mut Vec<Action>,
        note: &str,
    ) -> Phase {
        let pid = boards[b as usize].pid;
        self.record(sim_s, servo_mode, pid, note);
        out.push(Action::Signal(b, libc::SIGKILL));
        Phase::Recovering {
            board: b,
            since: Instant::now(),
            pid,
        }
    }

    /// One of each bad sample, built from the newest genuine one.
    fn burst(&mut self, g: &WrenchSample) {
        for kind in BadSample::ALL {
            if self
                .publisher
                .send_copy(kind.sample(g, rt::monotonic_ns()))
                .is_ok()
            {
                self.bad.count(kind);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ipc;

    fn signals(actions: &[Action]) -> Vec<i32> {
        actions
            .iter()
            .filter_map(|a| match a {
                Action::Signal(Board::Estimator, s) => Some(*s),
                _ => None,
            })
            .collect()
    }

    fn asked(actions: &[Action]) -> Vec<u32> {
        actions
            .iter()
            .filter_map(|a| match a {
                Action::AskProbe { started_before } => Some(*started_before),
                _ => None,
            })
            .collect()
    }

    /// A due mid-request fault asks the tracking servo for a probe (once, not again while it
    /// stops), freezes the estimator when the strokes start; a probe cut short lets the
    /// estimator go and asks for another, whose request is then killed in flight.
    #[test]
    fn a_due_probe_fault_asks_for_a_probe_and_rearms_when_it_is_cut_short() {
        let prefix = format!("ut_chaos_{}", std::process::id());
        let node = ipc::node(&prefix, "injector_test").unwrap();
        let service = ipc::wrench(&node).unwrap();
        let publisher = service.publisher_builder().create().unwrap();
        let plan = vec![PlannedFault {
            at_s: 1.0,
            kind: FaultKind::KillEstimatorMidRequest,
        }];
        let mut inj = Injector::new(plan, publisher);
        let up = BoardView {
            pid: 42,
            data_since: Instant::now().checked_sub(Duration::from_secs(5)),
            stall_policy: true,
        };
        let boards = [up; 3];
        let link = BoardView::default();
        let servo = |mode, started| ServoView {
            mode: Some(mode),
            started,
        };
        use ServoMode::*;
        assert!(
            inj.step(0.5, servo(Track, 0), &boards, link, None)
                .is_empty()
        );
        assert!(
            inj.step(1.0, servo(Track, 0), &boards, link, None)
                .is_empty()
        );
        assert_eq!(
            asked(&inj.step(1.01, servo(Track, 0), &boards, link, None)),
            [0]
        );
        // Not again at once, nor while the servo stops.
        assert!(
            inj.step(1.02, servo(Track, 0), &boards, link, None)
                .is_empty()
        );
        assert!(
            inj.step(1.1, servo(Stopping, 1), &boards, link, None)
                .is_empty()
        );
        assert_eq!(
            signals(&inj.step(1.5, servo(Probing, 1), &boards, link, None)),
            [libc::SIGSTOP]
        );
        assert!(
            inj.step(1.6, servo(Probing, 1), &boards, link, None)
                .is_empty()
        );
        // The servo's safe state aborts the probe: no request will come.
        let thaw = inj.step(1.7, servo(Resuming, 1), &boards, link, None);
        assert_eq!(signals(&thaw), [libc::SIGCONT]);
        assert!(thaw.contains(&Action::Hold(Board::Estimator, false)));
        assert!(inj.records().is_empty());
        assert_eq!(
            asked(&inj.step(2.0, servo(Track, 1), &boards, link, None)),
            [1]
        );
        assert_eq!(
            signals(&inj.step(3.0, servo(Probing, 2), &boards, link, None)),
            [libc::SIGSTOP]
        );
        assert!(
            inj.step(4.0, servo(AwaitingEstimate, 2), &boards, link, None)
                .is_empty()
        );
        std::thread::sleep(REQUEST_KILL_DELAY);
        assert_eq!(
            signals(&inj.step(4.1, servo(AwaitingEstimate, 2), &boards, link, None)),
            [libc::SIGKILL]
        );
        let r = &inj.records()[0];
        assert_eq!(r.servo_mode, Some(AwaitingEstimate));
        assert_eq!(r.probes_asked, 2);
        assert!(!r.thawed);
        assert!(r.note.contains("cut 1 probe(s) short"), "{}", r.note);
        drop((inj, service, node));
        // Everything went with the node but the domain's node counter, which the release
        // removes.
        assert!(
            ipc::leftovers(&prefix)
                .iter()
                .all(|f| ipc::is_node_counter(f))
        );
        let left = ipc::release_prefix(&prefix).unwrap();
        assert!(left.is_empty(), "{left:?}");
    }

    /// The link's faults wait for a link board that has been up a while; a kill signals it and
    /// is over when another one runs, and a cut asks for the cut, then for the restore once
    /// its time is up.
    #[test]
    fn the_link_is_killed_and_cut_then_restored() {
        let prefix = format!("ut_chaos_link_{}", std::process::id());
        let node = ipc::node(&prefix, "injector_test").unwrap();
        let service = ipc::wrench(&node).unwrap();
        let publisher = service.publisher_builder().create().unwrap();
        let plan = vec![
            PlannedFault {
                at_s: 1.0,
                kind: FaultKind::KillLink,
            },
            PlannedFault {
                at_s: 2.0,
                kind: FaultKind::CutLink,
            },
        ];
        let cut_for = Duration::from_millis(30);
        let mut inj = Injector::new(plan, publisher).with_cut(cut_for);
        let long_ago = Instant::now().checked_sub(Duration::from_secs(5));
        let up = |pid| BoardView {
            pid,
            data_since: long_ago,
            stall_policy: false,
        };
        let boards = [up(42); 3];
        let servo = ServoView::default();
        let just_started = BoardView {
            data_since: Some(Instant::now()),
            ..up(7)
        };
        // No link board, or one just started: the fault waits.
        assert!(
            inj.step(1.5, servo, &boards, BoardView::default(), None)
                .is_empty()
        );
        assert!(inj.step(1.5, servo, &boards, just_started, None).is_empty());
        assert_eq!(
            inj.step(1.5, servo, &boards, up(7), None),
            [Action::SignalLink(libc::SIGKILL)]
        );
        assert!(!inj.idle());
        // Not back while the killed one's pid is shown, or none runs.
        assert!(inj.step(1.6, servo, &boards, up(7), None).is_empty());
        assert!(
            inj.step(1.6, servo, &boards, BoardView::default(), None)
                .is_empty()
        );
        let back = BoardView {
            data_since: Some(Instant::now()),
            ..up(8)
        };
        assert!(inj.step(1.7, servo, &boards, back, None).is_empty());
        assert!(inj.idle());
        assert_eq!(inj.records()[0].kind, "kill-link");
        assert_eq!(inj.records()[0].pid, 7);
        assert!(inj.records()[0].back_ms.is_some());
        // The cut, once the new link board has been up for a while.
        let old = up(8);
        assert!(inj.step(1.9, servo, &boards, old, None).is_empty());
        assert_eq!(
            inj.step(2.0, servo, &boards, old, None),
            [Action::CutLink(true)]
        );
        assert!(inj.cutting());
        assert!(inj.step(2.01, servo, &boards, old, None).is_empty());
        std::thread::sleep(cut_for);
        assert_eq!(
            inj.step(2.1, servo, &boards, old, None),
            [Action::CutLink(false)]
        );
        assert!(inj.done() && !inj.cutting());
        let r = &inj.records()[1];
        assert_eq!((r.kind.as_str(), r.pid), ("cut-link", 0));
        assert!(r.note.contains("restored after"), "{}", r.note);
        drop((inj, service, node));
        let _ = ipc::release_prefix(&prefix);
    }
}
