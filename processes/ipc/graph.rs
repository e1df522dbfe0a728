//! The process graph as data: which process writes and which reads each iceoryx2 service of a
//! stack. `afs graph` draws it (the README's picture); `tests/stack` checks it against the
//! nodes a running stack has on each service, so the picture cannot drift from the code.

use afs_shared::msg::service;

/// A process of the graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Party {
    /// `afs-servo`: the world and the fast loop.
    Servo,
    /// `afs-sensor`: the force sensor on its own clock.
    Sensor,
    /// `afs-estimator`: tangent, rotation centre, friction identification.
    Estimator,
    /// `afs run`: launches, watches, restarts, checks.
    Supervisor,
    /// `afs-link`: the services to and from another host.
    Link,
    /// Anything outside the stack: `afs status`, `afs view`, `afs record`, Python clients.
    Clients,
}

impl Party {
    /// Every party, in drawing order.
    pub const ALL: [Party; 6] = [
        Party::Servo,
        Party::Sensor,
        Party::Estimator,
        Party::Supervisor,
        Party::Link,
        Party::Clients,
    ];

    /// The iceoryx2 node name of a board's process (None for the clients, which have many).
    pub fn node(self) -> Option<&'static str> {
        match self {
            Party::Servo => Some("servo"),
            Party::Sensor => Some("sensor"),
            Party::Estimator => Some("estimator"),
            Party::Supervisor => Some("supervisor"),
            Party::Link => Some("link"),
            Party::Clients => None,
        }
    }

    /// Its label in the picture.
    pub fn label(self) -> &'static str {
        match self {
            Party::Servo => "afs-servo",
            Party::Sensor => "afs-sensor",
            Party::Estimator => "afs-estimator",
            Party::Supervisor => "afs run (supervisor)",
            Party::Link => "afs-link",
            Party::Clients => "afs status, view, record, Python",
        }
    }

    /// What it is, in a few words.
    pub fn role(self) -> &'static str {
        match self {
            Party::Servo => "world + fast loop, 10 kHz, SCHED_FIFO",
            Party::Sensor => "force sensor, 7 kHz, own clock",
            Party::Estimator => "tangent, rotation centre, friction",
            Party::Supervisor => "launch, watch, restart, check",
            Party::Link => "to and from another host (zenoh)",
            Party::Clients => "read any stream, send commands",
        }
    }
}

/// How a service carries its messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pattern {
    /// Publish-subscribe.
    Stream,
    /// Request-response.
    Request,
    /// A blackboard (key-value, the latest value).
    Blackboard,
}

/// One service: who writes it, who reads it.
#[derive(Debug, Clone, Copy)]
pub struct Edge {
    /// The iceoryx2 service name.
    pub service: &'static str,
    /// The message it carries.
    pub message: &'static str,
    /// How.
    pub pattern: Pattern,
    /// Who writes (publishes, asks, writes the blackboard).
    pub from: &'static [Party],
    /// Who reads (subscribes, answers, reads the blackboard).
    pub to: &'static [Party],
    /// Opened only in some set-ups (a scenario, a link board), not by the default stack.
    pub optional: bool,
}

use Party::{Clients, Estimator, Link, Sensor, Servo, Supervisor};

/// Every service of a stack (docs/messages.md has their layouts and settings).
pub const EDGES: &[Edge] = &[
    edge(
        service::PLANT,
        "PlantSample",
        &[Servo],
        &[Sensor, Supervisor, Clients],
    ),
    edge(
        service::WRENCH,
        "WrenchSample",
        &[Sensor],
        &[Servo, Supervisor, Clients],
    ),
    edge(
        service::SERVO,
        "ServoSample",
        &[Servo],
        &[Estimator, Supervisor, Link, Clients],
    ),
    edge(
        service::LOOP_STATS,
        "LoopStats",
        &[Servo],
        &[Supervisor, Clients],
    ),
    edge(
        service::SENSOR_STATS,
        "SensorStats",
        &[Sensor],
        &[Supervisor, Clients],
    ),
    edge(
        service::FRICTION,
        "FrictionReport",
        &[Estimator],
        &[Supervisor, Clients],
    ),
    edge(
        service::SUPERVISOR,
        "SupervisorStatus",
        &[Supervisor],
        &[Clients],
    ),
    edge(
        service::STARTUP,
        "BoardStartup",
        &[Servo, Sensor, Estimator],
        &[Supervisor],
    ),
    edge(
        service::COMMAND,
        "ServoCommand",
        &[Supervisor, Clients],
        &[Servo],
    ),
    Edge {
        pattern: Pattern::Request,
        ..edge(service::TANGENT, "TangentRequest", &[Servo], &[Estimator])
    },
    Edge {
        pattern: Pattern::Request,
        ..edge(
            service::ROTATION,
            "RotationRequest",
            &[Clients],
            &[Estimator],
        )
    },
    Edge {
        pattern: Pattern::Blackboard,
        ..edge(
            service::WORLD,
            "WorldSnapshot",
            &[Servo],
            &[Supervisor, Servo],
        )
    },
    optional(service::PEG, "PegSample", &[Servo], &[Supervisor, Clients]),
    optional(service::LINK_SERVO, "ServoBatch", &[Link], &[Link]),
    optional(
        service::TANGENT_REQUEST,
        "TangentRequest",
        &[Servo, Link],
        &[Estimator, Link],
    ),
    optional(
        service::TANGENT_RESPONSE,
        "TangentResponse",
        &[Estimator, Link],
        &[Servo, Link],
    ),
    optional(
        service::ROTATION_REQUEST,
        "RotationRequest",
        &[Clients, Link],
        &[Estimator, Link],
    ),
    optional(
        service::ROTATION_RESPONSE,
        "RotationResponse",
        &[Estimator, Link],
        &[Clients, Link],
    ),
];

const fn edge(
    service: &'static str,
    message: &'static str,
    from: &'static [Party],
    to: &'static [Party],
) -> Edge {
    Edge {
        service,
        message,
        pattern: Pattern::Stream,
        from,
        to,
        optional: false,
    }
}

const fn optional(
    service: &'static str,
    message: &'static str,
    from: &'static [Party],
    to: &'static [Party],
) -> Edge {
    Edge {
        optional: true,
        ..edge(service, message, from, to)
    }
}

/// The edge of service `name`.
pub fn edge_of(name: &str) -> Option<&'static Edge> {
    EDGES.iter().find(|e| e.service == name)
}
