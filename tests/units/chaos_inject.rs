//! The injector's state machine, stepped with a clock the tests hand it.

use afs::chaos::inject::*;
use afs::ipc;
use afs_shared::servo::ServoMode;

use afs::chaos::BadSampleSender;
use afs_shared::faults::{Board, FaultKind, PlannedFault};
use std::cell::Cell;
use std::time::{Duration, Instant};

/// The injector's clock in the tests: each step 1 ms after the last, moved on at will.
struct Clock {
    now: Cell<Instant>,
}

impl Clock {
    fn new() -> Self {
        Self {
            now: Cell::new(Instant::now()),
        }
    }

    fn tick(&self) -> Instant {
        self.now.set(self.now.get() + Duration::from_millis(1));
        self.now.get()
    }

    fn advance(&self, d: Duration) {
        self.now.set(self.now.get() + d);
    }
}

/// One step at `sim_s` with no genuine force sample.
fn step(
    inj: &mut Injector,
    clock: &Clock,
    sim_s: f64,
    servo: ServoView,
    boards: &[BoardView; 3],
    link: BoardView,
) -> Vec<Action> {
    let moment = Moment {
        sim_s,
        servo,
        boards,
        link,
        genuine: None,
    };
    inj.step(clock.tick(), &moment)
}

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
    let bad = BadSampleSender::new(ipc::wrench(&node).unwrap()).unwrap();
    let plan = vec![PlannedFault {
        at_s: 1.0,
        kind: FaultKind::KillEstimatorMidRequest,
    }];
    let clock = Clock::new();
    let mut inj = Injector::new(plan, bad, clock.tick());
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
    assert!(step(&mut inj, &clock, 0.5, servo(Track, 0), &boards, link).is_empty());
    assert!(step(&mut inj, &clock, 1.0, servo(Track, 0), &boards, link).is_empty());
    assert_eq!(
        asked(&step(
            &mut inj,
            &clock,
            1.01,
            servo(Track, 0),
            &boards,
            link
        )),
        [0]
    );
    // Not again at once, nor while the servo stops.
    assert!(step(&mut inj, &clock, 1.02, servo(Track, 0), &boards, link).is_empty());
    assert!(step(&mut inj, &clock, 1.1, servo(Stopping, 1), &boards, link).is_empty());
    assert_eq!(
        signals(&step(
            &mut inj,
            &clock,
            1.5,
            servo(Probing, 1),
            &boards,
            link
        )),
        [libc::SIGSTOP]
    );
    assert!(step(&mut inj, &clock, 1.6, servo(Probing, 1), &boards, link).is_empty());
    // The servo's safe state aborts the probe: no request will come.
    let thaw = step(&mut inj, &clock, 1.7, servo(Resuming, 1), &boards, link);
    assert_eq!(signals(&thaw), [libc::SIGCONT]);
    assert!(thaw.contains(&Action::Hold(Board::Estimator, false)));
    assert!(inj.records().is_empty());
    assert_eq!(
        asked(&step(&mut inj, &clock, 2.0, servo(Track, 1), &boards, link)),
        [1]
    );
    assert_eq!(
        signals(&step(
            &mut inj,
            &clock,
            3.0,
            servo(Probing, 2),
            &boards,
            link
        )),
        [libc::SIGSTOP]
    );
    assert!(
        step(
            &mut inj,
            &clock,
            4.0,
            servo(AwaitingEstimate, 2),
            &boards,
            link
        )
        .is_empty()
    );
    clock.advance(REQUEST_KILL_DELAY);
    assert_eq!(
        signals(&step(
            &mut inj,
            &clock,
            4.1,
            servo(AwaitingEstimate, 2),
            &boards,
            link
        )),
        [libc::SIGKILL]
    );
    let r = &inj.records()[0];
    assert_eq!(r.servo_mode, Some(AwaitingEstimate));
    assert_eq!(r.probes_asked, 2);
    assert!(!r.thawed);
    assert!(r.note.contains("cut 1 probe(s) short"), "{}", r.note);
    drop((inj, node));
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
    let bad = BadSampleSender::new(ipc::wrench(&node).unwrap()).unwrap();
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
    let clock = Clock::new();
    let mut inj = Injector::new(plan, bad, clock.tick()).with_cut(cut_for);
    let long_ago = Instant::now().checked_sub(Duration::from_secs(5));
    let up = |pid| BoardView {
        pid,
        data_since: long_ago,
        stall_policy: false,
    };
    let boards = [up(42); 3];
    let servo = ServoView::default();
    let just_started = BoardView {
        data_since: Some(clock.tick()),
        ..up(7)
    };
    // No link board, or one just started: the fault waits.
    assert!(step(&mut inj, &clock, 1.5, servo, &boards, BoardView::default()).is_empty());
    assert!(step(&mut inj, &clock, 1.5, servo, &boards, just_started).is_empty());
    assert_eq!(
        step(&mut inj, &clock, 1.5, servo, &boards, up(7)),
        [Action::SignalLink(libc::SIGKILL)]
    );
    assert!(!inj.idle());
    // Not back while the killed one's pid is shown, or none runs.
    assert!(step(&mut inj, &clock, 1.6, servo, &boards, up(7)).is_empty());
    assert!(step(&mut inj, &clock, 1.6, servo, &boards, BoardView::default()).is_empty());
    let back = BoardView {
        data_since: Some(clock.tick()),
        ..up(8)
    };
    assert!(step(&mut inj, &clock, 1.7, servo, &boards, back).is_empty());
    assert!(inj.idle());
    assert_eq!(inj.records()[0].kind, "kill-link");
    assert_eq!(inj.records()[0].pid, 7);
    assert!(inj.records()[0].back_ms.is_some());
    // The cut, once the new link board has been up for a while.
    let old = up(8);
    assert!(step(&mut inj, &clock, 1.9, servo, &boards, old).is_empty());
    assert_eq!(
        step(&mut inj, &clock, 2.0, servo, &boards, old),
        [Action::CutLink(true)]
    );
    assert!(inj.cutting());
    assert!(step(&mut inj, &clock, 2.01, servo, &boards, old).is_empty());
    clock.advance(cut_for);
    assert_eq!(
        step(&mut inj, &clock, 2.1, servo, &boards, old),
        [Action::CutLink(false)]
    );
    assert!(inj.done() && !inj.cutting());
    let r = &inj.records()[1];
    assert_eq!((r.kind.as_str(), r.pid), ("cut-link", 0));
    assert!(r.note.contains("restored after"), "{}", r.note);
    drop((inj, node));
    let _ = ipc::release_prefix(&prefix);
}
