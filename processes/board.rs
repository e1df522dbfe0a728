//! What the board binaries share: their common command-line options, loading the set-up, and
//! the stop flag set by SIGINT/SIGTERM/SIGHUP.

use crate::experiment::load_config;
use afs_shared::scenario::Scenario;
use afs_shared::sim::SimConfig;
use anyhow::Result;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

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
