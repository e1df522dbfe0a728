//! `afs experiment NAME`: runs one of the in-process lockstep experiments, writes its plot and
//! returns its report; over many seeds (`--seeds`, [`sweep`]) or, for the insertion, over the
//! grid of fits (`--grid`, [`grid`]).

mod grid;
mod one;
mod sweep;

pub use grid::{GridPoint, GridReport, grid};
pub use one::{ExperimentReport, Timing, run};
pub use sweep::{SweepReport, sweep};

use crate::tools::progress::Progress;
use afs_shared::experiments::{self, Options};
use afs_shared::setups::Rig;
use anyhow::{Context, Result, bail};
use serde::Serialize;
use std::fmt;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;

/// Seeds `first..=last`, from `A..B` or `A..=B` (both inclusive).
pub fn parse_seeds(s: &str) -> Result<std::ops::RangeInclusive<u64>> {
    let (a, b) = s
        .split_once("..=")
        .or_else(|| s.split_once(".."))
        .with_context(|| format!("--seeds '{s}' must be a range FIRST..LAST, e.g. 1..100"))?;
    let parse = |x: &str| {
        x.trim()
            .parse::<u64>()
            .with_context(|| format!("--seeds '{s}': '{x}' is not a seed (a whole number)"))
    };
    let (a, b) = (parse(a)?, parse(b)?);
    if a > b {
        bail!("--seeds '{s}': the first seed is after the last");
    }
    if b - a >= 100_000 {
        bail!("--seeds '{s}': at most 100000 seeds at once");
    }
    Ok(a..=b)
}

/// The options of `afs experiment`.
#[derive(Debug, Clone, clap::Args)]
pub struct ExperimentArgs {
    /// The experiment (`afs experiment list`, docs/experiments.md), `all` of them, or `list`
    /// to print the table of experiments.
    #[arg(value_parser = experiment_names())]
    pub name: String,
    /// Directory for the plot(s).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Seed of the sensor noise and surface roughness.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print the report as one JSON object (an array for `all`).
    #[arg(long)]
    pub json: bool,
    /// fig4.6: use the six trials printed in the thesis.
    #[arg(long)]
    pub thesis_table: bool,
    /// Run at every seed of FIRST..LAST (inclusive) and report, per check, its pass rate and
    /// the median, 90th percentile and worst of its figure; plots each check's figure over the
    /// seeds (NAME_seeds.svg). Overrides --seed.
    #[arg(long, value_name = "FIRST..LAST")]
    pub seeds: Option<String>,
    /// Threads for --seeds (default: one per CPU).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// A stack file whose `[sim]` table overrides the default set-up (plant, surface, sensor,
    /// servo, world, insertion), the same file `afs run --config` takes; the experiment's own
    /// settings apply on top.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The rig: `afs` (decoupled operating point, inverse-dynamics and preload feedforward) or
    /// `thesis` (PID joints only, at a coupled point; docs/model.md). Applied on top of
    /// --config. The thesis rig is defined for the friction experiments (with `all`, only
    /// those run).
    #[arg(long, default_value = "afs", value_parser = ["afs", "thesis"])]
    pub rig: String,
    /// The world the servo drives: `builtin` (afs's plant) or `mujoco` (MuJoCo on the model
    /// afs generates from the set-up; docs/mujoco.md). Applied on top of --config.
    #[arg(long, value_parser = ["builtin", "mujoco"])]
    pub plant: Option<String>,
    /// A MuJoCo model of your own arm (implies --plant mujoco): two hinge joints about z, a
    /// site `tool`, a mocap body `surface` (docs/mujoco.md, *Your own arm*).
    #[arg(long, value_name = "FILE")]
    pub mjcf: Option<PathBuf>,
    /// The servo rate (Hz): 10000 (the thesis's rig), 1000 (Franka FCI), 500 (UR e-Series);
    /// the dither and tuner settings follow it (docs/mujoco.md, *Rates*).
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// insertion's own options.
    #[command(flatten)]
    pub insertion: InsertionArgs,
}

