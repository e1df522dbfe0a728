//! What crosses a link to another host in batches: the servo's per-tick stream, packed so that
//! the link carries a few hundred messages a second instead of one per tick (docs/link.md).

use super::ServoSample;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Servo samples per [`ServoBatch`]: 20 ms of ticks at 10 kHz (50 batches a second: the
/// zenoh carrier's inbox of 64 arrivals per service then holds 1.3 s, docs/link.md).
pub const SERVO_BATCH: usize = 200;

wire_message! {
    version = 3;
    /// Consecutive [`ServoSample`]s of one servo, as the link board of the controller's host packs
    /// them (`afs/link/servo`); the link board of the remote host unpacks them onto its own
    /// `afs/servo/state`.
    #[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
    #[type_name("afs::ServoBatch.v3")]
    pub struct ServoBatch {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// Samples used in `samples` (1 to [`SERVO_BATCH`]).
        pub count: u32,
        /// Batch number, from 1, counted by the packing link board (a restarted one starts again
        /// at 1 with a new `epoch`).
        pub seq: u64,
        /// Start time (monotonic ns) of the packing link board's process: tells its incarnations
        /// apart.
        pub epoch: u64,
        /// Servo samples the packer knows it missed before this batch (gaps in the servo's `seq`
        /// on its own host; 0 unless the packer fell behind).
        pub missed: u64,
        /// Monotonic time of publication (ns).
        pub publish_ns: u64,
        /// The samples, oldest first; `samples[count..]` are zero.
        pub samples: [ServoSample; SERVO_BATCH],
    }
}

impl Default for ServoBatch {
    fn default() -> Self {
        Self {
            version: Self::VERSION,
            count: 0,
            seq: 0,
            epoch: 0,
            missed: 0,
            publish_ns: 0,
            samples: [ServoSample::default(); SERVO_BATCH],
        }
    }
}

impl ServoBatch {
    /// The samples used.
    pub fn used(&self) -> &[ServoSample] {
        &self.samples[..(self.count as usize).min(SERVO_BATCH)]
    }
}
