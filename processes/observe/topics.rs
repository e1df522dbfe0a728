//! The topics a stack's streams are recorded and shown under: one record type ([`Rec`]), the
//! topic list with each message's type name ([`TOPICS`]), and each topic's JSON schema from
//! the message's byte layout. The recording, the live view and the follower share it.

use crate::ipc::{self, Svc};
use afs_shared::live::{ContactLive, InsertionLive, LiveSample};
use afs_shared::msg::{
    self, FrictionReport, LoopStats, PlantSample, SensorStats, ServoSample, SupervisorStatus,
    WrenchSample,
};
use iceoryx2::service::port_factory::blackboard;
use serde::Serialize;
use std::time::Instant;

/// One recorded sample.
#[derive(Debug, Clone)]
pub enum Rec {
    /// `/plant`.
    Plant(PlantSample),
    /// `/servo`.
    Servo(ServoSample),
    /// `/wrench`.
    Wrench(WrenchSample),
    /// `/loop_stats` (boxed, as `/supervisor`: ten a second, and the largest variants; the
    /// recorder's queue holds [`Rec`]s by value).
    Stats(Box<LoopStats>),
    /// `/friction`.
    Friction(FrictionReport),
    /// `/supervisor`.
    Status(Box<SupervisorStatus>),
    /// `/sensor_stats`.
    SensorStats(SensorStats),
    /// `/live`: the tick's display record, from its world and controller samples.
    Live(LiveSample),
    /// `/insertion`: an insertion tick's display record (`insertion` scenario).
    Insertion(InsertionLive),
    /// `/contact`: what the servo knows of its contact, from its newest snapshot.
    Contact(ContactLive),
}

/// How often the `/contact` record is made from the servo's newest world snapshot.
pub const CONTACT_EVERY: std::time::Duration = std::time::Duration::from_millis(100);

/// Where the `/contact` record comes from: the world blackboard the supervisor makes, read
/// every [`CONTACT_EVERY`]. The recording and the follower share it.
#[derive(Default)]
pub struct ContactSource {
    world: Option<blackboard::PortFactory<Svc, u64>>,
    at: Option<Instant>,
}

impl ContactSource {
    /// A source reading `world` (None: opened later, by [`ContactSource::poll`]'s opener).
    pub fn new(world: Option<blackboard::PortFactory<Svc, u64>>) -> Self {
        Self { world, at: None }
    }

    /// The record, when one is due: the blackboard opened with `open` while it is missing, and
    /// the servo's newest snapshot read from it. None when not due or nothing is there yet.
    pub fn poll(
        &mut self,
        open: impl FnOnce() -> Option<blackboard::PortFactory<Svc, u64>>,
    ) -> Option<ContactLive> {
        if self.at.is_some_and(|t| t.elapsed() < CONTACT_EVERY) {
            return None;
        }
        self.at = Some(Instant::now());
        if self.world.is_none() {
            self.world = open();
        }
        let snapshot = ipc::newest_world(self.world.as_ref()?).ok()??;
        Some(ContactLive::of_snapshot(
            &snapshot,
            crate::rt::monotonic_ns(),
        ))
    }
}

/// The topics, in channel order: (topic, message type name).
pub const TOPICS: [(&str, &str); 10] = [
    ("/plant", "afs::PlantSample"),
    ("/servo", "afs::ServoSample.v3"),
    ("/wrench", "afs::WrenchSample"),
    ("/loop_stats", "afs::LoopStats.v2"),
    ("/friction", "afs::FrictionReport"),
    ("/supervisor", "afs::SupervisorStatus"),
    ("/sensor_stats", "afs::SensorStats"),
    ("/live", "afs::LiveSample"),
    ("/insertion", "afs::InsertionLive"),
    ("/contact", "afs::ContactLive"),
];

