//! The supervisor's side of `afs chaos`: what the injector sees of the stack, and its actions
//! carried out (signals, holds, the link's cut, probes asked of the servo).

use super::super::child::Proc;
use super::super::footprint;
use super::Supervisor;
use crate::chaos::{Action, BoardView, Moment};
use crate::rt;
use crate::stack::LINK_PROCESS;
use afs_shared::msg::{self, Board, ServoCommand};
use std::time::{Duration, Instant};

impl Supervisor {
    /// One step of the fault injector (`afs chaos`): what it sees of the stack in, its
    /// actions carried out; the stack's footprint taken while steady before the first fault
    /// and after the last.
    pub(super) fn inject(&mut self) {
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
                self.steady[slot] = Some(footprint::now(&self.launch.prefix, &self.procs, self.t0));
            }
        }
        if let Some(c) = self.link_cut.as_mut() {
            for e in c.poll() {
                eprintln!("afs: warning: {e}");
                inj.note(&e);
            }
        }
        let moment = Moment {
            sim_s: self.last_time_s,
            servo: self.servo_view,
            boards: &views,
            link,
            genuine: self.genuine.as_ref(),
        };
        let actions = inj.step(Instant::now(), &moment);
        for a in actions {
            match a {
                Action::Signal(b, sig) => {
                    if let Some(p) = self.proc_mut(b) {
                        p.signal(sig);
                    }
                }
                Action::Hold(b, h) => {
                    if let Some(p) = self.proc_mut(b) {
                        p.hold(h, Instant::now());
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
                        version: ServoCommand::VERSION,
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
}
