//! `afs bench`: latency and jitter against the machine's floor and the usual alternatives.
//!
//! * **hop**: ping-pong between this process (CPU 0) and a peer (`afs bench-peer`, CPU 1),
//!   both at normal priority (busy-polling at SCHED_FIFO would starve a 2-core machine), over
//!   five transports in interleaved rounds with the same sample count each: a shared-memory
//!   atomic ping-pong (the floor), afs's own services and message types through iceoryx2
//!   busy-polling (`WrenchSample` out, `ServoSample` back, the servo's sample gate on
//!   receipt), the same with iceoryx2 event wake-up, a bare iceoryx2 publish-subscribe pair of
//!   the same sizes with default settings, and a Unix-domain socket. Round trip measured by
//!   the initiator; one way (initiator → peer) from the timestamp in the ping, both processes
//!   reading the same `CLOCK_MONOTONIC`.
//! * **loop**: a stack runs surface-tracking while a bare absolute-time sleep loop runs beside
//!   its servo at the same SCHED_FIFO priority on the same core, half a period out of phase:
//!   both see the same machine at the same time.
//! * **stack**: the full graph's force-data age at use, servo wake latency and misses, without
//!   and with a CPU hog on the other core, and with a Foxglove client reading every topic of
//!   the live view (`afs run --foxglove`), in six alternating stack runs of half the duration.
//!
//! * **link**: the link board (docs/link.md): a servo sample's age on arrival on the same host
//!   and across the link, an estimator request's round trip across it and on one host, the
//!   servo's wake latency with the link and without; host B is a second prefix (not part of
//!   `all`: it needs `afs-link`, built with `--workspace`).
//!
//! Each part writes one `.hgrm` per series (HdrHistogram's percentile distribution) and a
//! percentile plot into `--out`, and reports p50 … max per series with its ratio to its floor,
//! every ratio from series measured in the same invocation.

mod hop;
mod link;
mod robot;
mod stack;
mod transport;
mod upstream;
mod world;

pub use transport::peer;

use crate::hist::{self, QuantilesUs, Summary};
use crate::tools::progress::Progress;
use crate::{ipc, rt};
use afs_shared::check::Check;
use anyhow::{Context, Result, bail};
use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Which part to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Part {
    /// Message hop latency between two processes.
    Hop,
    /// Servo wake jitter against a bare loop.
    Loop,
    /// The full graph, without and with a CPU hog.
    Stack,
    /// The link board: latency and loss across it (not part of `all`).
    Link,
    /// The world's step and the servo's wake, MuJoCo against the built-in plant (not part
    /// of `all`: it needs the feature `mujoco`).
    World,
    /// afs's FCI client holding the robot of `--config` (not part of `all`: it needs a robot).
    Robot,
    /// Hop, loop and stack.
    All,
}

impl Part {
    fn name(self) -> &'static str {
        match self {
            Part::Hop => "hop",
            Part::Loop => "loop",
            Part::Stack => "stack",
            Part::Link => "link",
            Part::World => "world",
            Part::Robot => "robot",
            Part::All => "all",
        }
    }

    fn includes(self, p: Part) -> bool {
        self == p || (self == Part::All && !matches!(p, Part::Link | Part::World | Part::Robot))
    }
}

/// What `afs bench` was asked.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Part(s) to run.
    pub part: Part,
    /// Seconds of measurement per part (the stack part runs twice this: without and with hog).
    pub duration_s: f64,
    /// Directory for histograms and plots.
    pub out: PathBuf,
    /// Prefix for the shared memory of the benchmark's stacks and services.
    pub prefix: String,
    /// A stack file with a `[robot]` table (the robot part).
    pub config: Option<PathBuf>,
}

/// The machine the benchmark ran on.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Machine {
    /// CPUs this process may run on.
    pub cpus: usize,
    /// Kernel release.
    pub kernel: String,
}

/// One measured series of a part.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SeriesReport {
    /// What was measured.
    pub what: String,
    /// Its percentiles (µs).
    pub summary_us: Summary,
    /// The series (or constant) it is compared with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub floor: Option<String>,
    /// Each percentile divided by the floor's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ratio_to_floor: Option<QuantilesUs>,
}

/// What every part reports: its series by name, its targets, the files it wrote.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PartReport {
    /// Series by name.
    pub series: BTreeMap<String, SeriesReport>,
    /// The limits, as target checks (a loaded machine may miss them).
    pub targets: Vec<Check>,
    /// `.hgrm` histograms and the percentile plot.
    pub files: Vec<String>,
}

