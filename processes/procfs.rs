//! The `/proc` readings the processes need (the `procfs` crate): resident memory of a process,
//! CPU time of this one, the kernel's release.

use procfs::process::Process;
use serde::{Deserialize, Serialize};

/// Resident memory of a process (KiB).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Rss {
    /// Private: heap and stacks (RssAnon).
    pub anon: u64,
    /// All of it (VmRSS), with the pages of shared memory read so far.
    pub total: u64,
}

impl std::ops::Add for Rss {
    type Output = Rss;
    fn add(self, o: Rss) -> Rss {
        Rss {
            anon: self.anon + o.anon,
            total: self.total + o.total,
        }
    }
}

/// Resident memory of process `pid` (zero if it cannot be read).
pub fn rss(pid: i32) -> Rss {
    Process::new(pid)
        .and_then(|p| p.status())
        .map(|s| Rss {
            anon: s.rssanon.unwrap_or(0),
            total: s.vmrss.unwrap_or(0),
        })
        .unwrap_or_default()
}

/// CPU time of this process so far, user and system (s; 0 if it cannot be read).
pub fn cpu_seconds() -> f64 {
    Process::myself()
        .and_then(|p| p.stat())
        .map(|s| (s.utime + s.stime) as f64 / procfs::ticks_per_second() as f64)
        .unwrap_or(0.0)
}

/// The kernel's release (`uname -r`), if it can be read.
pub fn kernel_release() -> Option<String> {
    std::fs::read_to_string("/proc/sys/kernel/osrelease")
        .ok()
        .map(|s| s.trim().to_string())
}

/// True while process `pid` exists and is not a zombie.
pub fn alive(pid: i32) -> bool {
    Process::new(pid)
        .and_then(|p| p.stat())
        .is_ok_and(|s| s.state != 'Z')
}
