//! `afs experiment insertion --grid --seeds A..B`: the insertion over the grid of fits
//! (clearance × μ × chamfer, docs/insertion.md) for the three methods, each point a seed sweep:
//! the table of success rates and the plot of success against clearance.

use super::sweep::sweep;
use crate::tools::plot;
use crate::tools::progress::Progress;
use afs_shared::experiments::{Figure, Options, Panel, Series};
use afs_shared::insertion::controller::Method;
use anyhow::{Context, Result};
use serde::Serialize;
use std::fmt;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// Clearance ratios c of the grid (the plot's x, decreasing: tighter to the right).
pub const CLEARANCES: [f64; 3] = [0.01, 0.002, 0.0005];
/// Friction coefficients of the grid (one panel each).
pub const MUS: [f64; 3] = [0.1, 0.3, 0.5];
/// Chamfer legs of the grid (mm; 0: none).
pub const CHAMFERS_MM: [f64; 2] = [0.5, 0.0];

/// One method at one point of the grid, over the seeds.
#[derive(Debug, Clone, Serialize)]
pub struct GridPoint {
    /// Clearance ratio c.
    pub clearance_ratio: f64,
    /// μ.
    pub mu: f64,
    /// Chamfer leg (mm; 0: none).
    pub chamfer_mm: f64,
    /// The controller.
    pub method: &'static str,
    /// Seeds run.
    pub runs: usize,
    /// Seeds where the peg went in (depth within the time limit, under the force limit).
    pub inserted: usize,
    /// Its Wilson 95 % interval.
    pub inserted_wilson_95: [f64; 2],
    /// Median insertion time over the seeds that inserted (s; null if none did).
    pub median_time_s: Option<f64>,
}

/// The grid's report.
#[derive(Debug, Clone, Serialize)]
pub struct GridReport {
    /// The seeds of every point.
    pub seeds: [u64; 2],
    /// Every method at every point.
    pub points: Vec<GridPoint>,
    /// Points (of 18) where the dither method inserted at least as often as both baselines.
    pub dither_at_least_both: usize,
    /// True when that holds at every point.
    pub passed: bool,
    /// Path of the plot.
    pub plot: String,
    /// Wall time (s).
    pub wall_s: f64,
}

impl fmt::Display for GridReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [a, b] = self.seeds;
        writeln!(
            f,
            "insertion grid over seeds {a}..={b}: inserted of {}",
            b - a + 1
        )?;
        writeln!(f, "     c     μ  chamfer   dither  no-dither   search")?;
        for p in self.points.chunks(Method::ALL.len()) {
            let chamfer = if p[0].chamfer_mm > 0.0 {
                format!("{} mm", p[0].chamfer_mm)
            } else {
                "none".into()
            };
            write!(
                f,
                "{:>6} {:>5} {:>8}",
                p[0].clearance_ratio, p[0].mu, chamfer
            )?;
            for m in p {
                write!(f, " {:>9}", m.inserted)?;
            }
            writeln!(f)?;
        }
        writeln!(
            f,
            "dither at least both baselines at {} of {} points ({:.1} s; plot {})",
            self.dither_at_least_both,
            self.points.len() / Method::ALL.len(),
            self.wall_s,
            self.plot
        )
    }
}