/// `afs experiment insertion`'s options (docs/insertion.md).
#[derive(Debug, Clone, clap::Args)]
pub struct InsertionArgs {
    /// insertion: clearance ratio c = (D − d)/D [default: the set-up's, 0.002].
    #[arg(long)]
    pub clearance: Option<f64>,
    /// insertion: friction coefficient μ at every contact [default: the set-up's, 0.3].
    #[arg(long)]
    pub mu: Option<f64>,
    /// insertion: chamfer leg (mm); 0 for a sharp edge [default: the set-up's, 0.5].
    #[arg(long)]
    pub chamfer_mm: Option<f64>,
    /// insertion: initial lateral error (mm); default uniform in ±2 mm per seed.
    #[arg(long, allow_hyphen_values = true)]
    pub lateral_mm: Option<f64>,
    /// insertion: initial angle error (deg); default uniform in ±2° per seed.
    #[arg(long, allow_hyphen_values = true)]
    pub angle_deg: Option<f64>,
    /// insertion: the controller [default: the set-up's, dither].
    #[arg(long, value_parser = ["dither", "no-dither", "search"])]
    pub method: Option<String>,
    /// insertion: what positions the wrist's flange: `ideal` (exactly where commanded) or
    /// `arm` (the three-joint arm with its dynamics under its joint servos) [default: the
    /// set-up's, ideal].
    #[arg(long, value_parser = ["ideal", "arm"])]
    pub drive: Option<String>,
    /// insertion: what the robot knows of the part's orientation: `known` (a fixtured part)
    /// or `unknown` (its frame turned by the angle error; the controller estimates the face's
    /// tangent) [default: the set-up's, known].
    #[arg(long, value_parser = ["known", "unknown"])]
    pub part_frame: Option<String>,
    /// insertion: every method at every point of the grid (c 0.01, 0.002, 0.0005 × μ 0.1,
    /// 0.3, 0.5 × chamfer 0.5 mm, none) over --seeds, instead of one fit and method; prints
    /// the table and plots success against clearance (insertion_grid.svg). Exits 1 where the
    /// dither method inserts less often than a baseline.
    #[arg(long, requires = "seeds")]
    pub grid: bool,
}

impl InsertionArgs {
    /// The set-up's `[insertion]` settings with the options given on the command line.
    fn options(&self, base: &experiments::InsertionOptions) -> experiments::InsertionOptions {
        experiments::InsertionOptions {
            clearance_ratio: self.clearance.unwrap_or(base.clearance_ratio),
            mu: self.mu.unwrap_or(base.mu),
            chamfer_mm: self.chamfer_mm.unwrap_or(base.chamfer_mm),
            lateral_mm: self.lateral_mm.or(base.lateral_mm),
            angle_deg: self.angle_deg.or(base.angle_deg),
            // The parser allows only the three names.
            method: self
                .method
                .as_deref()
                .and_then(afs_shared::insertion::controller::Method::parse)
                .unwrap_or(base.method),
            drive: self
                .drive
                .as_deref()
                .and_then(afs_shared::insertion::drive::Drive::parse)
                .unwrap_or(base.drive),
            part_frame: self
                .part_frame
                .as_deref()
                .and_then(afs_shared::insertion::rig::PartFrame::parse)
                .unwrap_or(base.part_frame),
            ..*base
        }
    }
}

/// The registry's names, `all` and `list`, for `afs experiment --help` and the parser.
fn experiment_names() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(
        experiments::REGISTRY
            .iter()
            .map(|e| e.name)
            .chain(["all", "list"]),
    )
}

