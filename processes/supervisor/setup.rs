//! What a run is set up with before its processes start: the stack file and scenario, the
//! fault plan, the live view, the prefix (claimed), the shared memory the supervisor owns, the
//! set-up directory the boards read, the recording and the fault injector; and, at the end,
//! the prefix given back.

use super::child::{Launch, Proc};
use super::watch::{Ports, Sinks, Supervisor};
use super::{Cleanup, default_wall_limit_s, end_stack};
use crate::chaos::{self, BadSampleSender, Injector, LinkCut};
use crate::ipc::{self, Svc};
use crate::observe::record::Recorder;
use crate::observe::view::LiveView;
use crate::stack::{LINK_PROCESS, RunOptions, StackFile, load_stack};
use afs_shared::faults::PlannedFault;
use afs_shared::scenario::Scenario;
use anyhow::{Context, Result};
use iceoryx2::node::Node;
use iceoryx2::service::port_factory::blackboard;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The set-up directory of the supervisor `pid` of stack `prefix`.
pub fn setup_dir(prefix: &str, pid: u32) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("afs-{prefix}-{pid}"))
}

/// Removes the set-up directories of the prefix's supervisors that are no longer alive
/// (killed before they could remove their own).
fn remove_dead_setups(prefix: &str) {
    let head = format!("afs-{prefix}-");
    let Ok(dir) = std::fs::read_dir(std::env::temp_dir()) else {
        return;
    };
    for e in dir.flatten() {
        let name = e.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(|n| n.strip_prefix(&head))
            .and_then(|p| p.parse::<i32>().ok())
        else {
            continue;
        };
        if pid as u32 != std::process::id() && !crate::procfs::alive(pid) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// A run, set up.
pub(super) struct Setup {
    /// The stack file, with the command line's overrides.
    pub(super) stack: StackFile,
    /// Its scenario.
    pub(super) scenario: Scenario,
    /// Simulated seconds.
    pub(super) duration: f64,
    plan: Option<Vec<PlannedFault>>,
    view: Option<LiveView>,
    // Shared memory the supervisor owns: the world blackboard and its node (until released).
    world: Option<blackboard::PortFactory<Svc, u64>>,
    node: Option<Node<Svc>>,
    dir: PathBuf,
}

impl Setup {
    /// Loads the stack, plans the faults, starts the live view (a port in use is refused
    /// before anything else is set up), claims the prefix (a dead stack's leftovers are
    /// removed) and creates the world blackboard.
    pub(super) fn prepare(opts: &RunOptions) -> Result<Self> {
        let stack = load_stack(opts)?;
        let scenario = Scenario::new(&stack.scenario, &stack.sim_config()?)?;
        let duration = if stack.duration_s > 0.0 {
            stack.duration_s.min(scenario.natural_duration_s)
        } else {
            scenario.natural_duration_s
        };
        let prefix = stack.prefix.clone();
        let plan = opts
            .chaos
            .as_ref()
            .map(|c| chaos::plan(c, &stack, &scenario, duration))
            .transpose()?;
        let view = match opts.foxglove {
            Some(v) => {
                let tick_hz = 1.0 / scenario.cfg.servo.dt();
                // The cores of the real-time boards.
                let avoid: Vec<usize> = stack
                    .process
                    .iter()
                    .filter(|p| p.priority > 0)
                    .filter_map(|p| p.cpu)
                    .collect();
                let lv = LiveView::start(v, Some(tick_hz), &format!("afs {prefix}"), &avoid)?;
                eprintln!(
                    "afs: live view at {} (open it in Foxglove with examples/foxglove-layout.json)",
                    lv.url()
                );
                Some(lv)
            }
            None => None,
        };
        let (cleaned, removed) = ipc::claim_prefix(&prefix)?;
        if cleaned > 0 || removed > 0 {
            eprintln!(
                "afs: removed the leftovers of a dead stack '{prefix}' ({cleaned} nodes, {removed} files)"
            );
        }
        // A killed supervisor's set-up directory is removed too.
        remove_dead_setups(&prefix);
        let node = ipc::node(&prefix, "supervisor")?;
        let world = ipc::create_world(&node).with_context(|| {
            format!(
                "another supervisor holds prefix '{prefix}'; stop it or choose another --prefix"
            )
        })?;
        Ok(Self {
            dir: setup_dir(&prefix, std::process::id()),
            stack,
            scenario,
            duration,
            plan,
            view,
            world: Some(world),
            node: Some(node),
        })
    }

    /// The supervisor of the run: its ports, the set-up the boards read, the recording, the
    /// injector with the plan (the restarts its faults cost are not held against a process's
    /// budget), the link's cut commands, the wall-time limit.
    pub(super) fn supervisor(&mut self, opts: &RunOptions) -> Result<Supervisor> {
        let stack = &self.stack;
        let node = self.node.as_ref().context("the run's node is released")?;
        let ports = Ports::open(node, self.scenario.insertion.is_some())?;
        std::fs::create_dir_all(&self.dir)
            .with_context(|| format!("creating {}", self.dir.display()))?;
        let sim_file = match &stack.sim {
            Some(t) => {
                let f = self.dir.join("sim.toml");
                std::fs::write(&f, toml::to_string(t).context("writing [sim]")?)
                    .with_context(|| format!("writing {}", f.display()))?;
                Some(f)
            }
            None => None,
        };
        let robot_file = match &stack.robot {
            Some(r) => {
                let f = self.dir.join("robot.toml");
                let mut t = toml::Table::new();
                t.insert(
                    "robot".into(),
                    toml::Value::try_from(r).context("writing [robot]")?,
                );
                std::fs::write(&f, toml::to_string(&t).context("writing [robot]")?)
                    .with_context(|| format!("writing {}", f.display()))?;
                Some(f)
            }
            None => None,
        };
        let launch = Launch {
            prefix: stack.prefix.clone(),
            scenario: stack.scenario.clone(),
            seed: stack.seed,
            sim_file,
            duration: self.duration,
            robot_file,
            cell_file: crate::stack::cell::write(stack, &self.scenario, &self.dir)?,
        };
        let mut procs = stack
            .process
            .iter()
            .map(Proc::new)
            .collect::<Result<Vec<_>>>()?;
        let recorder = opts.record.as_deref().map(Recorder::start).transpose()?;
        let injector = match self.plan.take() {
            Some(plan) => {
                let bad = BadSampleSender::new(ipc::wrench(node)?)?;
                let inj = Injector::new(plan, bad, Instant::now())
                    .with_cut(Duration::from_secs_f64(stack.cut_for_s()));
                for p in procs.iter_mut() {
                    if let Some(b) = p.board {
                        p.injected_budget = inj.planned_for(b);
                    } else if p.spec.name == LINK_PROCESS {
                        p.injected_budget = inj.planned_link_kills();
                    }
                }
                Some(inj)
            }
            None => None,
        };
        // A simulated robot's time runs at its simulation's pace (0.4–0.7 of the wall clock's
        // on this project's 2-core machine, docs/franka.md): its run's wall-time
        // limit is the one of four times its duration.
        let pace = if stack.has_cell() { 4.0 } else { 1.0 };
        let wall_limit = stack
            .wall_limit_s
            .unwrap_or_else(|| default_wall_limit_s(pace * self.duration));
        Ok(
            Supervisor::new(procs, launch, &self.scenario, self.duration, ports)
                .with_sinks(Sinks {
                    recorder,
                    view: self.view.take(),
                })
                .injecting(injector)
                .cutting_with(
                    stack
                        .link_cut()
                        .map(|(cut, restore)| LinkCut::new(cut, restore)),
                )
                .with_progress(opts.progress)
                .with_wall_limit(Duration::from_secs_f64(wall_limit)),
        )
    }

    /// Gives the prefix back once the run's processes (`procs`) have ended: the supervisor's
    /// own shared memory and set-up directory go first.
    /// What the servo knew of its contact, from the newest snapshot it left (None if it left
    /// none, or the blackboard is released).
    pub(super) fn contact_report(&self) -> Option<afs_shared::servo::ContactReport> {
        let world = self.world.as_ref()?;
        let snapshot = ipc::newest_world(world).ok().flatten()?;
        Some(afs_shared::servo::ContactReport::from_state(
            &snapshot.controller,
        ))
    }

    pub(super) fn release(&mut self, procs: &[Proc]) -> Result<Cleanup> {
        let prefix = self.stack.prefix.clone();
        drop(self.world.take());
        drop(self.node.take());
        let _ = std::fs::remove_dir_all(&self.dir);
        let own: Vec<i32> = procs
            .iter()
            .flat_map(|p| p.exits.iter().map(|e| e.pid).chain([p.pid()]))
            .chain([std::process::id() as i32])
            .filter(|pid| *pid != 0)
            .collect();
        let end = end_stack(&prefix, &own)?;
        Ok(Cleanup {
            left: end.left,
            observers: end.observers,
        })
    }
}
