//! Following a running stack from outside it, as any subscriber does: its streams read every
//! few milliseconds and handed on as recording records, until the supervisor says it stops or
//! the stack falls silent with none of its nodes left. `afs view` and `afs record` are built
//! on it; on a remote host they follow what the link board carries (docs/link.md).

use super::topics::{ContactSource, Rec, live};
use crate::ipc::{self, Svc};
use afs_shared::insertion::geometry::PegHoleGeometry;
use afs_shared::join::Joiner;
use afs_shared::live::InsertionLive;
use afs_shared::msg::{
    self, FrictionReport, LoopStats, PegSample, PlantSample, SensorStats, ServoSample,
    SupervisorPhase, SupervisorStatus, WrenchSample,
};
use afs_shared::scenario::ScenarioKind;
use anyhow::{Context, Result, bail};
use iceoryx2::node::Node;
use iceoryx2::port::subscriber::Subscriber;
use std::time::{Duration, Instant};

/// Silence after which the follower looks whether the stack still has nodes.
const SILENCE: Duration = Duration::from_secs(2);

/// Why following ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// The supervisor published its `Stopping` status.
    Stopping,
    /// Silent, and no node of the stack left but the follower's own.
    Gone,
}

/// Subscribers on every stream of stack `prefix`.
pub struct Follower {
    prefix: String,
    name: String,
    plant: Subscriber<Svc, PlantSample, ()>,
    servo: Subscriber<Svc, ServoSample, ()>,
    wrench: Subscriber<Svc, WrenchSample, ()>,
    stats: Subscriber<Svc, LoopStats, ()>,
    sensor_stats: Subscriber<Svc, SensorStats, ()>,
    friction: Subscriber<Svc, FrictionReport, ()>,
    status: Subscriber<Svc, SupervisorStatus, ()>,
    /// The insertion's stream, opened once the supervisor's status names the `insertion`
    /// scenario (a stack of another scenario does not have it).
    peg: Option<Subscriber<Svc, PegSample, ()>>,
    /// The `/contact` record's source (the world blackboard, once the supervisor made it).
    contact: ContactSource,
    /// Holds the ports' node (dropped after them).
    _node: Node<Svc>,
    joiner: Joiner,
    heard: Instant,
}

impl Follower {
    /// Opens the streams of stack `prefix` as node `name`; refuses a prefix with no node alive.
    pub fn open(prefix: &str, name: &str) -> Result<Self> {
        ipc::check_prefix(prefix)?;
        if ipc::census(prefix, false)?.alive.is_empty() {
            bail!(
                "no stack with prefix '{prefix}' is running; start one with `afs run --prefix {prefix}` (or, on another host, its link board)"
            );
        }
        let node = ipc::node(prefix, name)?;
        let sub = |what: &str| format!("creating the {name} {what} subscriber");
        Ok(Self {
            plant: ipc::plant(&node)?
                .subscriber_builder()
                .create()
                .with_context(|| sub("world"))?,
            servo: ipc::servo(&node)?
                .subscriber_builder()
                .create()
                .with_context(|| sub("controller"))?,
            wrench: ipc::wrench(&node)?
                .subscriber_builder()
                .create()
                .with_context(|| sub("force"))?,
            stats: ipc::loop_stats(&node)?
                .subscriber_builder()
                .create()
                .with_context(|| sub("loop-statistics"))?,
            sensor_stats: ipc::sensor_stats(&node)?
                .subscriber_builder()
                .create()
                .with_context(|| sub("sensor-statistics"))?,
            friction: ipc::friction(&node)?
                .subscriber_builder()
                .create()
                .with_context(|| sub("friction"))?,
            status: ipc::supervisor(&node)?
                .subscriber_builder()
                .create()
                .with_context(|| sub("status"))?,
            peg: None,
            contact: ContactSource::default(),
            _node: node,
            joiner: Joiner::default(),
            heard: Instant::now(),
            prefix: prefix.to_string(),
            name: name.to_string(),
        })
    }

