//! One experiment at one seed: run in lockstep, its plot written, its report.

use crate::tools::plot;
use afs_shared::check::Check;
use afs_shared::experiments::{self, Options, Run};
use afs_shared::setups::Rig;
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::fmt;
use std::path::Path;
use std::time::Instant;

/// What running an experiment cost.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Timing {
    /// Simulated time (s).
    pub simulated_s: f64,
    /// Wall-clock time (s).
    pub wall_s: f64,
    /// CPU time of this process (s).
    pub cpu_s: f64,
    /// Simulated seconds per CPU second.
    pub realtime_factor: f64,
}

/// The report of one experiment (documented in docs/experiments.md).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ExperimentReport {
    /// Experiment name (`fig4.8`, ...).
    pub experiment: String,
    /// Seed of the sensor noise and surface roughness.
    pub seed: u64,
    /// The rig (`afs` or `thesis`).
    pub rig: Rig,
    /// True when every check passes.
    pub passed: bool,
    /// The measured figures; their shape is the experiment's own.
    pub summary: Value,
    /// Acceptance checks.
    pub checks: Vec<Check>,
    /// Simulated time (s).
    pub simulated_s: f64,
    /// Path of the plot.
    pub plot: String,
    /// What running it cost.
    pub timing: Timing,
}

impl fmt::Display for ExperimentReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{}: {} (plot {}, {:.1} s simulated in {:.2} s CPU)",
            self.experiment,
            if self.passed { "PASS" } else { "FAIL" },
            self.plot,
            self.timing.simulated_s,
            self.timing.cpu_s,
        )?;
        for c in &self.checks {
            writeln!(f, "  {}", c.line())?;
        }
        Ok(())
    }
}

/// The plot's file name without extension: `fig4_7`, or `fig4_7_thesis` on the thesis rig.
pub(super) fn file_stem(name: &str, rig: Rig) -> String {
    let stem = name.replace('.', "_");
    match rig {
        Rig::Afs => stem,
        other => format!("{stem}_{}", other.name()),
    }
}

/// The names of the experiments of the thesis's rig.
fn friction_names() -> String {
    let names: Vec<&str> = experiments::REGISTRY
        .iter()
        .filter(|e| e.friction)
        .map(|e| e.name)
        .collect();
    names.join(", ")
}

/// Runs experiment `name` without plotting it.
pub(super) fn compute(name: &str, opts: &Options) -> Result<Run> {
    let e = experiments::find(name).with_context(|| {
        let names: Vec<&str> = experiments::REGISTRY.iter().map(|e| e.name).collect();
        format!(
            "unknown experiment '{name}'; choose one of: {}",
            names.join(", ")
        )
    })?;
    if opts.rig != Rig::Afs && !e.friction {
        bail!(
            "the {} rig is defined for the friction experiments ({}); run {name} without --rig",
            opts.rig.name(),
            friction_names()
        );
    }
    Ok((e.run)(opts)?)
}

/// Runs experiment `name`, writes its plot into `out_dir`.
pub fn run(name: &str, opts: &Options, out_dir: &Path) -> Result<ExperimentReport> {
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("creating output directory {}", out_dir.display()))?;
    let started = Instant::now();
    let cpu0 = crate::procfs::cpu_seconds();
    let out = compute(name, opts)?;
    let wall = started.elapsed().as_secs_f64();
    let cpu = crate::procfs::cpu_seconds() - cpu0;
    let file = out_dir.join(format!("{}.svg", file_stem(name, opts.rig)));
    plot::render(&out.figure, &file)?;
    let passed = afs_shared::check::all_pass(&out.checks);
    Ok(ExperimentReport {
        experiment: name.to_string(),
        seed: opts.seed,
        rig: opts.rig,
        passed,
        summary: out.summary,
        checks: out.checks,
        simulated_s: out.simulated_s,
        plot: file.display().to_string(),
        timing: Timing {
            simulated_s: out.simulated_s,
            wall_s: wall,
            cpu_s: cpu,
            realtime_factor: if cpu > 0.0 {
                out.simulated_s / cpu
            } else {
                0.0
            },
        },
    })
}
