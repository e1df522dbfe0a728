//! The stack's iceoryx2 wiring: one config per stack prefix, and the services with the
//! quality-of-service settings every process opens them with (so any process may come first).
//!
//! Stacks are isolated by iceoryx2's file prefix: a stack with prefix `P` keeps every shared
//! memory segment and every file under the iceoryx2 root with names starting `afs_P_`, so two
//! stacks run side by side and a stack's leftovers are easy to find (`leftovers`).

pub mod graph;

use afs_shared::msg::{
    BoardStartup, FrictionReport, LoopStats, PegSample, PlantSample, RotationRequestHeader,
    RotationResponse, RotationSample, SensorStats, ServoBatch, ServoCommand, ServoSample,
    SupervisorStatus, TangentRequestHeader, TangentResponse, WorldSnapshot, WrenchSample, service,
};
use afs_shared::tangent::ProbeSample;
use anyhow::{Context, Result, bail};
use iceoryx2::port::backpressure_strategy::BackpressureStrategy;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{blackboard, publish_subscribe, request_response};

/// The iceoryx2 service type of the stack: inter-process.
pub type Svc = ipc::Service;

/// Largest number of samples a subscriber of a per-tick stream may buffer (2 s at 10 kHz).
pub const TICK_BUFFER: usize = 20_000;
/// Largest number of wrench samples a subscriber may buffer (about 1 s at 7 kHz).
pub const WRENCH_BUFFER: usize = 8_192;
/// Largest probe record a tangent request carries (samples): a re-probe plan at 1 kHz with
/// margin.
pub const MAX_PROBE_SAMPLES: usize = 40_000;
/// Largest rotation-dither record (samples).
pub const MAX_ROTATION_SAMPLES: usize = 100_000;

/// Checks a stack prefix: 1–32 characters of `[A-Za-z0-9_-]`.
pub fn check_prefix(prefix: &str) -> Result<()> {
    if prefix.is_empty()
        || prefix.len() > 32
        || !prefix
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        bail!("invalid stack prefix '{prefix}': use 1 to 32 letters, digits, '_' or '-'");
    }
    Ok(())
}

/// The iceoryx2 file-name prefix of stack `prefix`.
pub fn file_prefix(prefix: &str) -> String {
    format!("afs_{prefix}_")
}

/// The iceoryx2 config of stack `prefix`: its file prefix, under this user's root folder
/// ([`root_path`]).
pub fn config(prefix: &str) -> Result<Config> {
    check_prefix(prefix)?;
    let mut c = Config::default();
    c.global.prefix = FileName::new(file_prefix(prefix).as_bytes())
        .with_context(|| format!("stack prefix '{prefix}'"))?;
    let root = root_path();
    c.global.set_root_path(
        &iceoryx2::prelude::Path::new(root.as_bytes())
            .with_context(|| format!("iceoryx2 root folder '{root}'"))?,
    );
    Ok(c)
}

/// The iceoryx2 root folder of this user's stacks: iceoryx2's own, `/tmp/iceoryx2/`, for root,
/// `/tmp/iceoryx2-<uid>/` for any other user. iceoryx2 makes its root folder readable only by
/// whoever made it first, so one shared folder locks every other user out (a `sudo afs run`
/// once, and a user's stacks fail with "insufficient permissions"). The user is the machine's:
/// inside a user namespace that `unshare --map-root-user` made (examples/two-hosts.sh), root is
/// the user who made it, and sees that user's stacks. examples/python/afs_client.py follows the
/// same rule.
pub fn root_path() -> String {
    // SAFETY: getuid has no preconditions and cannot fail.
    let uid = unsafe { libc::getuid() };
    let uid = std::fs::read_to_string("/proc/self/uid_map")
        .ok()
        .and_then(|map| machine_uid(&map, uid))
        .unwrap_or(uid);
    if uid == 0 {
        "/tmp/iceoryx2/".into()
    } else {
        format!("/tmp/iceoryx2-{uid}/")
    }
}