    /// Hands every sample waiting to `sink` (with the `/live` record of each joined tick);
    /// says whether the stack ended.
    pub fn poll(&mut self, mut sink: impl FnMut(Rec)) -> Result<Option<Ended>> {
        let mut any = false;
        while let Ok(Some(s)) = self.plant.receive() {
            any = true;
            let p = *s.payload();
            if !self.joiner.is_repeat(&p) {
                sink(Rec::Plant(p));
                self.joiner.push_plant(p);
            }
        }
        while let Ok(Some(s)) = self.servo.receive() {
            any = true;
            sink(Rec::Servo(*s.payload()));
            self.joiner.push_servo(*s.payload());
        }
        self.joiner.pairs(|p, s| {
            if let Some(r) = live(p, s) {
                sink(r);
            }
        });
        while let Ok(Some(s)) = self.wrench.receive() {
            any = true;
            sink(Rec::Wrench(*s.payload()));
        }
        while let Ok(Some(s)) = self.stats.receive() {
            sink(Rec::Stats(Box::new(*s.payload())));
        }
        while let Ok(Some(s)) = self.sensor_stats.receive() {
            sink(Rec::SensorStats(*s.payload()));
        }
        while let Ok(Some(s)) = self.friction.receive() {
            sink(Rec::Friction(*s.payload()));
        }
        let mut stopping = false;
        let mut insertion = false;
        while let Ok(Some(s)) = self.status.receive() {
            any = true;
            let st = *s.payload();
            sink(Rec::Status(Box::new(st)));
            stopping |= SupervisorPhase::try_from(st.phase) == Ok(SupervisorPhase::Stopping);
            insertion |= msg::str_of(&st.scenario) == ScenarioKind::Insertion.name();
        }
        if insertion && self.peg.is_none() {
            self.peg = Some(
                ipc::peg(&self._node)?
                    .subscriber_builder()
                    .create()
                    .with_context(|| format!("creating the {} insertion subscriber", self.name))?,
            );
        }
        if let Some(peg) = &self.peg {
            // The scenario's peg (its settings set the fit, never the peg).
            let width = PegHoleGeometry::default().peg_width_m;
            while let Ok(Some(s)) = peg.receive() {
                sink(Rec::Insertion(InsertionLive::of_sample(s.payload(), width)));
            }
        }
        self.contact(&mut sink);
        if stopping {
            return Ok(Some(Ended::Stopping));
        }
        if any {
            self.heard = Instant::now();
        } else if self.heard.elapsed() > SILENCE {
            // Silent: ended, or between a board's death and its restart.
            let others = ipc::census(&self.prefix, false)?
                .alive
                .iter()
                .filter(|(n, _)| *n != self.name)
                .count();
            if others == 0 {
                return Ok(Some(Ended::Gone));
            }
            self.heard = Instant::now();
        }
        Ok(None)
    }

    /// The `/contact` record, when one is due.
    fn contact(&mut self, sink: &mut impl FnMut(Rec)) {
        if let Some(c) = self.contact.poll(|| ipc::open_world(&self._node)) {
            sink(Rec::Contact(c));
        }
    }

    /// The CPUs the stack's live processes are pinned to.
    pub fn pinned_cpus(&self) -> Result<Vec<usize>> {
        let mut cpus: Vec<usize> = ipc::census(&self.prefix, false)?
            .alive
            .iter()
            .filter_map(|(_, pid)| crate::rt::pinned_cpu(*pid))
            .collect();
        cpus.sort_unstable();
        cpus.dedup();
        Ok(cpus)
    }

    /// Closes the ports and leaves the prefix as the supervisor would if this was its last
    /// node (the supervisor was killed): iceoryx2 keeps the node counter, removed by name.
    pub fn close(self) {
        let prefix = self.prefix.clone();
        drop(self);
        let _ = ipc::release_prefix(&prefix);
    }
}
