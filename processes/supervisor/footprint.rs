//! Measuring a running stack's [`Footprint`]: its iceoryx2 files (those of dead processes named
//! with who left them) and the resident memory of the supervisor and the boards.

use super::child::Proc;
use crate::ipc;
use crate::procfs::{self, Rss};
use crate::stack::Footprint;
use afs_shared::msg::ProcessState;
use std::path::Path;
use std::time::Instant;

/// The stack `prefix` now (`t0`: when it started).
pub fn now(prefix: &str, procs: &[Proc], t0: Instant) -> Footprint {
    let files = ipc::leftovers(prefix);
    let boards_rss_kib = procs
        .iter()
        .filter(|p| p.state == ProcessState::Running)
        .map(|p| procfs::rss(p.pid()))
        .fold(Rss::default(), |a, b| a + b);
    let stale = ipc::stale_files(prefix).unwrap_or_default();
    Footprint {
        at_s: t0.elapsed().as_secs_f64(),
        shm_files: files.len(),
        stale_files: stale
            .iter()
            .map(|f| describe_file(f, prefix, procs))
            .collect(),
        shm_bytes: files
            .iter()
            .filter_map(|f| std::fs::metadata(f).ok())
            .filter(|m| m.is_file())
            .map(|m| m.len())
            .sum(),
        supervisor_rss_kib: procfs::rss(std::process::id() as i32),
        boards_rss_kib,
    }
}

/// `f` with the processes its ports belong to, by board and pid (e.g. `… (supervisor 812 →
/// servo 815, dead)`), so that a leak names who left it and who should have cleaned it.
fn describe_file(f: &Path, prefix: &str, procs: &[Proc]) -> String {
    let me = std::process::id();
    let who = |pid: u32| -> String {
        if pid == me {
            return format!("supervisor {pid}");
        }
        for p in procs {
            if p.pid() as u32 == pid {
                return format!("{} {pid}", p.spec.name);
            }
            if p.exits.iter().any(|e| e.pid as u32 == pid) {
                return format!("{} {pid}, dead", p.spec.name);
            }
        }
        format!("pid {pid}")
    };
    let pids: Vec<String> = ipc::file_pids(f, prefix).into_iter().map(who).collect();
    if pids.is_empty() {
        f.display().to_string()
    } else {
        format!("{} ({})", f.display(), pids.join(" → "))
    }
}
