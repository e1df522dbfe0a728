//! `afs status`: a running stack's processes and loop statistics, read from its status,
//! statistics and friction streams (history 1; subscribing does not disturb the loop).

use super::report::{FrictionIdReport, LoopReport};
use crate::ipc;
use afs_shared::msg::{self, ProcessState};
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::time::{Duration, Instant};

/// A live iceoryx2 node of the stack.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct NodeEntry {
    /// Node name (the board's).
    pub name: String,
    /// Its process.
    pub pid: i32,
}

/// The supervisor, as its status stream says.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SupervisorEntry {
    /// Its pid.
    pub pid: i32,
    /// Scenario.
    pub scenario: String,
    /// Simulated seconds so far.
    pub elapsed_s: f64,
    /// Planned simulated seconds.
    pub duration_s: f64,
}

/// A process of the graph, as the supervisor's status stream says.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProcessEntry {
    /// Name.
    pub name: String,
    /// Pid (0: not running).
    pub pid: i32,
    /// State (None: a code this version does not know).
    pub state: Option<ProcessState>,
    /// Restarts so far.
    pub restarts: u32,
    /// Last exit status (−signal), if any.
    pub last_exit: Option<i32>,
}

/// What `afs status` shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StatusReport {
    /// Stack prefix.
    pub prefix: String,
    /// Live nodes.
    pub nodes: Vec<NodeEntry>,
    /// The supervisor (None: no status heard within the wait).
    pub supervisor: Option<SupervisorEntry>,
    /// The processes.
    pub processes: Option<Vec<ProcessEntry>>,
    /// The servo loop's statistics.
    #[serde(rename = "loop")]
    pub loop_stats: Option<LoopReport>,
    /// The estimator's friction identification.
    pub friction: Option<FrictionIdReport>,
}

/// Reads a running stack's status, waiting up to `wait` for its streams.
pub fn status(prefix: &str, wait: Duration) -> Result<StatusReport> {
    ipc::check_prefix(prefix)?;
    let census = ipc::census(prefix, false)?;
    if census.alive.is_empty() {
        bail!("no stack with prefix '{prefix}' is running");
    }
    let node = ipc::node(prefix, "status")?;
    let sup = ipc::supervisor(&node)?
        .subscriber_builder()
        .create()
        .context("creating the status subscriber")?;
    let stats = ipc::loop_stats(&node)?
        .subscriber_builder()
        .create()
        .context("creating the loop-statistics subscriber")?;
    let friction = ipc::friction(&node)?
        .subscriber_builder()
        .create()
        .context("creating the friction subscriber")?;
    let t0 = Instant::now();
    let (mut s, mut l, mut f) = (None, None, None);
    while t0.elapsed() < wait && (s.is_none() || l.is_none()) {
        while let Ok(Some(x)) = sup.receive() {
            s = Some(*x.payload());
        }
        while let Ok(Some(x)) = stats.receive() {
            l = Some(*x.payload());
        }
        while let Ok(Some(x)) = friction.receive() {
            f = Some(*x.payload());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let processes = s.map(|st: msg::SupervisorStatus| {
        st.processes[..(st.process_count as usize).min(msg::MAX_PROCESSES)]
            .iter()
            .map(|p| ProcessEntry {
                name: msg::str_of(&p.name),
                pid: p.pid,
                state: ProcessState::try_from(p.state).ok(),
                restarts: p.restarts,
                last_exit: (p.last_exit != i32::MIN).then_some(p.last_exit),
            })
            .collect()
    });
    Ok(StatusReport {
        prefix: prefix.into(),
        nodes: census
            .alive
            .into_iter()
            .map(|(name, pid)| NodeEntry { name, pid })
            .collect(),
        supervisor: s.map(|st| SupervisorEntry {
            pid: st.pid,
            scenario: msg::str_of(&st.scenario),
            elapsed_s: st.elapsed_s,
            duration_s: st.duration_s,
        }),
        processes,
        loop_stats: l.as_ref().map(LoopReport::from),
        friction: f.as_ref().map(FrictionIdReport::from),
    })
}

impl fmt::Display for StatusReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "stack '{}'", self.prefix)?;
        if let Some(s) = &self.supervisor {
            writeln!(
                f,
                "  supervisor pid {}: {} at {:.1}/{:.1} s",
                s.pid, s.scenario, s.elapsed_s, s.duration_s
            )?;
        }
        for p in self.processes.iter().flatten() {
            let state = p
                .state
                .map_or("?".to_string(), |s| format!("{s:?}").to_lowercase());
            writeln!(
                f,
                "  {:<10} pid {:<7} {:<10} restarts {}",
                p.name, p.pid, state, p.restarts
            )?;
        }
        if let Some(l) = &self.loop_stats {
            writeln!(
                f,
                "  servo loop: {} ticks, {} misses, wake jitter p99 {:.1} µs, force age p99 {:.0} µs, safe entries {}",
                l.ticks, l.misses, l.wake_jitter_us.p99, l.force_age_us.p99, l.safe_entries
            )?;
        }
        Ok(())
    }
}