/// The machine's id of `uid` by a user namespace's `uid_map` (lines of: first id inside, first
/// id outside, count); None if no line maps it.
#[doc(hidden)]
pub fn machine_uid(map: &str, uid: u32) -> Option<u32> {
    map.lines().find_map(|line| {
        let f: Vec<u64> = line
            .split_whitespace()
            .filter_map(|x| x.parse().ok())
            .collect();
        let (inside, outside, count) = (*f.first()?, *f.get(1)?, *f.get(2)?);
        let uid = u64::from(uid);
        (f.len() == 3 && inside <= uid && uid < inside + count)
            .then(|| u32::try_from(outside + (uid - inside)).ok())
            .flatten()
    })
}

/// The iceoryx2 config of stack `prefix` as the TOML file iceoryx2 reads: with it in
/// `config/iceoryx2.toml` of the working directory (or `~/.config/iceoryx2/iceoryx2.toml`), the
/// upstream `iox2` CLI and any iceoryx2 program see the stack's nodes and services.
pub fn config_toml(prefix: &str) -> Result<String> {
    let c = config(prefix)?;
    let body = toml::to_string_pretty(&c).context("writing the iceoryx2 config as TOML")?;
    Ok(format!(
        "# iceoryx2 config of the afs stack with prefix '{prefix}' (afs iox2-config --prefix {prefix}).\n\
         # iceoryx2 reads ./config/iceoryx2.toml, then ~/.config/iceoryx2/iceoryx2.toml, then\n\
         # /etc/iceoryx2/iceoryx2.toml; the stack's files are named {}*.\n{body}",
        file_prefix(prefix)
    ))
}

/// A node of stack `prefix` named `name`; iceoryx2's own signal handling is off (the
/// processes handle SIGINT/SIGTERM themselves).
pub fn node(prefix: &str, name: &str) -> Result<Node<Svc>> {
    let cfg = config(prefix)?;
    let node_name: NodeName = name
        .try_into()
        .with_context(|| format!("node name '{name}'"))?;
    NodeBuilder::new()
        .name(&node_name)
        .config(&cfg)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Svc>()
        .with_context(|| format!("creating iceoryx2 node '{name}' for stack '{prefix}'"))
}

pub fn name(s: &str) -> Result<ServiceName> {
    s.try_into().with_context(|| format!("service name '{s}'"))
}

/// How a publish-subscribe service is opened: every afs stream has safe overflow (a slow
/// subscriber loses its oldest samples, it never blocks the publisher); the rest differs per
/// stream (docs/messages.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StreamSettings {
    /// Samples a new subscriber receives at once.
    pub history: usize,
    /// Samples a subscriber buffers.
    pub buffer: usize,
    /// Samples a subscriber may hold at once (None: iceoryx2's default).
    pub borrowed: Option<usize>,
    /// Subscribers at most.
    pub subscribers: usize,
    /// Publishers at most.
    pub publishers: usize,
    /// Nodes at most.
    pub nodes: usize,
}

/// The per-tick streams (plant and servo samples): one publisher, history 1, buffers deep
/// enough for a subscriber that looks twice a second.
pub const TICK_STREAM: StreamSettings = StreamSettings {
    history: 1,
    buffer: TICK_BUFFER,
    borrowed: Some(4),
    subscribers: 4,
    publishers: 1,
    nodes: 8,
};

/// The insertion's stream (`insertion` scenario).
pub fn peg(node: &Node<Svc>) -> Result<publish_subscribe::PortFactory<Svc, PegSample, ()>> {
    stream(node, service::PEG, TICK_STREAM)
}

/// The wrench stream. No history: a new subscriber waits at most one sensor period, and keeping
/// one costs every send (≈ 60 ns of a 0.75 µs hop, `afs bench hop`). Three publishers: the
/// sensor, a restarted sensor whose predecessor is not cleaned up yet, and the bad-sample
/// injector of `afs chaos`.
pub const WRENCH_STREAM: StreamSettings = StreamSettings {
    history: 0,
    buffer: WRENCH_BUFFER,
    borrowed: Some(4),
    subscribers: 8,
    publishers: 3,
    nodes: 12,
};

/// The low-rate status streams (loop statistics, friction identification, the supervisor's
/// status): history 1, so a late subscriber gets the latest at once. Two publishers: the
/// board's, and the link board's tunnel, which opens one on every service it carries to or
/// from another host (docs/link.md).
pub const STATUS_STREAM: StreamSettings = StreamSettings {
    history: 1,
    buffer: 64,
    borrowed: None,
    subscribers: 8,
    publishers: 2,
    nodes: 12,
};

