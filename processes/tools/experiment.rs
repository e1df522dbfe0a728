//! `afs experiment NAME`: runs one of the in-process lockstep experiments, writes its plot and
//! returns its report.

use crate::tools::plot;
use afs_shared::check::Check;
use afs_shared::error::ExperimentError;
use afs_shared::experiments::{self, Options, Outcome};
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

/// Runs experiment `name`, writes its plot into `out_dir`.
pub fn run(name: &str, opts: &Options, out_dir: &Path) -> Result<ExperimentReport> {
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("creating output directory {}", out_dir.display()))?;
    let started = Instant::now();
    let cpu0 = crate::procfs::cpu_seconds();
    let packed = match name {
        "friction-id" => pack(experiments::friction_id(opts))?,
        "fig4.5" => pack(experiments::fig4_5(opts))?,
        "fig4.6" => pack(experiments::fig4_6(opts))?,
        "fig4.7" => pack(experiments::fig4_7(opts))?,
        "fig4.8" => pack(experiments::fig4_8(opts))?,
        "tangent" => pack(experiments::tangent(opts))?,
        "fig5.6" => pack(experiments::fig5_6(opts))?,
        "corners" => pack(experiments::corners(opts))?,
        "fig5.3" => pack(experiments::fig5_3(opts))?,
        "fig5.9" => pack(experiments::fig5_9(opts))?,
        other => bail!(
            "unknown experiment '{other}'; choose one of: {}",
            experiments::NAMES.join(", ")
        ),
    };
    let wall = started.elapsed().as_secs_f64();
    let cpu = crate::procfs::cpu_seconds() - cpu0;
    let file = out_dir.join(format!("{}.svg", name.replace('.', "_")));
    plot::render(&packed.figure, &file)?;
    let passed = afs_shared::check::all_pass(&packed.checks);
    Ok(ExperimentReport {
        experiment: name.to_string(),
        seed: opts.seed,
        passed,
        summary: packed.summary,
        checks: packed.checks,
        simulated_s: packed.simulated_s,
        plot: file.display().to_string(),
        timing: Timing {
            simulated_s: packed.simulated_s,
            wall_s: wall,
            cpu_s: cpu,
            realtime_factor: if cpu > 0.0 {
                packed.simulated_s / cpu
            } else {
                0.0
            },
        },
    })
}

/// An outcome with its summary made generic.
struct Packed {
    summary: Value,
    checks: Vec<Check>,
    simulated_s: f64,
    figure: experiments::Figure,
}

fn pack<S: Serialize>(r: Result<Outcome<S>, ExperimentError>) -> Result<Packed> {
    let o = r?;
    Ok(Packed {
        summary: serde_json::to_value(&o.summary).context("serialising the summary")?,
        checks: o.checks,
        simulated_s: o.simulated_s,
        figure: o.figure,
    })
}
