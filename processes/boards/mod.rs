//! The board processes' loops ([`servo`], [`sensor`], [`estimator`]), and what they share:
//! their common command-line options, loading the set-up, the stop flag set by
//! SIGINT/SIGTERM/SIGHUP, and the start-up report.

pub mod estimator;
pub mod netft;
pub mod sensor;
pub mod servo;

use crate::ipc::{self, Svc};
use crate::rt;
use afs_shared::config::SimConfig;
use afs_shared::msg::{self, Board, BoardStartup};
use afs_shared::scenario::Scenario;
use anyhow::{Context, Result};
use iceoryx2::node::Node;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::update_connections::UpdateConnections;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Reads a TOML set-up (any subset of `SimConfig`'s fields; the rest keep their defaults) and
/// checks it.
pub fn load_config(path: &Path) -> Result<SimConfig> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading config {}", path.display()))?;
    let cfg: SimConfig =
        toml::from_str(&text).with_context(|| format!("parsing config {}", path.display()))?;
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("config {}: {e}", path.display()))?;
    Ok(cfg)
}

/// Options every board takes.
#[derive(Debug, Clone, clap::Args)]
pub struct Common {
    /// Stack prefix: isolates this stack's shared memory (iceoryx2 files named `afs_<prefix>_*`).
    #[arg(long, default_value = "afs")]
    pub prefix: String,
    /// Scenario whose set-up to use.
    #[arg(long, default_value = "surface-tracking")]
    pub scenario: String,
    /// TOML file overriding the default set-up (same keys as `afs experiment --config`).
    #[arg(long)]
    pub sim_config: Option<PathBuf>,
    /// Seed of the sensor noise.
    #[arg(long)]
    pub seed: Option<u64>,
    /// CPU to pin to.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// SCHED_FIFO priority, 1–99 (0: normal scheduling).
    #[arg(long, default_value_t = 0)]
    pub priority: u8,
}

impl Common {
    /// The base set-up: the file's, with the seed applied, checked.
    pub fn base(&self) -> Result<SimConfig> {
        crate::ipc::check_prefix(&self.prefix)?;
        let mut cfg = match &self.sim_config {
            Some(p) => load_config(p)?,
            None => SimConfig::default(),
        };
        if let Some(s) = self.seed {
            cfg.seed = s;
        }
        Ok(cfg)
    }

    /// The scenario's set-up.
    pub fn scenario(&self) -> Result<Scenario> {
        Scenario::new(&self.scenario, &self.base()?).map_err(anyhow::Error::msg)
    }
}

/// A flag set when the process is asked to stop (SIGINT, SIGTERM, SIGHUP).
pub fn stop_flag() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    ctrlc::set_handler(move || s.store(true, Ordering::Relaxed))
        .map_err(|e| anyhow::anyhow!("installing the signal handler: {e}"))?;
    Ok(stop)
}

/// A board's start-up report in the making: each phase's end is stamped as it happens
/// ([`rt::monotonic_ns`]) and the report goes out once, when the board's data flows
/// (`afs/boards/startup`, read by the supervisor to explain each restart's time).
pub struct Startup {
    /// The phases so far.
    pub report: BoardStartup,
    publisher: Option<Publisher<Svc, BoardStartup, ()>>,
    sent: bool,
}

impl Startup {
    /// Starts the clock of `board`  at `main_ns`, the time `main` was
    /// entered.
    pub fn new(board: Board, main_ns: u64) -> Self {
        Self {
            report: BoardStartup {
                version: msg::BoardStartup::VERSION,
                board: board.into(),
                pid: std::process::id() as i32,
                main_ns,
                ..Default::default()
            },
            publisher: None,
            sent: false,
        }
    }

    /// The current time, for a phase field.
    pub fn now() -> u64 {
        rt::monotonic_ns()
    }

    /// Opens the report's publisher on `node` (with the board's other ports).
    pub fn open(&mut self, node: &Node<Svc>) -> Result<()> {
        self.publisher = Some(
            ipc::startup(node)?
                .publisher_builder()
                .create()
                .context("start-up publisher")?,
        );
        Ok(())
    }

    /// Drops the connections to subscribers that died (the publisher sends once, so it would
    /// otherwise keep them) and connects new ones; call it now and then.
    pub fn update_connections(&self) {
        if let Some(p) = self.publisher.as_ref() {
            let _ = p.update_connections();
        }
    }

    /// Sends the report (once; later calls do nothing). A failed send only loses the report.
    pub fn send(&mut self) {
        if let Some(p) = self.publisher.as_ref()
            && !self.sent
        {
            let _ = p.send_copy(self.report);
            self.sent = true;
        }
    }
}
