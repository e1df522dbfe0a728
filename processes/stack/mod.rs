//! The stack: its file (`examples/stack.toml`), the process graph `afs run` launches with each
//! board's restart policy and the command line's overrides of it; and what the supervisor and
//! `afs chaos` both say of a running stack ([`Timeline`] of a restart, [`Footprint`]). It sits
//! below both: neither imports the other for it.

pub mod cell;
#[doc(hidden)]
pub mod fci;
mod footprint;
pub mod robot;
mod timeline;

pub use footprint::Footprint;
pub use robot::RobotTable;
pub use timeline::Timeline;

use crate::ipc;
use afs_shared::config::SimConfig;
use afs_shared::faults::FaultKind;
use afs_shared::msg::{self, Board};
use afs_shared::scenario;
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The built-in stack file.
pub const DEFAULT_STACK: &str = include_str!("../../examples/stack.toml");

/// When to restart a process that ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Restart {
    /// Whatever the exit.
    Always,
    /// Unless it exited with status 0.
    OnFailure,
    /// Never.
    Never,
}

fn default_restarts() -> u32 {
    5
}
fn default_backoff() -> u64 {
    50
}
fn default_restart() -> Restart {
    Restart::OnFailure
}

/// One process of the graph.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ProcessSpec {
    /// Name (servo, sensor and estimator have their roles; others are just supervised).
    pub name: String,
    /// Executable: a path, or a name looked up next to the `afs` executable.
    pub binary: String,
    /// Extra arguments.
    #[serde(default)]
    pub args: Vec<String>,
    /// CPU to pin to.
    #[serde(default)]
    pub cpu: Option<usize>,
    /// SCHED_FIFO priority (0: normal).
    #[serde(default)]
    pub priority: u8,
    /// Restart policy.
    #[serde(default = "default_restart")]
    pub restart: Restart,
    /// Most restarts before giving up.
    #[serde(default = "default_restarts")]
    pub max_restarts: u32,
    /// First restart delay (ms), doubling up to 2 s.
    #[serde(default = "default_backoff")]
    pub backoff_ms: u64,
    /// Alive but silent this long (ms) → killed and restarted (0: never).
    #[serde(default)]
    pub stall_ms: u64,
    /// How long it may take before its data first flows (ms; default 5 000 for the servo,
    /// 2 000 for the others): a board that waits on a device that comes up with the stack (a
    /// simulated robot and its sensor) needs longer.
    #[serde(default)]
    pub start_grace_ms: Option<u64>,
}

impl ProcessSpec {
    /// The board this process is (None: another supervised process).
    pub fn board(&self) -> Option<Board> {
        Board::from_name(&self.name)
    }
}

/// A stack file.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StackFile {
    /// Stack prefix.
    pub prefix: String,
    /// Scenario.
    pub scenario: String,
    /// Simulated seconds (0: the scenario's own length).
    pub duration_s: f64,
    /// Noise seed.
    pub seed: u64,
    /// Wall time the run may take before the supervisor stops it, and fails it (s; default:
    /// 1.5 × the duration + 30 s).
    #[serde(default)]
    pub wall_limit_s: Option<f64>,
    /// SimConfig overrides.
    #[serde(default)]
    pub sim: Option<toml::Table>,
    /// The processes.
    pub process: Vec<ProcessSpec>,
    /// What `afs chaos` needs beyond the processes.
    #[serde(default)]
    pub chaos: Option<ChaosTable>,
    /// A robot for the servo to drive (issue 48, docs/franka.md).
    #[serde(default)]
    pub robot: Option<RobotTable>,
}

/// The `[chaos]` table: how to cut the link and restore it (the `cut-link` fault; on real
/// hosts, a command that downs an interface or adds a firewall rule, and its inverse).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ChaosTable {
    /// The command that cuts the link (program and arguments, run as they are).
    #[serde(default)]
    pub cut_link: Vec<String>,
    /// The command that restores it.
    #[serde(default)]
    pub restore_link: Vec<String>,
    /// How long a cut lasts (s).
    #[serde(default = "default_cut_for")]
    pub cut_for_s: f64,
}

fn default_cut_for() -> f64 {
    DEFAULT_CUT_FOR_S
}

/// How long a cut of the link lasts without a `[chaos]` table saying (s).
const DEFAULT_CUT_FOR_S: f64 = 5.0;

/// The name of the link board's process (docs/link.md), which the link's faults address.
pub const LINK_PROCESS: &str = "link";

impl StackFile {
    /// Parses and checks a stack file's text (`origin` names it in errors).
    pub fn parse(text: &str, origin: &str) -> Result<Self> {
        let s: StackFile =
            toml::from_str(text).with_context(|| format!("parsing stack file {origin}"))?;
        s.check().with_context(|| format!("stack file {origin}"))?;
        Ok(s)
    }