/// The servo's stream packed for a link (`afs/link/servo`): no history (a far side that
/// joins late starts with the next batch), 1.3 s of batches buffered, two publishers (the
/// packing link board and the far side's tunnel).
pub const LINK_STREAM: StreamSettings = StreamSettings {
    history: 0,
    buffer: 64,
    borrowed: None,
    subscribers: 4,
    publishers: 2,
    nodes: 8,
};

/// The estimator's answers as a topic (`afs/estimator/*/response`): no history (an answer is
/// for the request in flight only), four publishers (the estimator, a restarted one not yet
/// cleaned up, the tunnel).
pub const RESPONSE_STREAM: StreamSettings = StreamSettings {
    history: 0,
    buffer: 8,
    borrowed: None,
    subscribers: 4,
    publishers: 4,
    nodes: 8,
};

/// The servo's command stream: no history (a restarted servo must not act on an old
/// command), a few publishers (the supervisor, clients).
pub const COMMAND_STREAM: StreamSettings = StreamSettings {
    history: 0,
    buffer: 16,
    borrowed: None,
    subscribers: 4,
    publishers: 4,
    nodes: 12,
};

/// The boards' start-up reports: one publisher per board process (and room for dead ones not
/// yet cleaned up), history 1 each.
pub const STARTUP_STREAM: StreamSettings = StreamSettings {
    history: 1,
    buffer: 64,
    borrowed: None,
    subscribers: 8,
    publishers: 16,
    nodes: 24,
};

/// Opens (or creates) the stream `service_name` of `T` with `settings`.
pub fn stream<T>(
    node: &Node<Svc>,
    service_name: &str,
    settings: StreamSettings,
) -> Result<publish_subscribe::PortFactory<Svc, T, ()>>
where
    T: std::fmt::Debug + ZeroCopySend + 'static,
{
    let builder = node
        .service_builder(&name(service_name)?)
        .publish_subscribe::<T>()
        .enable_safe_overflow(true)
        .history_size(settings.history)
        .subscriber_max_buffer_size(settings.buffer)
        .max_subscribers(settings.subscribers)
        .max_publishers(settings.publishers)
        .max_nodes(settings.nodes);
    let builder = match settings.borrowed {
        Some(n) => builder.subscriber_max_borrowed_samples(n),
        None => builder,
    };
    builder.open_or_create().map_err(|e| {
        let what = match layout_mismatch::<T>(node, service_name) {
            Some(m) => m,
            None => format!("{e:?}"),
        };
        anyhow::anyhow!("opening service '{service_name}': {what}")
    })
}

/// The layout version an afs type name carries: `afs::Name.vN` is N, `afs::Name` is 1.
pub fn layout_version(type_name: &str) -> u32 {
    type_name
        .rsplit_once(".v")
        .and_then(|(_, v)| v.parse().ok())
        .unwrap_or(1)
}

/// When the publish-subscribe service `service_name` exists with another payload type than
/// `T`: both type names, layout versions and sizes, and what to do (docs/messages.md,
/// *Versions*). None when it does not exist or carries `T`.
pub fn layout_mismatch<T: ZeroCopySend>(node: &Node<Svc>, service_name: &str) -> Option<String> {
    let details = <Svc as iceoryx2::service::Service>::details(
        &name(service_name).ok()?,
        node.config(),
        iceoryx2::service::messaging_pattern::MessagingPattern::PublishSubscribe,
    )
    .ok()??;
    let payload = &details
        .static_details
        .publish_subscribe()
        .message_type_details()
        .payload;
    let theirs = payload.type_name().to_string();
    // SAFETY: type_name returns the derive attribute's string.
    let ours = unsafe { <T as ZeroCopySend>::type_name() };
    (theirs != ours).then(|| {
        format!(
            "it carries {theirs} (layout version {}, {} bytes) and this program reads {ours} (layout version {}, {} bytes): use afs and clients of the same message versions (docs/messages.md, Versions)",
            layout_version(&theirs),
            payload.size(),
            layout_version(ours),
            std::mem::size_of::<T>()
        )
    })
}