/// The report of `afs bench` (documented in docs/bench.md).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BenchReport {
    /// Part asked for (`hop`, `loop`, `stack` or `all`).
    pub bench: String,
    /// Seconds of measurement per part.
    pub duration_s: f64,
    /// The machine.
    pub machine: Machine,
    /// Message hop latency.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hop: Option<hop::HopReport>,
    /// Servo wake latency against a bare loop.
    #[serde(rename = "loop", default, skip_serializing_if = "Option::is_none")]
    pub loop_part: Option<stack::LoopPart>,
    /// The full graph without and with a CPU hog.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stack: Option<stack::StackPart>,
    /// The link board.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<link::LinkPart>,
    /// The world's step and the servo's wake on MuJoCo and on the built-in plant.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world: Option<world::WorldPart>,
    /// afs's FCI client on a robot.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<robot::RobotPart>,
    /// Wall time (s).
    pub wall_s: f64,
    /// Stopped by Ctrl-C.
    pub interrupted: bool,
}

impl BenchReport {
    /// The parts run, by name.
    pub fn parts(&self) -> Vec<(&'static str, &PartReport)> {
        let mut v = Vec::new();
        if let Some(h) = &self.hop {
            v.push(("hop", &h.part));
        }
        if let Some(l) = &self.loop_part {
            v.push(("loop", &l.part));
        }
        if let Some(s) = &self.stack {
            v.push(("stack", &s.part));
        }
        if let Some(l) = &self.link {
            v.push(("link", &l.part));
        }
        if let Some(w) = &self.world {
            v.push(("world", &w.part));
        }
        if let Some(r) = &self.robot {
            v.push(("robot", &r.part));
        }
        v
    }
}

impl fmt::Display for BenchReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (name, part) in self.parts() {
            writeln!(f, "{name}:")?;
            writeln!(
                f,
                "  {:<28} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}  {:>9}",
                "series (µs)", "p50", "p90", "p99", "p99.9", "p99.99", "max", "p50/floor"
            )?;
            for (series, s) in &part.series {
                let q = &s.summary_us.quantiles;
                writeln!(
                    f,
                    "  {:<28} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2}  {:>9}",
                    series,
                    q.p50,
                    q.p90,
                    q.p99,
                    q.p99_9,
                    q.p99_99,
                    q.max,
                    s.ratio_to_floor
                        .map_or("-".to_string(), |r| format!("{:.2}", r.p50))
                )?;
            }
            for t in &part.targets {
                writeln!(f, "  {}", t.line())?;
            }
        }
        writeln!(f, "files in the --out directory; {:.1} s", self.wall_s)
    }
}

/// Runs the benchmark.
pub fn run(opts: &BenchOptions, stop: &AtomicBool) -> Result<BenchReport> {
    if !(opts.duration_s.is_finite() && opts.duration_s > 0.0 && opts.duration_s <= 3600.0) {
        bail!(
            "--duration {} must be a number of seconds in (0, 3600]",
            opts.duration_s
        );
    }
    ipc::check_prefix(&opts.prefix)?;
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("creating {}", opts.out.display()))?;
    let t0 = Instant::now();
    let stopped = || stop.load(Ordering::Relaxed);
    let parts = [
        Part::Hop,
        Part::Loop,
        Part::Stack,
        Part::Link,
        Part::World,
        Part::Robot,
    ];
    let progress = Progress::counting(
        &format!("afs bench {}", opts.part.name()),
        parts.iter().filter(|&&p| opts.part.includes(p)).count() as u64,
        "parts",
    );
    let hop = match opts.part.includes(Part::Hop) {
        true => Some(done(&progress, hop::hop(opts, stop)?)),
        false => None,
    };
    let loop_part = match opts.part.includes(Part::Loop) && !stopped() {
        true => Some(done(&progress, stack::jitter(opts, stop)?)),
        false => None,
    };
    let stack = match opts.part.includes(Part::Stack) && !stopped() {
        true => Some(done(&progress, stack::stack(opts, stop)?)),
        false => None,
    };
    let link = match opts.part.includes(Part::Link) && !stopped() {
        true => Some(done(&progress, link::link(opts, stop)?)),
        false => None,
    };
    let world = match opts.part.includes(Part::World) && !stopped() {
        true => Some(done(&progress, world::world_part(opts, stop)?)),
        false => None,
    };
    let robot = match opts.part.includes(Part::Robot) && !stopped() {
        true => Some(done(&progress, robot::robot_part(opts, stop)?)),
        false => None,
    };
    progress.finish();
    Ok(BenchReport {
        bench: opts.part.name().into(),
        duration_s: opts.duration_s,
        machine: Machine {
            cpus: rt::available_cpus(),
            kernel: crate::procfs::kernel_release().unwrap_or_default(),
        },
        hop,
        loop_part,
        stack,
        link,
        world,
        robot,
        wall_s: t0.elapsed().as_secs_f64(),
        interrupted: stopped(),
    })
}

