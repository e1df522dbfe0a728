//! The servo board in the `insertion` scenario: the tick runs the insertion's rig
//! ([`InsertionRig`]: the peg's world, built-in or MuJoCo's, the insertion controller, the
//! contact-state estimator)
//! in place of the arm's servo and world, on the same force input, gate, statistics and
//! snapshot. The arm's servo and world stay built and idle (their snapshot parts are kept as
//! they are), so nothing else of the board changes.

use super::{ServoBoard, Tick};
use crate::rt;
use afs_shared::insertion::rig::{InsertionRig, RigState};
use afs_shared::msg::{PegSample, PlantSample, ServoSample, WorldSnapshot, WrenchSample};
use afs_shared::scenario::Scenario;
use afs_shared::sensor::Wrench;
use anyhow::Result;

/// The rig of `scenario` (None unless it is an insertion), where `snapshot` left it.
pub(super) fn rig(
    scenario: &Scenario,
    snapshot: Option<&WorldSnapshot>,
) -> Result<Option<InsertionRig>> {
    let Some(o) = scenario.insertion else {
        return Ok(None);
    };
    let cfg = &scenario.cfg;
    let mut rig = InsertionRig::on_world(&o, cfg.seed, &cfg.world, cfg.servo.dt())
        .map_err(anyhow::Error::msg)?;
    if let Some(s) = snapshot.filter(|s| s.insertion.active == 1) {
        rig.restore(&RigState::from(&s.insertion))
            .map_err(anyhow::Error::msg)?;
    }
    Ok(Some(rig))
}

/// The world's first sample of an insertion that starts afresh.
pub(super) fn first_sample(rig: &InsertionRig, seq: u64) -> PlantSample {
    let mut p = PlantSample::of_peg(rig, seq, rt::monotonic_ns());
    p.publish_ns = rt::monotonic_ns();
    p
}

impl ServoBoard {
    /// One tick of the insertion: the newest accepted force sample, tared, or none (the wrist
    /// holds its pose: the safe state), one rig step, the tick published. The scenario runs to
    /// its time limit (holding at depth once in: a chaos run's faults have the whole of it)
    /// unless a force above the limit ends it. Allocates nothing, takes no lock, logs nothing.
    pub(super) fn tick_peg(&mut self, now: u64, late: u64) -> Tick {
        self.take_force();
        let (_, used) = self.input(now, late);
        if self.seq > self.tick_limit || self.peg.as_ref().is_none_or(InsertionRig::failed) {
            return Tick::Done;
        }
        self.drain_commands();
        let reading = used.map(|(w, _)| w.wrench().tared(w.tare()));
        if let Some(rig) = &mut self.peg {
            rig.step(reading, self.dt);
        }
        if reading.is_none() {
            self.stats.safe_ticks += 1;
        }
        self.publish_peg(now, used, reading);
        self.account(now, late);
        self.seq += 1;
        Tick::Ran
    }

    /// Commands have no meaning during an insertion: each is counted as refused.
    fn drain_commands(&mut self) {
        while let Ok(Some(_)) = self.ports.command.receive() {
            self.stats.commands += 1;
            self.stats.bad_commands += 1;
        }
    }

    /// The snapshot first, then the world, controller and peg samples (as the arm's tick).
    fn publish_peg(
        &mut self,
        now: u64,
        used: Option<(WrenchSample, u64)>,
        reading: Option<Wrench>,
    ) {
        let Some(rig) = &self.peg else {
            return;
        };
        let p = PlantSample::of_peg(rig, self.seq, now);
        let s = ServoSample::of_peg(rig, self.seq, now, reading);
        let mut g = PegSample::of_rig(rig, self.seq, now, used.is_some());
        let state = (&rig.state()).into();
        self.send(p, s, used, state);
        if let Some(out) = &self.ports.peg {
            g.publish_ns = rt::monotonic_ns();
            if out.send_copy(g).is_err() {
                self.stats.publish_failures += 1;
            }
        }
    }
}
