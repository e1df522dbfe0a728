//! A check over many seeds: how often it held, and the distribution of its figure (median,
//! 90th percentile and worst, "worst" in the direction that fails the check), with the seed of
//! the worst. `afs experiment NAME --seeds A..B` reports one per check; the figure over seeds
//! is plotted as value / limit (1 is the limit).

use crate::check::{Check, CheckKind, Relation};
use crate::experiments::{Figure, Panel, Series};
use serde::{Deserialize, Serialize};

/// One check over the seeds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckSweep {
    /// The check's stable identifier.
    pub id: String,
    /// What is checked.
    pub name: String,
    /// How the figure must stand to the limit.
    pub relation: Relation,
    /// The limit (of the first seed; a check whose limit depends on the seed is rare).
    pub limit: f64,
    /// Correctness or target.
    pub kind: CheckKind,
    /// Seeds run.
    pub runs: usize,
    /// Seeds where it held.
    pub passes: usize,
    /// passes / runs.
    pub pass_rate: f64,
    /// The Wilson score 95 % interval of the pass rate ([`wilson_95`]).
    #[serde(default)]
    pub pass_rate_wilson_95: [f64; 2],
    /// Seeds whose figure was not a finite number (counted as failures, left out of the
    /// quantiles).
    pub non_finite: usize,
    /// Median figure.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub median: f64,
    /// The figure that 90 % of the seeds do better than (the 90th percentile for `<=`, the
    /// 10th for `>=`).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub p90: f64,
    /// The worst figure (largest for `<=`, smallest for `>=`).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub worst: f64,
    /// The seed of the worst figure (or of the first non-finite one).
    pub worst_seed: u64,
    /// The seeds where it failed.
    pub failed_seeds: Vec<u64>,
}

/// The Wilson score interval at 95 % (z = 1.96) of a rate of `k` successes in `n` trials:
/// `(p̂ + z²/2n ± z √(p̂(1 − p̂)/n + z²/4n²)) / (1 + z²/n)`. [0, 1] for no trials.
pub fn wilson_95(k: usize, n: usize) -> [f64; 2] {
    if n == 0 {
        return [0.0, 1.0];
    }
    let (z, n) = (1.96f64, n as f64);
    let p = k as f64 / n;
    let z2 = z * z;
    let centre = (p + z2 / (2.0 * n)) / (1.0 + z2 / n);
    let half = z / (1.0 + z2 / n) * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt();
    [(centre - half).max(0.0), (centre + half).min(1.0)]
}

/// The value at fraction `q` of sorted finite values, by linear interpolation between ranks
/// (`q = 0.5` is the median).
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        n => {
            let pos = q.clamp(0.0, 1.0) * (n - 1) as f64;
            let (lo, frac) = (pos.floor() as usize, pos.fract());
            if lo + 1 < n {
                sorted[lo] + frac * (sorted[lo + 1] - sorted[lo])
            } else {
                sorted[lo]
            }
        }
    }
}

/// Every check (by identifier) in `runs` (each a seed and its checks), in the order the first seed
/// lists them, summarised over the seeds.
pub fn summarize(runs: &[(u64, Vec<Check>)]) -> Vec<CheckSweep> {
    let mut names: Vec<&Check> = Vec::new();
    for (_, checks) in runs {
        for c in checks {
            if !names.iter().any(|n| n.id == c.id) {
                names.push(c);
            }
        }
    }
    names
        .into_iter()
        .map(|first| {
            let mut values = Vec::new();
            let mut s = CheckSweep {
                id: first.id.clone(),
                name: first.name.clone(),
                relation: first.relation,
                limit: first.limit,
                kind: first.kind,
                runs: 0,
                passes: 0,
                pass_rate: 0.0,
                pass_rate_wilson_95: [0.0, 1.0],
                non_finite: 0,
                median: f64::NAN,
                p90: f64::NAN,
                worst: f64::NAN,
                worst_seed: 0,
                failed_seeds: Vec::new(),
            };
            let mut worst: Option<(f64, u64)> = None;
            let mut first_non_finite = None;
            for (seed, checks) in runs {
                let Some(c) = checks.iter().find(|c| c.id == first.id) else {
                    continue;
                };
                s.runs += 1;
                if c.pass && c.value.is_finite() {
                    s.passes += 1;
                } else {
                    s.failed_seeds.push(*seed);
                }
                if !c.value.is_finite() {
                    s.non_finite += 1;
                    first_non_finite.get_or_insert(*seed);
                    continue;
                }
                values.push(c.value);
                let worse = match (worst, first.relation) {
                    (None, _) => true,
                    (Some((w, _)), Relation::AtMost) => c.value > w,
                    (Some((w, _)), Relation::AtLeast) => c.value < w,
                };
                if worse {
                    worst = Some((c.value, *seed));
                }
            }
            values.sort_by(f64::total_cmp);
            s.pass_rate = if s.runs > 0 {
                s.passes as f64 / s.runs as f64
            } else {
                0.0
            };
            s.pass_rate_wilson_95 = wilson_95(s.passes, s.runs);
            s.median = quantile(&values, 0.5);
            s.p90 = quantile(
                &values,
                match first.relation {
                    Relation::AtMost => 0.9,
                    Relation::AtLeast => 0.1,
                },
            );
            match (first_non_finite, worst) {
                (Some(seed), _) => (s.worst, s.worst_seed) = (f64::NAN, seed),
                (None, Some((w, seed))) => (s.worst, s.worst_seed) = (w, seed),
                (None, None) => {}
            }
            s
        })
        .collect()
}