    /// Checks the stack file (after overrides).
    pub fn check(&self) -> Result<()> {
        ipc::check_prefix(&self.prefix)?;
        scenario::ScenarioKind::from_name(&self.scenario)?;
        if !(self.duration_s.is_finite() && (0.0..=86_400.0).contains(&self.duration_s)) {
            bail!(
                "duration_s = {} must be a number of seconds in [0, 86400] (0: the scenario's own length)",
                self.duration_s
            );
        }
        if let Some(w) = self.wall_limit_s
            && !(w.is_finite() && (0.1..=1e6).contains(&w))
        {
            bail!("wall_limit_s = {w} must be a number of seconds in [0.1, 1000000]");
        }
        if self.process.is_empty() || self.process.len() > msg::MAX_PROCESSES {
            bail!(
                "needs 1 to {} [[process]] tables, found {}",
                msg::MAX_PROCESSES,
                self.process.len()
            );
        }
        for (i, p) in self.process.iter().enumerate() {
            if p.name.is_empty() || p.name.len() > 15 {
                bail!("process {i}: name must be 1 to 15 characters");
            }
            if self.process[..i].iter().any(|q| q.name == p.name) {
                bail!("process '{}' is listed twice", p.name);
            }
            if p.priority > 99 {
                bail!(
                    "process '{}': priority {} must be 0 to 99",
                    p.name,
                    p.priority
                );
            }
        }
        if let Some(c) = &self.chaos {
            if c.cut_link.is_empty() != c.restore_link.is_empty() {
                bail!(
                    "[chaos]: cut_link and restore_link go together (a cut must be restored); give both or neither"
                );
            }
            if !(c.cut_for_s.is_finite() && (0.1..=600.0).contains(&c.cut_for_s)) {
                bail!(
                    "[chaos]: cut_for_s = {} must be a number of seconds in [0.1, 600]",
                    c.cut_for_s
                );
            }
        }
        if let Some(r) = &self.robot {
            r.check()?;
            r.check_reach()?;
        }
        for role in [Board::Servo, Board::Sensor] {
            if self.spec(role).is_none() {
                bail!("the graph needs a process named '{}'", role.name());
            }
        }
        Ok(())
    }

    /// The link board's process, if the graph has one.
    pub fn link(&self) -> Option<&ProcessSpec> {
        self.process.iter().find(|p| p.name == LINK_PROCESS)
    }

    /// The commands that cut and restore the link, if the stack file gives them.
    pub fn link_cut(&self) -> Option<(&[String], &[String])> {
        self.chaos
            .as_ref()
            .filter(|c| !c.cut_link.is_empty())
            .map(|c| (c.cut_link.as_slice(), c.restore_link.as_slice()))
    }

    /// How long a cut of the link lasts (s).
    pub fn cut_for_s(&self) -> f64 {
        self.chaos
            .as_ref()
            .map_or(DEFAULT_CUT_FOR_S, |c| c.cut_for_s)
    }

    /// The process of a board, if the graph has it.
    pub fn spec(&self, board: Board) -> Option<&ProcessSpec> {
        self.process.iter().find(|p| p.board() == Some(board))
    }

    /// The simulated set-up: defaults with the `[sim]` overrides.
    pub fn sim_config(&self) -> Result<SimConfig> {
        let mut cfg: SimConfig = match &self.sim {
            Some(t) => t
                .clone()
                .try_into()
                .context("the [sim] table (see `afs experiment --config`)")?,
            None => SimConfig::default(),
        };
        cfg.seed = self.seed;
        cfg.validate().context("the [sim] table")?;
        Ok(cfg)
    }
}

/// What `afs run` was asked.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Stack file (None: the built-in one).
    pub config: Option<PathBuf>,
    /// Overrides.
    pub scenario: Option<String>,
    /// Override (s).
    pub duration: Option<f64>,
    /// Override.
    pub prefix: Option<String>,
    /// Override.
    pub seed: Option<u64>,
    /// Overrides of the set-up's `[sim]` table.
    pub sim: SimOverrides,
    /// Override of the wall-time limit (s).
    pub wall_limit_s: Option<f64>,
    /// Record every topic to this MCAP file.
    pub record: Option<PathBuf>,
    /// Print a progress line every second on stderr.
    pub progress: bool,
    /// Inject faults (`afs chaos`).
    pub chaos: Option<ChaosOptions>,
    /// Serve a live view to Foxglove.
    pub foxglove: Option<crate::observe::view::ViewSettings>,
}

/// The command line's settings of the set-up, the same flags as `afs experiment`'s: each
/// overrides its key of the stack file's `[sim]` table.
#[derive(Debug, Clone, Default)]
pub struct SimOverrides {
    /// `[sim.servo] rate_hz`.
    pub rate_hz: Option<f64>,
    /// `[sim.world] kind`.
    pub plant: Option<String>,
    /// `[sim.world] mjcf` (and `kind = "mujoco"`).
    pub mjcf: Option<PathBuf>,
}