/// A part done: counted in `progress`, its target checks tallied (read from its report, which
/// every part gives a `targets` list).
fn done<T: Serialize>(progress: &Progress, part: T) -> T {
    let targets: Vec<Check> = serde_json::to_value(&part)
        .ok()
        .and_then(|v| serde_json::from_value(v["targets"].clone()).ok())
        .unwrap_or_default();
    progress.run_done(&targets);
    part
}

/// A measured series.
struct Series {
    name: &'static str,
    what: &'static str,
    floor: Option<&'static str>,
    hist: Histogram<u64>,
}

/// A fixed floor (e.g. the sensor period) a series is compared with.
struct ConstFloor {
    name: &'static str,
    value_us: f64,
}

/// Writes every series' `.hgrm` and the percentile plot; returns the part's report.
fn finish_part(
    part: &str,
    series: &[Series],
    consts: &[ConstFloor],
    targets: Vec<Check>,
    out: &Path,
    title: &str,
) -> Result<PartReport> {
    let mut files = Vec::new();
    let mut map = BTreeMap::new();
    for s in series {
        let f = out.join(format!("{part}_{}.hgrm", s.name));
        hist::write_hgrm(&s.hist, &f)?;
        files.push(f.display().to_string());
        let sum = Summary::of(&s.hist);
        let (floor, ratio_to_floor) = match s.floor {
            Some(fl) => {
                if let Some(f) = series.iter().find(|x| x.name == fl) {
                    (
                        Some(fl.to_string()),
                        Some(sum.quantiles.ratio_to(&QuantilesUs::of(&f.hist))),
                    )
                } else if let Some(c) = consts.iter().find(|c| c.name == fl) {
                    (
                        Some(format!("{} ({:.3} µs)", c.name, c.value_us)),
                        Some(sum.quantiles.ratio_to(&QuantilesUs::constant(c.value_us))),
                    )
                } else {
                    (None, None)
                }
            }
            None => (None, None),
        };
        map.insert(
            s.name.to_string(),
            SeriesReport {
                what: s.what.into(),
                summary_us: sum,
                floor,
                ratio_to_floor,
            },
        );
    }
    let plot = out.join(format!("{part}.svg"));
    percentile_plot(series, &plot, title)?;
    files.push(plot.display().to_string());
    Ok(PartReport {
        series: map,
        targets,
        files,
    })
}

/// Latency against percentile ("nines" on the x axis), log scale, one line per series.
fn percentile_plot(series: &[Series], path: &Path, title: &str) -> Result<()> {
    use plotters::prelude::*;
    let lines: Vec<(&str, Vec<(f64, f64)>)> = series
        .iter()
        .filter(|s| !s.hist.is_empty())
        .map(|s| {
            let pts = (0..=50)
                .map(|k| {
                    let nines = k as f64 / 10.0;
                    let q = 1.0 - 10f64.powf(-nines);
                    (nines, (s.hist.value_at_quantile(q) as f64 / 1e3).max(0.01))
                })
                .collect();
            (s.name, pts)
        })
        .collect();
    let lo = lines
        .iter()
        .flat_map(|l| l.1.iter().map(|p| p.1))
        .fold(f64::INFINITY, f64::min)
        .max(0.01);
    let hi = lines
        .iter()
        .flat_map(|l| l.1.iter().map(|p| p.1))
        .fold(0.0, f64::max)
        .max(lo * 10.0);
    let root = SVGBackend::new(path, (900, 560)).into_drawing_area();
    let draw = || -> std::result::Result<(), Box<dyn std::error::Error>> {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(0f64..5f64, (lo * 0.8..hi * 1.25).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("percentile (nines: 1 = p90, 2 = p99, 3 = p99.9, 4 = p99.99)")
            .y_desc("latency (µs)")
            .draw()?;
        for (i, (name, pts)) in lines.iter().enumerate() {
            let c = Palette99::pick(i).to_rgba();
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))?
                .label(*name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))
}