/// Runs the grid on the options' other settings (initial errors, limits) over `seeds`.
pub fn grid(
    opts: &Options,
    seeds: std::ops::RangeInclusive<u64>,
    jobs: usize,
    out_dir: &Path,
    stop: &AtomicBool,
) -> Result<GridReport> {
    let started = Instant::now();
    // Each point's seed plot is of no use here: it goes to a scratch folder, removed after.
    let scratch = std::env::temp_dir().join(format!("afs-grid-{}", std::process::id()));
    let points_n = CLEARANCES.len() * MUS.len() * CHAMFERS_MM.len() * Method::ALL.len();
    let progress = Progress::new(
        &format!(
            "insertion grid ({points_n} points) over seeds {}..={}",
            seeds.start(),
            seeds.end()
        ),
        points_n as u64 * (seeds.end() - seeds.start() + 1),
    );
    let points = run_points(opts, &seeds, jobs, &scratch, stop, &progress);
    progress.finish();
    let _ = std::fs::remove_dir_all(&scratch);
    let points = points?;
    let dither_at_least_both = points
        .chunks(Method::ALL.len())
        .filter(|p| p[1..].iter().all(|b| p[0].inserted >= b.inserted))
        .count();
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("creating output directory {}", out_dir.display()))?;
    let file = out_dir.join("insertion_grid.svg");
    plot::render(&figure(&points), &file)?;
    Ok(GridReport {
        seeds: [*seeds.start(), *seeds.end()],
        passed: dither_at_least_both == points.len() / Method::ALL.len(),
        dither_at_least_both,
        points,
        plot: file.display().to_string(),
        wall_s: started.elapsed().as_secs_f64(),
    })
}

/// Every method at every fit, in the order of [`CLEARANCES`], [`MUS`], [`CHAMFERS_MM`],
/// [`Method::ALL`].
fn run_points(
    opts: &Options,
    seeds: &std::ops::RangeInclusive<u64>,
    jobs: usize,
    scratch: &Path,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<Vec<GridPoint>> {
    let mut points = Vec::new();
    for c in CLEARANCES {
        for mu in MUS {
            for chamfer in CHAMFERS_MM {
                for method in Method::ALL {
                    let mut o = opts.clone();
                    o.insertion.clearance_ratio = c;
                    o.insertion.mu = mu;
                    o.insertion.chamfer_mm = chamfer;
                    o.insertion.method = method;
                    let r = sweep(
                        "insertion",
                        &o,
                        seeds.clone(),
                        jobs,
                        scratch,
                        stop,
                        progress,
                    )
                    .with_context(|| {
                        format!("grid point c = {c}, μ = {mu}, chamfer {chamfer} mm")
                    })?;
                    let check = |id: &str| r.checks.iter().find(|k| k.id == id);
                    let inserted =
                        check("inserted").context("insertion has no `inserted` check")?;
                    let time = check("insertion_time_s")
                        .map(|k| k.median)
                        .filter(|t| t.is_finite() && inserted.passes > 0);
                    points.push(GridPoint {
                        clearance_ratio: c,
                        mu,
                        chamfer_mm: chamfer,
                        method: method.name(),
                        runs: inserted.runs,
                        inserted: inserted.passes,
                        inserted_wilson_95: inserted.pass_rate_wilson_95,
                        median_time_s: time,
                    });
                }
            }
        }
    }
    Ok(points)
}

/// Success against clearance: a panel per μ, a series per method and chamfer.
fn figure(points: &[GridPoint]) -> Figure {
    let panels = MUS
        .iter()
        .map(|&mu| Panel {
            x_label: None,
            y_label: format!("inserted (%), μ = {mu}"),
            series: Method::ALL
                .iter()
                .flat_map(|m| CHAMFERS_MM.iter().map(move |&ch| (m.name(), ch)))
                .map(|(name, ch)| Series {
                    label: if ch > 0.0 {
                        format!("{name}, chamfer {ch} mm")
                    } else {
                        format!("{name}, no chamfer")
                    },
                    points: points
                        .iter()
                        .filter(|p| p.mu == mu && p.chamfer_mm == ch && p.method == name)
                        .map(|p| [p.clearance_ratio, 100.0 * p.inserted as f64 / p.runs as f64])
                        .collect(),
                    markers: true,
                })
                .collect(),
        })
        .collect();
    Figure {
        title: "Insertion: success against clearance, three methods".into(),
        x_label: "clearance ratio c = (D − d)/D".into(),
        log_x: true,
        panels,
    }
}