impl SimOverrides {
    /// Writes the overrides into the `[sim]` table `sim` (made if there is none).
    #[doc(hidden)]
    pub fn apply(&self, sim: &mut Option<toml::Table>) -> Result<()> {
        let mut set = |table: &str, key: &str, value: toml::Value| {
            let t = sim
                .get_or_insert_with(toml::Table::new)
                .entry(table)
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            match t {
                toml::Value::Table(t) => {
                    t.insert(key.into(), value);
                    Ok(())
                }
                _ => Err(anyhow::anyhow!(
                    "the stack file's [sim] has `{table}` that is not a table"
                )),
            }
        };
        if let Some(hz) = self.rate_hz {
            if !(hz.is_finite() && hz > 0.0) {
                bail!("--rate-hz {hz} must be a rate in Hz > 0 (10000, 1000 or 500)");
            }
            set("servo", "rate_hz", hz.into())?;
        }
        if let Some(kind) = &self.plant {
            set("world", "kind", kind.clone().into())?;
        }
        if let Some(path) = &self.mjcf {
            // The boards run from another directory: the model's path made absolute.
            let abs = std::fs::canonicalize(path)
                .with_context(|| format!("--mjcf {}: no such model", path.display()))?;
            set("world", "kind", "mujoco".into())?;
            set("world", "mjcf", abs.display().to_string().into())?;
        }
        Ok(())
    }
}

/// The set-up of a stack file, for the commands that run no stack (`afs experiment
/// --config`): its `[sim]` table on the defaults; the rest of the file (processes, prefix,
/// scenario) is the stack's and is not read. One file serves both.
pub fn setup_of(path: &Path) -> Result<SimConfig> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading config {}", path.display()))?;
    let doc: toml::Table =
        toml::from_str(&text).with_context(|| format!("parsing config {}", path.display()))?;
    let bare: Vec<&str> = doc
        .keys()
        .map(String::as_str)
        .filter(|k| SETUP_KEYS.contains(k))
        .collect();
    if !bare.is_empty() {
        bail!(
            "config {}: `{}` belongs under [sim], as in a stack file (e.g. [sim.{}] instead of \
             [{}]; examples/stack.toml)",
            path.display(),
            bare.join("`, `"),
            bare[0],
            bare[0]
        );
    }
    let sim = match doc.get("sim") {
        Some(toml::Value::Table(t)) => t.clone(),
        Some(_) => bail!("config {}: `sim` must be a table ([sim])", path.display()),
        None => toml::Table::new(),
    };
    let cfg: SimConfig = toml::Value::Table(sim)
        .try_into()
        .with_context(|| format!("config {}: [sim]", path.display()))?;
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("config {}: {e}", path.display()))?;
    Ok(cfg)
}

/// The tables and keys of a set-up ([`SimConfig`]'s fields), which a stack file has under
/// `[sim]`.
const SETUP_KEYS: [&str; 8] = [
    "plant",
    "surface",
    "sensor",
    "servo",
    "start_u_m",
    "tangent_error_rad",
    "world",
    "insertion",
];

/// What `afs chaos` injects.
#[derive(Debug, Clone)]
pub struct ChaosOptions {
    /// Number of faults.
    pub faults: usize,
    /// Seed of the plan.
    pub seed: u64,
    /// Kinds to draw from (empty: every kind the scenario allows).
    pub kinds: Vec<FaultKind>,
    /// Take the kinds in turn instead of at random.
    pub in_turn: bool,
}

/// Loads the stack file with the overrides applied.
pub fn load_stack(opts: &RunOptions) -> Result<StackFile> {
    let mut s = match &opts.config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading stack file {}", p.display()))?;
            StackFile::parse(&text, &p.display().to_string())?
        }
        None => StackFile::parse(DEFAULT_STACK, "(built-in)")?,
    };
    if let Some(x) = &opts.scenario {
        s.scenario = x.clone();
    }
    if let Some(x) = opts.duration {
        s.duration_s = x;
    }
    if let Some(x) = &opts.prefix {
        s.prefix = x.clone();
    }
    if let Some(x) = opts.seed {
        s.seed = x;
    }
    if let Some(x) = opts.wall_limit_s {
        s.wall_limit_s = Some(x);
    }
    opts.sim.apply(&mut s.sim)?;
    s.check()?;
    // A robot the graph starts itself (the simulated cell) cannot answer yet.
    if let Some(r) = s.robot.as_ref().filter(|_| !s.has_cell()) {
        fci::preflight(r)?;
    }
    Ok(s)
}

/// The executable of `name`: a path, or a name looked up next to the `afs` executable.
pub fn resolve_binary(name: &str) -> Result<PathBuf> {
    let p = Path::new(name);
    if p.components().count() > 1 {
        if p.is_file() {
            return Ok(p.to_path_buf());
        }
        bail!("binary {} does not exist", p.display());
    }
    let exe = std::env::current_exe().context("locating the afs executable")?;
    let dir = exe.parent().unwrap_or(Path::new("."));
    let cand = dir.join(name);
    if cand.is_file() {
        return Ok(cand);
    }
    bail!(
        "binary '{name}' not found next to {} (build it with `cargo build --release`)",
        exe.display()
    )
}
