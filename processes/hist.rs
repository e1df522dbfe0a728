//! Latency histograms (HdrHistogram) shared by the servo board and `afs bench`: saved in the
//! HdrHistogram V2 format (`.hdr`, readable by every HdrHistogram implementation), written as
//! the standard percentile distribution (`.hgrm`, which HdrHistogram's plotter reads), and
//! summarised as the percentiles the JSON reports carry.

use anyhow::{Context, Result};
pub use hdrhistogram::Histogram;
use hdrhistogram::serialization::{Deserializer, Serializer, V2Serializer};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// Largest value a histogram holds (ns); larger ones are recorded as this.
pub const MAX_NS: u64 = 1_000_000_000;

/// A histogram of nanoseconds from 1 ns to [`MAX_NS`], 3 significant digits.
pub fn new() -> Result<Histogram<u64>> {
    Histogram::<u64>::new_with_bounds(1, MAX_NS, 3).context("allocating a histogram")
}

/// Records `ns`, clamped into the histogram's range (never allocates).
pub fn record(h: &mut Histogram<u64>, ns: u64) {
    let _ = h.record(ns.clamp(1, MAX_NS));
}

/// A histogram's percentiles as the messages carry them (all 0 for an empty one).
pub fn quantiles(h: &Histogram<u64>) -> afs_shared::msg::Quantiles {
    if h.is_empty() {
        return afs_shared::msg::Quantiles::default();
    }
    afs_shared::msg::Quantiles {
        p50: h.value_at_quantile(0.5),
        p90: h.value_at_quantile(0.9),
        p99: h.value_at_quantile(0.99),
        p999: h.value_at_quantile(0.999),
        p9999: h.value_at_quantile(0.9999),
        max: h.max(),
    }
}

/// Saves `h` in the V2 format.
pub fn save(h: &Histogram<u64>, path: &Path) -> Result<()> {
    let mut buf = Vec::new();
    V2Serializer::new()
        .serialize(h, &mut buf)
        .context("encoding a histogram")?;
    std::fs::write(path, buf).with_context(|| format!("writing {}", path.display()))
}

/// Loads a histogram saved by [`save`].
pub fn load(path: &Path) -> Result<Histogram<u64>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    Deserializer::new()
        .deserialize(&mut bytes.as_slice())
        .with_context(|| format!("decoding the histogram {}", path.display()))
}

/// Writes the percentile distribution of `h` (values in µs) in HdrHistogram's `.hgrm` text.
pub fn write_hgrm(h: &Histogram<u64>, path: &Path) -> Result<()> {
    let mut out = String::from("       Value     Percentile TotalCount 1/(1-Percentile)\n\n");
    for v in h.iter_quantiles(5) {
        let q = v.quantile_iterated_to();
        let inv = if q < 1.0 {
            format!("{:14.2}", 1.0 / (1.0 - q))
        } else {
            format!("{:>14}", "inf")
        };
        out.push_str(&format!(
            "{:12.3} {:14.12} {:10} {inv}\n",
            v.value_iterated_to() as f64 / 1e3,
            q,
            v.count_since_last_iteration()
        ));
    }
    out.push_str(&format!(
        "#[Mean    = {:12.3}, StdDeviation   = {:12.3}]\n#[Max     = {:12.3}, Total count    = {:12}]\n",
        h.mean() / 1e3,
        h.stdev() / 1e3,
        h.max() as f64 / 1e3,
        h.len()
    ));
    let mut f =
        std::fs::File::create(path).with_context(|| format!("writing {}", path.display()))?;
    f.write_all(out.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

/// Percentiles of a latency distribution (µs): the servo's loop statistics, each benchmark
/// series, and ratios of two such.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct QuantilesUs {
    /// Median.
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub p50: f64,
    /// 90th percentile.
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub p90: f64,
    /// 99th percentile.
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub p99: f64,
    /// 99.9th percentile.
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub p99_9: f64,
    /// 99.99th percentile.
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub p99_99: f64,
    /// Largest.
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub max: f64,
}

impl QuantilesUs {
    /// The percentiles of `h` (ns values; all NaN when it is empty).
    pub fn of(h: &Histogram<u64>) -> Self {
        if h.is_empty() {
            return Self::constant(f64::NAN);
        }
        let q = |x: f64| h.value_at_quantile(x) as f64 / 1e3;
        Self {
            p50: q(0.5),
            p90: q(0.9),
            p99: q(0.99),
            p99_9: q(0.999),
            p99_99: q(0.9999),
            max: h.max() as f64 / 1e3,
        }
    }

    /// A fixed value at every percentile (a floor such as a sampling period), µs.
    pub fn constant(value_us: f64) -> Self {
        Self {
            p50: value_us,
            p90: value_us,
            p99: value_us,
            p99_9: value_us,
            p99_99: value_us,
            max: value_us,
        }
    }

    /// Each percentile divided by the floor's.
    pub fn ratio_to(&self, floor: &QuantilesUs) -> QuantilesUs {
        QuantilesUs {
            p50: self.p50 / floor.p50,
            p90: self.p90 / floor.p90,
            p99: self.p99 / floor.p99,
            p99_9: self.p99_9 / floor.p99_9,
            p99_99: self.p99_99 / floor.p99_99,
            max: self.max / floor.max,
        }
    }
}

impl From<&afs_shared::msg::Quantiles> for QuantilesUs {
    fn from(q: &afs_shared::msg::Quantiles) -> Self {
        let us = |v: u64| v as f64 / 1000.0;
        Self {
            p50: us(q.p50),
            p90: us(q.p90),
            p99: us(q.p99),
            p99_9: us(q.p999),
            p99_99: us(q.p9999),
            max: us(q.max),
        }
    }
}

/// A histogram's size and percentiles, as a benchmark series reports them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Values recorded.
    pub count: u64,
    /// Percentiles (µs).
    #[serde(flatten)]
    pub quantiles: QuantilesUs,
}

impl Summary {
    /// The summary of `h` (percentiles NaN when it is empty).
    pub fn of(h: &Histogram<u64>) -> Self {
        Self {
            count: h.len(),
            quantiles: QuantilesUs::of(h),
        }
    }
}
