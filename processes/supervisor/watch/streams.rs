//! The streams the supervisor reads (world, controller and force samples, statistics, start-up
//! reports, friction) and writes (status, commands), and where its samples go besides its own
//! checks: the recording and the live view.

use super::Supervisor;
use crate::chaos::ServoView;
use crate::ipc::{self, Svc};
use crate::observe::record::Recorder;
use crate::observe::topics::{self, ContactSource, Rec};
use crate::observe::view::LiveView;
use crate::rt;
use afs_shared::insertion::geometry::PegHoleGeometry;
use afs_shared::live::InsertionLive;
use afs_shared::msg::{
    Board, BoardStartup, FrictionReport, LoopStats, PegSample, PlantSample, ProcessState,
    SensorStats, ServoCommand, ServoSample, SupervisorStatus, WrenchFlags, WrenchSample,
};
use afs_shared::servo::ServoMode;
use anyhow::{Context, Result};
use iceoryx2::node::Node;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use std::time::Instant;

/// The ports the supervisor reads and writes.
pub struct Ports {
    pub(super) plant: Subscriber<Svc, PlantSample, ()>,
    pub(super) servo: Subscriber<Svc, ServoSample, ()>,
    pub(super) wrench: Subscriber<Svc, WrenchSample, ()>,
    /// The servo loop's statistics.
    pub stats: Subscriber<Svc, LoopStats, ()>,
    /// The sensor board's statistics.
    pub sensor_stats: Subscriber<Svc, SensorStats, ()>,
    pub(super) friction: Subscriber<Svc, FrictionReport, ()>,
    pub(super) startup: Subscriber<Svc, BoardStartup, ()>,
    pub(super) status: Publisher<Svc, SupervisorStatus, ()>,
    pub(super) command: Publisher<Svc, ServoCommand, ()>,
    /// The insertion's samples (`insertion` scenario only).
    pub(super) peg: Option<Subscriber<Svc, PegSample, ()>>,
    /// The `/contact` record's source.
    pub(super) contact: ContactSource,
}

impl Ports {
    /// Opens them on the supervisor's node (with the insertion's stream for an insertion).
    pub fn open(node: &Node<Svc>, insertion: bool) -> Result<Self> {
        let peg = if insertion {
            Some(
                ipc::peg(node)?
                    .subscriber_builder()
                    .buffer_size(ipc::TICK_BUFFER)
                    .create()
                    .context("creating the insertion subscriber")?,
            )
        } else {
            None
        };
        Ok(Self {
            peg,
            contact: ContactSource::new(ipc::open_world(node)),
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
    pub(super) fn any(&self) -> bool {
        self.recorder.is_some() || self.view.is_some()
    }

    pub(super) fn push(&mut self, r: Rec) {
        match (self.recorder.as_mut(), self.view.as_mut()) {
            (Some(x), Some(v)) => {
                v.push(r.clone());
                x.push(r);
            }
            (Some(x), None) => x.push(r),
            (None, Some(v)) => v.push(r),
            (None, None) => {}
        }
    }
}

impl Supervisor {
    /// Reads every stream: world and controller samples (joined, monitored, recorded), force
    /// samples, start-up reports, loop statistics, friction reports.
    pub(super) fn poll_streams(&mut self) {
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
        self.take_peg();
        self.take_contact();
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
            self.sinks.push(Rec::Stats(Box::new(*s.payload())));
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

    /// The insertion's samples, to its monitor (which skips a restarted servo's repeat).
    fn take_peg(&mut self) {
        let Some(sub) = &self.ports.peg else {
            return;
        };
        // The scenario's peg (its options set the fit, never the peg).
        let width = PegHoleGeometry::default().peg_width_m;
        while let Ok(Some(s)) = sub.receive() {
            let g = s.payload();
            self.monitor.push_peg(g);
            if self.sinks.any() {
                self.sinks
                    .push(Rec::Insertion(InsertionLive::of_sample(g, width)));
            }
        }
    }

    /// The `/contact` record, when one is due and anything records or shows it.
    fn take_contact(&mut self) {
        if !self.sinks.any() {
            return;
        }
        if let Some(c) = self.ports.contact.poll(|| None) {
            self.sinks.push(Rec::Contact(c));
        }
    }

    /// Feeds the ticks with both samples to the monitors.
    fn pair(&mut self) {
        let (monitor, faults, sinks) = (&mut self.monitor, &mut self.faults, &mut self.sinks);
        let live = sinks.any();
        self.joiner.pairs(|p, s| {
            monitor.push(p, s);
            faults.push(p, s);
            if live && let Some(r) = topics::live(p, s) {
                sinks.push(r);
            }
        });
    }

    /// One step of the fault injector, and what it asks for.
    /// What is still in flight after the loop.
    pub(super) fn drain(&mut self) {
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
        self.take_peg();
        while let Ok(Some(s)) = self.ports.friction.receive() {
            self.friction = Some(*s.payload());
        }
    }
}
