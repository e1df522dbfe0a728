//! What a running stack holds at one moment: its iceoryx2 files (and those of dead processes,
//! each named with who left it) and the resident memory of the supervisor and the boards.
//! The supervisor measures it (`supervisor::footprint`); `afs chaos` reports it before the
//! first fault and after the last.

use crate::procfs::Rss;
use serde::{Deserialize, Serialize};

/// Shared memory and resident memory of a running stack, at one moment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Footprint {
    /// Wall time since the stack started (s).
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub at_s: f64,
    /// iceoryx2 files of the prefix in /dev/shm and the iceoryx2 root.
    pub shm_files: usize,
    /// Their total size (bytes).
    pub shm_bytes: u64,
    /// Those of dead processes ([`ipc::stale_files`]): leaks.
    pub stale_files: Vec<String>,
    /// Resident memory of the supervisor (KiB): its heap and stacks (RssAnon), and all of it
    /// (VmRSS, which also counts the pages of shared memory it has read so far).
    pub supervisor_rss_kib: Rss,
    /// Resident memory of the boards (KiB), servo, sensor and estimator summed.
    pub boards_rss_kib: Rss,
}
