//! A stack's prefix as a whole: who is on it ([`census`]), taking it for a new stack
//! ([`claim_prefix`]), what a dead process left ([`stale_files`]), and giving it back at the end
//! of a run ([`end_stack`], [`release_prefix`]): the stack's own files must be gone, while a
//! client still attached (an observer) keeps its own.

use super::{Svc, config, file_prefix};
use anyhow::{Context, Result, bail};
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What `Node::list` says about a stack's nodes.
#[derive(Debug, Default, Clone)]
pub struct NodeCensus {
    /// Alive nodes: (name, pid).
    pub alive: Vec<(String, i32)>,
    /// Dead nodes whose resources were removed.
    pub cleaned: usize,
    /// Dead nodes that could not be cleaned.
    pub failed: usize,
}

/// Takes `prefix` for a new stack (or benchmark): refuses it while any of its nodes is alive,
/// and otherwise removes what dead ones left ([`release_prefix`]), then, as a last resort, any
/// file of the prefix iceoryx2 could not remove (no live node can be using it). Returns (dead
/// nodes cleaned, files removed by name).
pub fn claim_prefix(prefix: &str) -> Result<(usize, usize)> {
    let census = census(prefix, true)?;
    if !census.alive.is_empty() {
        bail!(
            "a stack with prefix '{prefix}' is already running ({}); stop it or choose another --prefix",
            census
                .alive
                .iter()
                .map(|(n, p)| format!("{n} pid {p}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok((census.cleaned, clear_prefix(prefix)?.len()))
}

/// [`release_prefix`], then removes by name what is still left (a dead stack's files iceoryx2
/// could not remove; with no node of the prefix alive nothing uses them). Returns what was
/// removed by name.
pub fn clear_prefix(prefix: &str) -> Result<Vec<PathBuf>> {
    let left = release_prefix(prefix)?;
    Ok(left
        .into_iter()
        .filter(|f| {
            if f.is_dir() {
                std::fs::remove_dir_all(f).is_ok()
            } else {
                std::fs::remove_file(f).is_ok()
            }
        })
        .collect())
}

/// Lists the nodes of stack `prefix`; with `clean`, removes the resources of dead ones.
pub fn census(prefix: &str, clean: bool) -> Result<NodeCensus> {
    let cfg = config(prefix)?;
    let mut out = NodeCensus::default();
    let mut dead = Vec::new();
    Node::<Svc>::list(&cfg, |state| {
        match state {
            NodeState::Alive(v) => {
                let (n, pid) = v.details().as_ref().map_or((String::from("?"), 0), |d| {
                    (d.name().to_string(), d.process_id().value())
                });
                out.alive.push((n, pid));
            }
            NodeState::Dead(v) => dead.push(v),
            _ => {}
        }
        CallbackProgression::Continue
    })
    .with_context(|| format!("listing iceoryx2 nodes of stack '{prefix}'"))?;
    if clean {
        for v in dead {
            match v.try_remove_stale_resources() {
                Ok(()) => out.cleaned += 1,
                Err(_) => out.failed += 1,
            }
        }
    }
    Ok(out)
}

/// Files of a running stack `prefix` that belong to no live process: the directories and
/// monitors of dead nodes, and the data segments and connections of ports no live node owns.
/// After a board dies and the supervisor has cleaned up, there are none; any left is a leak.
/// A file must look stale in two scans 50 ms apart (a port being created is not a leak).
pub fn stale_files(prefix: &str) -> Result<Vec<PathBuf>> {
    twice(prefix, Connections::AnyPortDead)
}

/// Files of stack `prefix` that no live process uses: as [`stale_files`], but a connection
/// between a dead port and a live one is the live one's (a subscriber still reading what a
/// dead publisher sent). What a stack leaves while an observer is still attached.
pub fn unowned_files(prefix: &str) -> Result<Vec<PathBuf>> {
    twice(prefix, Connections::BothPortsDead)
}

/// When a connection file is stale.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Connections {
    /// One of its two ports is dead.
    AnyPortDead,
    /// Both are.
    BothPortsDead,
}

/// The files two scans 50 ms apart both find stale (a port being created is not a leak).
fn twice(prefix: &str, connections: Connections) -> Result<Vec<PathBuf>> {
    let first = stale_scan(prefix, connections)?;
    std::thread::sleep(std::time::Duration::from_millis(50));
    let second = stale_scan(prefix, connections)?;
    Ok(first.into_iter().filter(|f| second.contains(f)).collect())
}

fn stale_scan(prefix: &str, connections: Connections) -> Result<Vec<PathBuf>> {
    let files = leftovers(prefix);
    let cfg = config(prefix)?;
    let mut alive = Vec::new();
    Node::<Svc>::list(&cfg, |state| {
        if let NodeState::Alive(v) = &state
            && let Ok(id) = u128::from_str_radix(&v.id().to_string(), 16)
        {
            alive.push(id.to_string());
        }
        CallbackProgression::Continue
    })
    .with_context(|| format!("listing iceoryx2 nodes of stack '{prefix}'"))?;
    let fp = file_prefix(prefix);
    let stem = |f: &Path| -> Option<(String, String)> {
        let name = f.file_name()?.to_str()?;
        let rest = name.strip_prefix(&fp)?;
        let (stem, ext) = rest.rsplit_once('.')?;
        Some((stem.to_string(), ext.to_string()))
    };
    // Node directories are named by node id; port tags inside them by port id.
    let node_of = |f: &Path| -> Option<String> {
        let parent = f.parent()?;
        (parent.parent()?.file_name()? == "nodes")
            .then(|| parent.file_name()?.to_str().map(String::from))?
    };
    let mut live_ports = std::collections::HashSet::new();
    for f in &files {
        if let (Some(node), Some((port, ext))) = (node_of(f), stem(f))
            && ext == "port_tag"
            && alive.contains(&node)
        {
            live_ports.insert(port);
        }
    }
    let mut stale = Vec::new();
    for f in &files {
        let Some((stem, ext)) = stem(f) else {
            continue;
        };
        let dead = if let Some(node) = node_of(f) {
            !alive.contains(&node)
        } else {
            match ext.as_str() {
                "node_monitor" | "node_monitor_context" | "node_monitor_owner_lock" => {
                    !alive.contains(&stem)
                }
                // <service>_<port>.data (or a resizable segment's <service>_<port>__<n>.data
                // and __mgmt.data); <service>_<sender port>_<receiver port>.connection
                "data" => segment_owner(&stem)
                    .rsplit('_')
                    .next()
                    .is_some_and(|p| !live_ports.contains(p)),
                "connection" => {
                    let mut ports = stem.rsplit('_').take(2);
                    let dead = |p: &str| !live_ports.contains(p);
                    match connections {
                        Connections::AnyPortDead => ports.any(dead),
                        Connections::BothPortsDead => ports.all(dead),
                    }
                }
                _ => false,
            }
        };
        if dead {
            stale.push(f.clone());
        }
    }
    Ok(stale)
}

/// The processes whose ports a data segment or connection file of stack `prefix` belongs to,
/// read from its name (`…_<port>.data`, `…_<sender port>_<receiver port>.connection`): an
/// iceoryx2 port id is a `UniqueSystemId`, whose bits 64–95 are the pid of the process that
/// created it.
pub fn file_pids(path: &Path, prefix: &str) -> Vec<u32> {
    let fp = file_prefix(prefix);
    let Some((stem, ext)) = path
        .file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.strip_prefix(&fp))
        .and_then(|n| n.rsplit_once('.'))
    else {
        return Vec::new();
    };
    let ports = match ext {
        "data" => 1,
        "connection" => 2,
        _ => return Vec::new(),
    };
    let mut pids: Vec<u32> = segment_owner(stem)
        .rsplit('_')
        .take(ports)
        .filter_map(|p| p.parse::<u128>().ok())
        .map(|id| (id >> 64) as u32)
        .collect();
    pids.reverse();
    pids
}

/// A data segment's name without the suffix of a resizable segment (iceoryx2 names those
/// `<service>_<port>__<n>` and `<service>_<port>__mgmt`: publishers of slices that grow, the
/// link's tunnel among them), so that it ends in its port's id as the others do.
#[doc(hidden)]
pub fn segment_owner(stem: &str) -> &str {
    stem.split_once("__").map_or(stem, |(owner, _)| owner)
}

/// Files of stack `prefix` left in /dev/shm and under the iceoryx2 root.
pub fn leftovers(prefix: &str) -> Vec<PathBuf> {
    let p = file_prefix(prefix);
    let mut out = Vec::new();
    let root = PathBuf::from(super::root_path());
    scan(Path::new("/dev/shm"), &p, &mut out, 0);
    scan(&root, &p, &mut out, 0);
    out
}

fn scan(dir: &Path, prefix: &str, out: &mut Vec<PathBuf>, depth: usize) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for e in rd.flatten() {
        let path = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with(prefix) {
            out.push(path.clone());
        }
        if depth < 4 && e.file_type().is_ok_and(|t| t.is_dir()) {
            scan(&path, prefix, out, depth + 1);
        }
    }
}

/// Releases stack `prefix` once its nodes are gone: iceoryx2's dead-node clean-up removes
/// what dead nodes held (their nodes, ports, connections, and services no node uses any more),
/// and the one file iceoryx2 keeps by design, the domain's node counter
/// ([`is_node_counter`]), is removed by name: it holds no state a later process needs (node
/// ids are unique by pid and creation time, docs/reliability.md). Refuses while a node of the
/// stack is alive. Returns the files of the prefix still left: a leak, for the caller to
/// report.
pub fn release_prefix(prefix: &str) -> Result<Vec<PathBuf>> {
    let c = census(prefix, true).context("cleaning dead nodes")?;
    if !c.alive.is_empty() {
        bail!(
            "stack '{prefix}' still has live nodes ({}); not releasing it",
            c.alive
                .iter()
                .map(|(n, p)| format!("{n} pid {p}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    for f in leftovers(prefix).iter().filter(|f| is_node_counter(f)) {
        let _ = std::fs::remove_file(f);
    }
    Ok(leftovers(prefix))
}

/// True for the domain's node-counter segment (`…node….global_mgmt` in /dev/shm): created by
/// the first node of a prefix and kept by iceoryx2 when the last one goes.
pub fn is_node_counter(f: &Path) -> bool {
    let suffix = iceoryx2::config::Node::default().global_mgmt_suffix;
    f.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.ends_with(&suffix.to_string()))
}

/// A live node on a stack's prefix that is none of the stack's processes: a client watching
/// it (`afs view`, `afs record`, a Python client), still attached when the run ends.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Observer {
    /// Its node's name.
    pub name: String,
    /// Its process.
    pub pid: i32,
    /// The services it has ports on.
    pub services: Vec<String>,
}

/// How a stack's prefix was given back at the end of a run.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StackEnd {
    /// Clients still attached: their nodes and files are theirs, left alone.
    pub observers: Vec<Observer>,
    /// What the stack leaked: files no live node owns (the stack's own, or a dead process's),
    /// and the nodes of the stack's own processes still alive.
    pub left: Vec<String>,
}

/// Ends stack `prefix`, whose own processes were `own` (pids; all of them stopped by now):
/// dead nodes are cleaned up; with no node left the prefix is released ([`release_prefix`]);
/// a live node of another process is an observer, reported with its services, and then only
/// the files no live node owns count as left ([`stale_files`]).
pub fn end_stack(prefix: &str, own: &[i32]) -> Result<StackEnd> {
    let c = census(prefix, true).context("cleaning dead nodes")?;
    if c.alive.is_empty() {
        let left = release_prefix(prefix)?;
        return Ok(StackEnd {
            observers: Vec::new(),
            left: left.iter().map(|f| f.display().to_string()).collect(),
        });
    }
    let mut end = StackEnd::default();
    for (name, pid) in &c.alive {
        if own.contains(pid) {
            end.left.push(format!(
                "node {name} of the stack's process {pid}, still alive"
            ));
        } else {
            end.observers.push(Observer {
                name: name.clone(),
                pid: *pid,
                services: services_of(prefix, *pid)?,
            });
        }
    }
    end.left.extend(
        unowned_files(prefix)?
            .iter()
            .map(|f| f.display().to_string()),
    );
    Ok(end)
}

/// Every service of stack `prefix` with the names of the live nodes registered on it (what
/// `tests/stack` holds the picture of `afs graph` against).
pub fn service_nodes(
    prefix: &str,
) -> Result<std::collections::BTreeMap<String, std::collections::BTreeSet<String>>> {
    let cfg = config(prefix)?;
    let mut out = std::collections::BTreeMap::new();
    Svc::list(&cfg, |s| {
        let nodes = s
            .dynamic_details
            .as_ref()
            .map(|d| {
                d.nodes
                    .iter()
                    .filter_map(|n| match n {
                        NodeState::Alive(v) => v.details().as_ref().map(|x| x.name().to_string()),
                        _ => None,
                    })
                    .collect()
            })
            .unwrap_or_default();
        out.insert(s.static_details.name().to_string(), nodes);
        CallbackProgression::Continue
    })
    .with_context(|| format!("listing the services of stack '{prefix}'"))?;
    Ok(out)
}

/// The services of stack `prefix` on which a node of process `pid` is registered.
fn services_of(prefix: &str, pid: i32) -> Result<Vec<String>> {
    let cfg = config(prefix)?;
    let mut out = Vec::new();
    Svc::list(&cfg, |s| {
        let of_pid = s.dynamic_details.as_ref().is_some_and(|d| {
            d.nodes.iter().any(|n| match n {
                NodeState::Alive(v) => v
                    .details()
                    .as_ref()
                    .is_some_and(|x| x.process_id().value() == pid),
                _ => false,
            })
        });
        if of_pid {
            out.push(s.static_details.name().to_string());
        }
        CallbackProgression::Continue
    })
    .with_context(|| format!("listing the services of stack '{prefix}'"))?;
    out.sort();
    Ok(out)
}
