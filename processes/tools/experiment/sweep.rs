//! One experiment over many seeds, on every core: each check's distribution and its plot.

use super::one::{compute, file_stem};
use crate::tools::plot;
use crate::tools::progress::Progress;
use afs_shared::check::Check;
use afs_shared::experiments::Options;
use afs_shared::setups::Rig;
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::Path;
use std::time::Instant;

/// An experiment over many seeds (`afs experiment NAME --seeds A..B`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SweepReport {
    /// Experiment name.
    pub experiment: String,
    /// First and last seed (inclusive).
    pub seeds: [u64; 2],
    /// The rig (`afs` or `thesis`).
    pub rig: Rig,
    /// Threads used.
    pub jobs: usize,
    /// True when every check passed at every seed.
    pub passed: bool,
    /// Each check over the seeds.
    pub checks: Vec<afs_shared::sweep::CheckSweep>,
    /// Path of the plot (each check's figure / limit over the seeds).
    pub plot: String,
    /// Wall time of the sweep (s).
    pub wall_s: f64,
    /// Sum of the single runs' wall times (s): what one thread would have taken.
    pub runs_wall_s: f64,
    /// wall_s / runs_wall_s (1: no gain from the threads).
    pub wall_ratio: f64,
    /// CPU time of this process during the sweep (s).
    pub cpu_s: f64,
}

impl fmt::Display for SweepReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{} over seeds {}..={}: {} ({} threads, {:.1} s, {:.2}x the single runs' {:.1} s; plot {})",
            self.experiment,
            self.seeds[0],
            self.seeds[1],
            if self.passed { "PASS" } else { "FAIL" },
            self.jobs,
            self.wall_s,
            self.wall_ratio,
            self.runs_wall_s,
            self.plot
        )?;
        for c in &self.checks {
            writeln!(
                f,
                "  {:5.1} % pass [{:.1}, {:.1}]  {} {} {}: median {:.4}, p90 {:.4}, worst {:.4} (seed {}){}",
                100.0 * c.pass_rate,
                100.0 * c.pass_rate_wilson_95[0],
                100.0 * c.pass_rate_wilson_95[1],
                c.name,
                c.relation.symbol(),
                c.limit,
                c.median,
                c.p90,
                c.worst,
                c.worst_seed,
                if c.failed_seeds.is_empty() || c.failed_seeds.len() > 10 {
                    String::new()
                } else {
                    format!("; failed at {:?}", c.failed_seeds)
                }
            )?;
        }
        Ok(())
    }
}

/// Runs experiment `name` at every seed of `seeds` on `jobs` threads (the core is pure: each
/// run owns its state) and summarises each check; writes the plot into `out_dir`. Each run is
/// counted in `progress`. Stops early (with an error) if `stop` is set.
pub fn sweep(
    name: &str,
    opts: &Options,
    seeds: std::ops::RangeInclusive<u64>,
    jobs: usize,
    out_dir: &Path,
    stop: &std::sync::atomic::AtomicBool,
    progress: &Progress,
) -> Result<SweepReport> {
    use std::sync::Mutex;
    use std::sync::atomic::{AtomicU64, Ordering};
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("creating output directory {}", out_dir.display()))?;
    let jobs = jobs.max(1);
    let (first, last) = (*seeds.start(), *seeds.end());
    let next = AtomicU64::new(first);
    let results: Mutex<Vec<(u64, Vec<Check>, f64)>> = Mutex::new(Vec::new());
    let error: Mutex<Option<anyhow::Error>> = Mutex::new(None);
    let started = Instant::now();
    let cpu0 = crate::procfs::cpu_seconds();
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            scope.spawn(|| {
                loop {
                    if stop.load(Ordering::Relaxed) {
                        return;
                    }
                    let seed = next.fetch_add(1, Ordering::Relaxed);
                    if seed > last {
                        return;
                    }
                    let o = Options {
                        seed,
                        ..opts.clone()
                    };
                    let t0 = Instant::now();
                    match compute(name, &o) {
                        Ok(p) => {
                            let wall = t0.elapsed().as_secs_f64();
                            progress.run_done(&p.checks);
                            results
                                .lock()
                                .unwrap_or_else(|e| e.into_inner())
                                .push((seed, p.checks, wall));
                        }
                        Err(e) => {
                            error
                                .lock()
                                .unwrap_or_else(|e| e.into_inner())
                                .get_or_insert(e.context(format!("{name} at seed {seed}")));
                            stop.store(true, Ordering::Relaxed);
                            return;
                        }
                    }
                }
            });
        }
    });
    if let Some(e) = error.into_inner().unwrap_or_else(|e| e.into_inner()) {
        return Err(e);
    }
    let mut results = results.into_inner().unwrap_or_else(|e| e.into_inner());
    if results.len() as u64 != last - first + 1 {
        bail!(
            "interrupted after {} of {} seeds",
            results.len(),
            last - first + 1
        );
    }
    results.sort_by_key(|r| r.0);
    let wall_s = started.elapsed().as_secs_f64();
    let cpu_s = crate::procfs::cpu_seconds() - cpu0;
    let runs_wall_s: f64 = results.iter().map(|r| r.2).sum();
    let runs: Vec<(u64, Vec<Check>)> = results.into_iter().map(|(s, c, _)| (s, c)).collect();
    let checks = afs_shared::sweep::summarize(&runs);
    let file = out_dir.join(format!("{}_seeds.svg", file_stem(name, opts.rig)));
    plot::render(&afs_shared::sweep::figure(name, &runs, &checks), &file)?;
    Ok(SweepReport {
        experiment: name.to_string(),
        seeds: [first, last],
        rig: opts.rig,
        jobs,
        passed: checks.iter().all(|c| c.passes == c.runs),
        checks,
        plot: file.display().to_string(),
        wall_s,
        runs_wall_s,
        wall_ratio: if runs_wall_s > 0.0 {
            wall_s / runs_wall_s
        } else {
            0.0
        },
        cpu_s,
    })
}
