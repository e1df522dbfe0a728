//! `afs experiment NAME`: runs one of the in-process lockstep experiments, writes its plot and
//! returns its JSON report.

use crate::tools::plot;
use afs_shared::error::ExperimentError;
use afs_shared::experiments::{self, Options, Outcome};
use anyhow::{Context, Result, bail};
use serde::Serialize;
use serde_json::{Value, json};
use std::path::Path;
use std::time::Instant;

/// The JSON report of one experiment: its name, the pass/fail of its checks, the measured
/// summary, the plot path and timing (documented in docs/experiments.md).
pub fn run(name: &str, opts: &Options, out_dir: &Path) -> Result<(Value, bool)> {
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("creating output directory {}", out_dir.display()))?;
    let started = Instant::now();
    let cpu0 = crate::procfs::cpu_seconds();
    let (report, figure, passed, simulated) = match name {
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
    plot::render(&figure, &file)?;
    let mut obj = report;
    obj["experiment"] = json!(name);
    obj["seed"] = json!(opts.seed);
    obj["passed"] = json!(passed);
    obj["plot"] = json!(file.display().to_string());
    obj["timing"] = json!({
        "simulated_s": simulated,
        "wall_s": wall,
        "cpu_s": cpu,
        "realtime_factor": if cpu > 0.0 { simulated / cpu } else { 0.0 },
    });
    Ok((obj, passed))
}

fn pack<S: Serialize>(
    r: Result<Outcome<S>, ExperimentError>,
) -> Result<(Value, experiments::Figure, bool, f64)> {
    let o = r?;
    let passed = o.passed();
    let v = serde_json::to_value(&o).context("serialising the report")?;
    Ok((v, o.figure, passed, o.simulated_s))
}