/// Each check's figure over the seeds as value / limit (1: the limit; a check with a zero
/// limit is drawn as its value), one series per check.
pub fn figure(experiment: &str, runs: &[(u64, Vec<Check>)], sweeps: &[CheckSweep]) -> Figure {
    let series = sweeps
        .iter()
        .map(|s| Series {
            label: format!("{} ({} {})", s.name, s.relation.symbol(), s.limit),
            points: runs
                .iter()
                .filter_map(|(seed, checks)| {
                    let c = checks.iter().find(|c| c.id == s.id)?;
                    let y = if s.limit != 0.0 {
                        c.value / s.limit
                    } else {
                        c.value
                    };
                    y.is_finite().then_some([*seed as f64, y])
                })
                .collect(),
            markers: true,
        })
        .collect();
    Figure {
        title: format!("{experiment}: checks over seeds"),
        x_label: "seed".into(),
        log_x: false,
        panels: vec![Panel {
            x_label: None,
            y_label: "figure / limit".into(),
            series,
        }],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_between_ranks() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile(&v, 0.5), 3.0);
        assert_eq!(quantile(&v, 0.9), 4.6);
        assert_eq!(quantile(&v, 0.1), 1.4);
        assert_eq!(quantile(&v, 1.0), 5.0);
        assert_eq!(quantile(&[7.0], 0.9), 7.0);
        assert!(quantile(&[], 0.5).is_nan());
    }

    /// Wilson's interval against its closed form at 495 of 500 and the textbook 0 of 10
    /// (upper bound 0.2775).
    #[test]
    fn wilson_interval_matches_its_closed_form() {
        let [lo, hi] = wilson_95(495, 500);
        assert!(
            (lo - 0.976_80).abs() < 1e-4 && (hi - 0.995_72).abs() < 1e-4,
            "{lo} {hi}"
        );
        let [lo, hi] = wilson_95(0, 10);
        assert!(lo == 0.0 && (hi - 0.2775).abs() < 1e-4, "{hi}");
        assert_eq!(wilson_95(0, 0), [0.0, 1.0]);
    }

    /// Ten seeds of an "at most 1" check and an "at least 2" one: pass rates, worst in the
    /// failing direction with its seed, a NaN figure counted as a failure.
    #[test]
    fn a_sweep_reports_pass_rate_and_the_failing_tail() {
        let runs: Vec<(u64, Vec<Check>)> = (1..=10u64)
            .map(|seed| {
                let x = seed as f64 / 10.0; // 0.1 .. 1.0
                let y = if seed == 4 { f64::NAN } else { 2.0 + x };
                (
                    seed,
                    vec![
                        Check::at_most("error", "error", x * 1.05, 1.0),
                        Check::at_least("margin", "margin", y - 0.25, 2.0),
                    ],
                )
            })
            .collect();
        let s = summarize(&runs);
        assert_eq!(s.len(), 2);
        let e = &s[0];
        assert_eq!((e.runs, e.passes, e.non_finite), (10, 9, 0));
        assert_eq!(e.failed_seeds, [10]);
        assert!((e.pass_rate - 0.9).abs() < 1e-12);
        assert!((e.worst - 1.05).abs() < 1e-12 && e.worst_seed == 10);
        assert!((e.median - 0.55 * 1.05).abs() < 1e-12);
        assert!((e.p90 - 0.91 * 1.05).abs() < 1e-12);
        let m = &s[1];
        // Seeds 1 and 2 (1.85, 1.95) fail, and seed 4 is NaN.
        assert_eq!((m.runs, m.passes, m.non_finite), (10, 7, 1));
        assert_eq!(m.failed_seeds, [1, 2, 4]);
        assert!(m.worst.is_nan() && m.worst_seed == 4);
        assert!((m.p90 - (1.85 + 0.8 * 0.1)).abs() < 1e-12, "{}", m.p90);
        let f = figure("x", &runs, &s);
        assert_eq!(f.panels[0].series.len(), 2);
        assert_eq!(f.panels[0].series[1].points.len(), 9);
    }
}