impl Rec {
    /// Its index in [`TOPICS`].
    pub fn channel(&self) -> usize {
        match self {
            Rec::Plant(_) => 0,
            Rec::Servo(_) => 1,
            Rec::Wrench(_) => 2,
            Rec::Stats(_) => 3,
            Rec::Friction(_) => 4,
            Rec::Status(_) => 5,
            Rec::SensorStats(_) => 6,
            Rec::Live(_) => 7,
            Rec::Insertion(_) => 8,
            Rec::Contact(_) => 9,
        }
    }

    /// Its publication time (ns, monotonic): the recording's log time.
    pub fn publish_ns(&self) -> u64 {
        match self {
            Rec::Plant(s) => s.publish_ns,
            Rec::Servo(s) => s.publish_ns,
            Rec::Wrench(s) => s.publish_ns,
            Rec::Stats(s) => s.publish_ns,
            Rec::Friction(s) => s.publish_ns,
            Rec::Status(s) => s.publish_ns,
            Rec::SensorStats(s) => s.publish_ns,
            Rec::Live(s) => s.publish_ns,
            Rec::Insertion(s) => s.publish_ns,
            Rec::Contact(s) => s.publish_ns,
        }
    }

    /// Its JSON encoding.
    pub fn json(&self) -> serde_json::Result<Vec<u8>> {
        fn j<T: Serialize>(t: &T) -> serde_json::Result<Vec<u8>> {
            serde_json::to_vec(t)
        }
        match self {
            Rec::Plant(s) => j(s),
            Rec::Servo(s) => j(s),
            Rec::Wrench(s) => j(s),
            Rec::Stats(s) => j(s),
            Rec::Friction(s) => j(s),
            Rec::Status(s) => j(s),
            Rec::SensorStats(s) => j(s),
            Rec::Live(s) => j(s),
            Rec::Insertion(s) => j(s),
            Rec::Contact(s) => j(s),
        }
    }
}

/// The live record of a joined tick, for the sinks that want it.
pub fn live(p: &PlantSample, s: &ServoSample) -> Option<Rec> {
    LiveSample::of_tick(p, s).map(Rec::Live)
}

/// A JSON schema of a message type, from its byte layout (numbers, arrays of numbers, nested
/// objects).
pub fn json_schema(type_name: &str) -> String {
    if type_name == "afs::LiveSample" {
        return serde_schema(type_name, &LiveSample::default()).to_string();
    }
    if type_name == "afs::InsertionLive" {
        return serde_schema(type_name, &InsertionLive::default()).to_string();
    }
    if type_name == "afs::ContactLive" {
        return serde_schema(type_name, &ContactLive::default()).to_string();
    }
    let layouts = msg::layouts();
    let Some(l) = layouts.iter().find(|l| l.type_name == type_name) else {
        return r#"{"type":"object"}"#.into();
    };
    let mut props = serde_json::Map::new();
    for f in &l.fields {
        let scalar = if f.ty.starts_with('u') || f.ty.starts_with('i') {
            "integer"
        } else if f.ty.starts_with("bool") {
            "boolean"
        } else if f.ty.starts_with('f') {
            "number"
        } else {
            "object"
        };
        let v = if f.ty.contains('[') {
            serde_json::json!({"type": "array", "items": {"type": scalar}})
        } else {
            serde_json::json!({"type": scalar})
        };
        props.insert(f.name.to_string(), v);
    }
    serde_json::json!({"type": "object", "title": type_name, "properties": props}).to_string()
}

/// The schema of a display record (not an iceoryx2 message, so without a byte layout):
/// every field typed as it serialises.
fn serde_schema<T: Serialize>(title: &str, sample: &T) -> serde_json::Value {
    let value = serde_json::to_value(sample).unwrap_or_default();
    let props: serde_json::Map<String, serde_json::Value> = value
        .as_object()
        .into_iter()
        .flatten()
        .map(|(k, v)| {
            let ty = match v {
                serde_json::Value::Bool(_) => "boolean",
                serde_json::Value::Number(n) if n.is_f64() => "number",
                _ => "integer",
            };
            (k.clone(), serde_json::json!({ "type": ty }))
        })
        .collect();
    serde_json::json!({"type": "object", "title": title, "properties": props})
}
