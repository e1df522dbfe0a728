//! The servo board's iceoryx2 ports: the world and controller streams out, force samples and
//! commands in, the loop statistics, the estimator's service in either form, and its entry in
//! the supervisor's world blackboard.

use super::link::Transport;
use super::{EstimatorVia, ServoArgs};
use crate::ipc::{self, Svc};
use afs_shared::msg::{
    LoopStats, PegSample, PlantSample, ServoCommand, ServoSample, WorldSnapshot, WrenchSample,
};
use afs_shared::scenario::ScenarioKind;
use anyhow::{Context, Result};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::writer::{EntryHandleMut, Writer};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::blackboard;

/// The ports.
pub(super) struct Ports {
    /// The world, every tick.
    pub(super) plant: Publisher<Svc, PlantSample, ()>,
    /// The controller, every tick.
    pub(super) servo: Publisher<Svc, ServoSample, ()>,
    /// The loop statistics, every 1000 ticks.
    pub(super) stats: Publisher<Svc, LoopStats, ()>,
    /// Force samples.
    pub(super) wrench: Subscriber<Svc, WrenchSample, ()>,
    /// Commands (a tangent estimate asked for).
    pub(super) command: Subscriber<Svc, ServoCommand, ()>,
    /// The insertion, every tick (`insertion` scenario only).
    pub(super) peg: Option<Publisher<Svc, PegSample, ()>>,
    /// The supervisor's world blackboard (None when run on its own).
    pub(super) world: Option<WorldBoard>,
}

/// This servo's entry in the supervisor's world blackboard, and the blackboard (for the
/// snapshots of earlier incarnations).
pub(super) struct WorldBoard {
    factory: blackboard::PortFactory<Svc, u64>,
    // Drop order: the entry before the writer it was taken from.
    entry: EntryHandleMut<Svc, u64, WorldSnapshot>,
    _writer: Writer<Svc, u64>,
}

impl WorldBoard {
    /// Writes this tick's snapshot.
    pub(super) fn write(&self, s: WorldSnapshot) {
        self.entry.update_with_copy(s);
    }

    /// The newest snapshot any incarnation of the servo left (of the current layout).
    pub(super) fn newest(&self) -> Result<Option<WorldSnapshot>> {
        ipc::newest_world(&self.factory)
    }
}

impl Ports {
    /// Opens them on `node`; the estimator's service comes back apart (the estimator link
    /// owns it).
    pub(super) fn open(node: &Node<Svc>, args: &ServoArgs) -> Result<(Self, Transport)> {
        let ports = Self {
            plant: ipc::plant(node)?
                .publisher_builder()
                .backpressure_strategy(ipc::BACKPRESSURE)
                .create()
                .context("plant publisher")?,
            servo: ipc::servo(node)?
                .publisher_builder()
                .backpressure_strategy(ipc::BACKPRESSURE)
                .create()
                .context("servo publisher")?,
            stats: ipc::loop_stats(node)?
                .publisher_builder()
                .create()
                .context("loop-stats publisher")?,
            wrench: ipc::wrench(node)?
                .subscriber_builder()
                .buffer_size(256)
                .create()
                .context("wrench subscriber")?,
            command: ipc::command(node)?
                .subscriber_builder()
                .buffer_size(16)
                .create()
                .context("command subscriber")?,
            peg: if args.scenario == ScenarioKind::Insertion.name() {
                Some(
                    ipc::peg(node)?
                        .publisher_builder()
                        .backpressure_strategy(ipc::BACKPRESSURE)
                        .create()
                        .context("insertion publisher")?,
                )
            } else {
                None
            },
            world: open_world(node)?,
        };
        Ok((ports, open_estimator(node, args.estimator_via)?))
    }
}

fn open_world(node: &Node<Svc>) -> Result<Option<WorldBoard>> {
    let Some(factory) = ipc::open_world(node) else {
        eprintln!(
            "afs-servo: warning: no world blackboard (not started by `afs run`?); a restart will start the world afresh"
        );
        return Ok(None);
    };
    let writer = factory.writer_builder().create().context("world writer")?;
    let entry = (0..ipc::WORLD_SLOTS)
        .find_map(|k| writer.entry::<WorldSnapshot>(&k).ok())
        .with_context(|| {
            format!(
                "no free entry in the world blackboard ({} servo incarnations used them all)",
                ipc::WORLD_SLOTS
            )
        })?;
    Ok(Some(WorldBoard {
        factory,
        entry,
        _writer: writer,
    }))
}

fn open_estimator(node: &Node<Svc>, via: EstimatorVia) -> Result<Transport> {
    Ok(match via {
        EstimatorVia::RequestResponse => Transport::RequestResponse(
            ipc::tangent(node)?
                .client_builder()
                .initial_max_slice_len(ipc::MAX_PROBE_SAMPLES)
                .allocation_strategy(AllocationStrategy::Static)
                .create()
                .context("tangent client")?,
        ),
        EstimatorVia::Topics => Transport::Topics {
            requests: ipc::tangent_requests(node)?
                .publisher_builder()
                .initial_max_slice_len(ipc::MAX_PROBE_SAMPLES)
                .allocation_strategy(AllocationStrategy::Static)
                .backpressure_strategy(ipc::BACKPRESSURE)
                .max_loaned_samples(1)
                .create()
                .context("tangent request publisher")?,
            responses: ipc::tangent_responses(node)?
                .subscriber_builder()
                .create()
                .context("tangent response subscriber")?,
        },
    })
}
