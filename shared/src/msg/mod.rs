//! The messages the afs processes exchange over iceoryx2 shared memory.
//!
//! Every type is `#[repr(C)]`, fixed-size (or a slice of a fixed-size element), free of
//! pointers, and derives `ZeroCopySend` with a stable `#[type_name]` so that a client in another
//! language (iceoryx2's C, C++ or Python bindings) can subscribe with a struct of the same
//! layout and name. Each starts with a `version` ([`VERSION`]); each carries a sequence number
//! and the timestamps of its life on one clock: `CLOCK_MONOTONIC` in nanoseconds, the same for
//! every process on the machine. Byte layouts and service names: `docs/messages.md` (checked by
//! the tests below).
//!
//! Conversions to and from the core's types ([`TangentOutcome`], [`TangentParams`],
//! [`ProbePlan`]) live here so that both ends of a service use the same code.

mod estimation;
mod insertion;
mod layout;
mod link;
mod samples;
mod status;
mod world;

pub use estimation::*;
pub use insertion::*;
pub use layout::*;
pub use link::*;
pub use samples::*;
pub use status::*;
pub use world::*;

/// Service names. Stacks are isolated by the iceoryx2 file prefix (`afs_<prefix>_`), not by the
/// names, so a client opens these names with the stack's config.
pub mod service {
    /// [`PlantSample`](super::PlantSample), every servo tick (servo → sensor, recorder).
    pub const PLANT: &str = "afs/plant/state";
    /// [`WrenchSample`](super::WrenchSample), every sensor sample (sensor → servo).
    pub const WRENCH: &str = "afs/sensor/wrench";
    /// [`SensorStats`](super::SensorStats), 10 Hz.
    pub const SENSOR_STATS: &str = "afs/sensor/stats";
    /// [`ServoSample`](super::ServoSample), every servo tick.
    pub const SERVO: &str = "afs/servo/state";
    /// [`LoopStats`](super::LoopStats), 10 Hz.
    pub const LOOP_STATS: &str = "afs/servo/loop_stats";
    /// Request-response: [`TangentRequestHeader`](super::TangentRequestHeader) +
    /// `[ProbeSample]` → [`TangentResponse`](super::TangentResponse).
    pub const TANGENT: &str = "afs/estimator/tangent";
    /// Request-response: [`RotationRequestHeader`](super::RotationRequestHeader) +
    /// `[RotationSample]` → [`RotationResponse`](super::RotationResponse).
    pub const ROTATION: &str = "afs/estimator/rotation";
    /// [`FrictionReport`](super::FrictionReport), about 1 Hz.
    pub const FRICTION: &str = "afs/estimator/friction";
    /// [`SupervisorStatus`](super::SupervisorStatus), 2 Hz.
    pub const SUPERVISOR: &str = "afs/supervisor/status";
    /// [`BoardStartup`](super::BoardStartup), once per board process (boards → supervisor).
    pub const STARTUP: &str = "afs/boards/startup";
    /// [`ServoCommand`], on demand (supervisor, clients → servo).
    pub const COMMAND: &str = "afs/servo/command";
    /// [`ServoBatch`](super::ServoBatch): the servo's stream packed for a link to another
    /// host (link board → link board, docs/link.md).
    pub const LINK_SERVO: &str = "afs/link/servo";
    /// The tangent service as two topics, for an estimator on another host (a link carries
    /// publish-subscribe only): [`TangentRequestHeader`](super::TangentRequestHeader) +
    /// `[ProbeSample]` (servo → estimator) ...
    pub const TANGENT_REQUEST: &str = "afs/estimator/tangent/request";
    /// ... and [`TangentResponse`](super::TangentResponse) (estimator → servo).
    pub const TANGENT_RESPONSE: &str = "afs/estimator/tangent/response";
    /// The rotation service as two topics: [`RotationRequestHeader`](super::RotationRequestHeader)
    /// + `[RotationSample]` ...
    pub const ROTATION_REQUEST: &str = "afs/estimator/rotation/request";
    /// ... and [`RotationResponse`](super::RotationResponse).
    pub const ROTATION_RESPONSE: &str = "afs/estimator/rotation/response";
    /// [`PegSample`](super::PegSample), every servo tick of the `insertion` scenario.
    pub const PEG: &str = "afs/insertion/state";
    /// Blackboard of the world's state (key 0: [`WorldSnapshot`](super::WorldSnapshot)),
    /// owned by the supervisor, written by the servo.
    pub const WORLD: &str = "afs/plant/world";
}

/// Copies `s` into a NUL-padded fixed buffer (truncating at a character boundary).
pub fn fixed_str<const N: usize>(s: &str) -> [u8; N] {
    let mut out = [0u8; N];
    let mut end = s.len().min(N);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    out[..end].copy_from_slice(&s.as_bytes()[..end]);
    out
}

/// The text of a NUL-padded fixed buffer.
pub fn str_of(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fixed strings truncate on a character boundary and read back.
    #[test]
    fn fixed_strings() {
        let b: [u8; 6] = fixed_str("servo");
        assert_eq!(str_of(&b), "servo");
        let b: [u8; 4] = fixed_str("añbc");
        assert_eq!(str_of(&b), "añb");
        let b: [u8; 2] = fixed_str("ñx");
        assert_eq!(str_of(&b), "ñ");
    }
}