/// The plant stream.
pub fn plant(node: &Node<Svc>) -> Result<publish_subscribe::PortFactory<Svc, PlantSample, ()>> {
    stream(node, service::PLANT, TICK_STREAM)
}

/// The servo stream.
pub fn servo(node: &Node<Svc>) -> Result<publish_subscribe::PortFactory<Svc, ServoSample, ()>> {
    stream(node, service::SERVO, TICK_STREAM)
}

/// The wrench stream.
pub fn wrench(node: &Node<Svc>) -> Result<publish_subscribe::PortFactory<Svc, WrenchSample, ()>> {
    stream(node, service::WRENCH, WRENCH_STREAM)
}

/// The loop statistics stream.
pub fn loop_stats(node: &Node<Svc>) -> Result<publish_subscribe::PortFactory<Svc, LoopStats, ()>> {
    stream(node, service::LOOP_STATS, STATUS_STREAM)
}

/// The sensor board's statistics stream.
pub fn sensor_stats(
    node: &Node<Svc>,
) -> Result<publish_subscribe::PortFactory<Svc, SensorStats, ()>> {
    stream(node, service::SENSOR_STATS, STATUS_STREAM)
}

/// The friction identification stream.
pub fn friction(
    node: &Node<Svc>,
) -> Result<publish_subscribe::PortFactory<Svc, FrictionReport, ()>> {
    stream(node, service::FRICTION, STATUS_STREAM)
}

/// The supervisor's status stream.
pub fn supervisor(
    node: &Node<Svc>,
) -> Result<publish_subscribe::PortFactory<Svc, SupervisorStatus, ()>> {
    stream(node, service::SUPERVISOR, STATUS_STREAM)
}

/// The servo's command stream.
pub fn command(node: &Node<Svc>) -> Result<publish_subscribe::PortFactory<Svc, ServoCommand, ()>> {
    stream(node, service::COMMAND, COMMAND_STREAM)
}

/// The boards' start-up reports.
pub fn startup(node: &Node<Svc>) -> Result<publish_subscribe::PortFactory<Svc, BoardStartup, ()>> {
    stream(node, service::STARTUP, STARTUP_STREAM)
}

/// The servo's stream packed for a link.
pub fn link_servo(node: &Node<Svc>) -> Result<publish_subscribe::PortFactory<Svc, ServoBatch, ()>> {
    stream(node, service::LINK_SERVO, LINK_STREAM)
}

/// A request topic of the publish-subscribe form of an estimation service: a slice of samples
/// behind a header, no history, two requests buffered per subscriber (the servo has one in
/// flight; a re-send may follow it), four publishers (the servo, a restarted one, the tunnel).
fn request_topic<Sample, Header>(
    node: &Node<Svc>,
    service_name: &str,
) -> Result<publish_subscribe::PortFactory<Svc, [Sample], Header>>
where
    Sample: std::fmt::Debug + ZeroCopySend + 'static,
    Header: std::fmt::Debug + ZeroCopySend + 'static,
{
    node.service_builder(&name(service_name)?)
        .publish_subscribe::<[Sample]>()
        .user_header::<Header>()
        .enable_safe_overflow(true)
        .history_size(0)
        .subscriber_max_buffer_size(2)
        .subscriber_max_borrowed_samples(2)
        .max_subscribers(4)
        .max_publishers(4)
        .max_nodes(8)
        .open_or_create()
        .with_context(|| format!("opening service '{service_name}'"))
}

/// The tangent service's request topic (its publish-subscribe form).
pub fn tangent_requests(
    node: &Node<Svc>,
) -> Result<publish_subscribe::PortFactory<Svc, [ProbeSample], TangentRequestHeader>> {
    request_topic(node, service::TANGENT_REQUEST)
}

/// The tangent service's response topic.
pub fn tangent_responses(
    node: &Node<Svc>,
) -> Result<publish_subscribe::PortFactory<Svc, TangentResponse, ()>> {
    stream(node, service::TANGENT_RESPONSE, RESPONSE_STREAM)
}

/// The rotation service's request topic.
pub fn rotation_requests(
    node: &Node<Svc>,
) -> Result<publish_subscribe::PortFactory<Svc, [RotationSample], RotationRequestHeader>> {
    request_topic(node, service::ROTATION_REQUEST)
}