/// `afs experiment`: the named experiment(s) at one seed, or over `--seeds`; prints the
/// report(s) (JSON with `--json`). Exit status 1 when a check fails.
pub fn command(a: &ExperimentArgs, stop: &AtomicBool) -> Result<ExitCode> {
    if a.name == "list" {
        print!("{}", experiments::registry_table());
        return Ok(ExitCode::SUCCESS);
    }
    let mut base = match &a.config {
        Some(path) => crate::stack::setup_of(path)?,
        None => Default::default(),
    };
    let rig = Rig::parse(&a.rig).unwrap_or_default();
    rig.apply(&mut base)?;
    if let Some(kind) = &a.plant {
        base.world.kind = afs_shared::world::WorldKind::parse(kind)?;
        if base.world.kind != afs_shared::world::WorldKind::Builtin
            && experiments::WORLD_FREE.contains(&a.name.as_str())
        {
            bail!(
                "{} simulates no world (eq. 4.5's curves: docs/mujoco.md); run it without \
                 --plant",
                a.name
            );
        }
    }
    if let Some(path) = &a.mjcf {
        base.world.kind = afs_shared::world::WorldKind::Mujoco;
        base.world.mjcf = Some(path.display().to_string());
        // Refused here, once, with what the model lacks (exit 2).
        afs_shared::world::resolve(&base)?;
    }
    if let Some(hz) = a.rate_hz {
        afs_shared::setups::set_rate(&mut base, hz)?;
    }
    let insertion = a.insertion.options(&base.insertion);
    let opts = Options {
        seed: a.seed,
        thesis_table: a.thesis_table,
        base,
        rig,
        insertion,
    };
    // The thesis's rig is defined for the friction experiments only.
    let names: Vec<&str> = match a.name.as_str() {
        "all" => experiments::REGISTRY
            .iter()
            .filter(|e| rig == Rig::Afs || e.friction)
            .filter(|e| {
                opts.base.world.kind == afs_shared::world::WorldKind::Builtin
                    || !experiments::WORLD_FREE.contains(&e.name)
            })
            .map(|e| e.name)
            .collect(),
        one => vec![one],
    };
    let passed = match &a.seeds {
        Some(range) if a.insertion.grid => {
            if a.name != "insertion" {
                bail!("--grid is insertion's (afs experiment insertion --grid --seeds A..B)");
            }
            let range = parse_seeds(range)?;
            let jobs = a.jobs.unwrap_or_else(crate::rt::available_cpus);
            if jobs == 0 {
                bail!("--jobs must be at least 1");
            }
            let report = grid(&opts, range, jobs, &a.out, stop)?;
            show(Some(&report), a.json);
            print_json(std::slice::from_ref(&report), a.json)?;
            report.passed
        }
        Some(range) => {
            let range = parse_seeds(range)?;
            let jobs = a.jobs.unwrap_or_else(crate::rt::available_cpus);
            if jobs == 0 {
                bail!("--jobs must be at least 1");
            }
            let mut reports = Vec::new();
            for n in names {
                let progress = Progress::new(
                    &format!("{n} over seeds {}..={}", range.start(), range.end()),
                    range.end() - range.start() + 1,
                );
                let report = sweep(n, &opts, range.clone(), jobs, &a.out, stop, &progress);
                progress.finish();
                reports.push(report?);
                show(reports.last(), a.json);
            }
            print_json(&reports, a.json)?;
            reports.iter().all(|r| r.passed)
        }
        None => {
            let mut reports = Vec::new();
            for n in names {
                reports.push(run(n, &opts, &a.out)?);
                show(reports.last(), a.json);
            }
            print_json(&reports, a.json)?;
            reports.iter().all(|r| r.passed)
        }
    };
    let warnings = afs_shared::world::mujoco_warnings();
    if warnings > 0 {
        eprintln!(
            "afs: MuJoCo gave {warnings} warnings (its solver's, counted, not printed); the \
             figures stand, but the contact settings may be stiff for the step (docs/mujoco.md)"
        );
    }
    Ok(if passed {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// A report as text, as soon as it is done (not with `--json`). A closed stdout (`afs
/// experiment all | head`) is not an error.
fn show<R: fmt::Display>(report: Option<&R>, json: bool) {
    use std::io::Write as _;
    if let Some(r) = report.filter(|_| !json) {
        let _ = write!(std::io::stdout().lock(), "{r}");
    }
}

/// With `json`, the reports as one JSON value: an object for one, an array for more.
fn print_json<R: Serialize>(reports: &[R], json: bool) -> Result<()> {
    use std::io::Write as _;
    if json {
        let text = match reports {
            [one] => serde_json::to_string_pretty(one)?,
            all => serde_json::to_string_pretty(all)?,
        };
        let _ = writeln!(std::io::stdout().lock(), "{text}");
    }
    Ok(())
}