/// The rotation service's response topic.
pub fn rotation_responses(
    node: &Node<Svc>,
) -> Result<publish_subscribe::PortFactory<Svc, RotationResponse, ()>> {
    stream(node, service::ROTATION_RESPONSE, RESPONSE_STREAM)
}

/// An estimation service: requests are a slice of samples behind a header, one response each.
/// Safe overflow both ways, 2 active requests per client, 4 clients, 2 servers.
fn estimation_service<Sample, Header, Response>(
    node: &Node<Svc>,
    service_name: &str,
) -> Result<request_response::PortFactory<Svc, [Sample], Header, Response, ()>>
where
    Sample: std::fmt::Debug + ZeroCopySend + 'static,
    Header: std::fmt::Debug + ZeroCopySend + 'static,
    Response: std::fmt::Debug + ZeroCopySend + 'static,
{
    node.service_builder(&name(service_name)?)
        .request_response::<[Sample], Response>()
        .request_user_header::<Header>()
        .enable_safe_overflow_for_requests(true)
        .enable_safe_overflow_for_responses(true)
        .max_active_requests_per_client(2)
        .max_loaned_requests(2)
        .max_response_buffer_size(4)
        .max_servers(2)
        .max_clients(4)
        .max_nodes(8)
        .open_or_create()
        .with_context(|| format!("opening service '{service_name}'"))
}

/// The tangent-estimation request-response service.
pub fn tangent(
    node: &Node<Svc>,
) -> Result<
    request_response::PortFactory<Svc, [ProbeSample], TangentRequestHeader, TangentResponse, ()>,
> {
    estimation_service(node, service::TANGENT)
}

/// The rotation-centre request-response service.
pub fn rotation(
    node: &Node<Svc>,
) -> Result<
    request_response::PortFactory<
        Svc,
        [RotationSample],
        RotationRequestHeader,
        RotationResponse,
        (),
    >,
> {
    estimation_service(node, service::ROTATION)
}

/// Entries of the world blackboard. Each servo incarnation writes the first entry no other
/// holds: iceoryx2 0.10 keeps the write handle of a SIGKILLed writer registered after its
/// node's clean-up (a new handle on that entry fails with `HandleAlreadyExists`), so a
/// restarted servo takes the next entry, and a resuming one reads the newest snapshot of all.
pub const WORLD_SLOTS: u64 = 64;

/// Creates the world-state blackboard (the supervisor owns it, so it outlives a servo).
pub fn create_world(node: &Node<Svc>) -> Result<blackboard::PortFactory<Svc, u64>> {
    let mut b = node
        .service_builder(&name(service::WORLD)?)
        .blackboard_creator::<u64>()
        .max_readers(4);
    for k in 0..WORLD_SLOTS {
        b = b.add::<WorldSnapshot>(k, WorldSnapshot::default());
    }
    b.create()
        .with_context(|| format!("creating blackboard '{}'", service::WORLD))
}

/// The newest snapshot any incarnation of the servo left in the world blackboard (of the
/// current layout), or None before the first.
pub fn newest_world(factory: &blackboard::PortFactory<Svc, u64>) -> Result<Option<WorldSnapshot>> {
    let reader = factory.reader_builder().create().context("world reader")?;
    let mut newest: Option<WorldSnapshot> = None;
    for k in 0..WORLD_SLOTS {
        let s = *reader
            .entry::<WorldSnapshot>(&k)
            .with_context(|| format!("world entry {k}"))?
            .get();
        if s.version == WorldSnapshot::VERSION && newest.is_none_or(|n| s.seq > n.seq) {
            newest = Some(s);
        }
    }
    Ok(newest)
}

/// Opens the world-state blackboard, if the supervisor made one.
pub fn open_world(node: &Node<Svc>) -> Option<blackboard::PortFactory<Svc, u64>> {
    node.service_builder(&name(service::WORLD).ok()?)
        .blackboard_opener::<u64>()
        .open()
        .ok()
}

/// The publisher settings of every stream: never block the publisher.
pub const BACKPRESSURE: BackpressureStrategy = BackpressureStrategy::DiscardData;

#[doc(hidden)]
pub mod prefix;

pub use prefix::*;
