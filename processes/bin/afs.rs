//! `afs`: the command-line front of the afs stack.
//!
//! ```text
//! afs experiment fig4.8 --out out --json     # deterministic in-process experiment
//! ```

use afs::supervisor;
use afs::tools::experiment;
use afs_shared::experiments::{NAMES, Options};
use afs_shared::faults::FaultKind;
use anyhow::Result;
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

/// `println!` that ignores a closed stdout (e.g. `afs messages | head`) instead of panicking.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($arg)*);
    }};
}

/// Active force sensing (Ipri 1995): force-guided assembly with tuned dither.
#[derive(Parser)]
#[command(name = "afs", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The options of `afs run` (and `afs chaos`).
#[derive(clap::Args)]
struct RunArgs {
    /// Stack file (processes, priorities, CPUs, restart policy, prefix); default: the
    /// built-in one (examples/stack.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// surface-tracking, corner, friction-suppression or friction-id.
    #[arg(long)]
    scenario: Option<String>,
    /// Simulated seconds (0: the scenario's own length).
    #[arg(long)]
    duration: Option<f64>,
    /// Stack prefix (isolates the shared memory of concurrent stacks).
    #[arg(long)]
    prefix: Option<String>,
    /// Seed of the sensor noise (`afs chaos`: also of the fault plan).
    #[arg(long)]
    seed: Option<u64>,
    /// Record every topic to this MCAP file (Foxglove opens it).
    #[arg(long)]
    record: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
    /// No progress line on stderr.
    #[arg(long)]
    quiet: bool,
}

/// Runs a stack (with faults if `chaos` is set) and prints its summary.
fn run_stack(a: RunArgs, chaos: Option<supervisor::ChaosOptions>) -> Result<ExitCode> {
    if let Some(d) = a.duration
        && !(d.is_finite() && d >= 0.0)
    {
        anyhow::bail!("--duration {d} must be a number of seconds ≥ 0");
    }
    let stop = afs::boards::stop_flag()?;
    let opts = supervisor::RunOptions {
        config: a.config,
        scenario: a.scenario,
        duration: a.duration,
        prefix: a.prefix,
        seed: a.seed,
        record: a.record,
        progress: !a.quiet,
        chaos,
    };
    let outcome = supervisor::run(&opts, &stop)?;
    if a.json {
        say!("{}", serde_json::to_string_pretty(&outcome.report)?);
    } else {
        print_run(&outcome.report);
    }
    Ok(if outcome.passed {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

#[derive(Subcommand)]
enum Command {
    /// Run one of the thesis's experiments in the deterministic lockstep simulation.
    ///
    /// Writes NAME.svg into --out and, with --json, prints one JSON object on stdout.
    /// Exits with status 1 if one of the experiment's acceptance checks fails.
    Experiment {
        /// friction-id, fig4.5, fig4.6, fig4.7, fig4.8, or all.
        name: String,
        /// Directory for the plot(s).
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Seed of the sensor noise and surface roughness.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print the report as one JSON object (an array for `all`).
        #[arg(long)]
        json: bool,
        /// fig4.6: use the six trials printed in the thesis.
        #[arg(long)]
        thesis_table: bool,
        /// TOML file overriding the default set-up (plant, surface, sensor, servo); the
        /// experiment's own settings apply on top.
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Print the byte layout of every message exchanged over iceoryx2 (docs/messages.md).
    Messages,
    /// Launch the process graph (servo, sensor, estimator) and run a scenario in real time.
    ///
    /// Ends with a summary (one JSON object with --json): the scenario's figures, the same
    /// scenario's lockstep reference and their agreement, the servo loop's statistics.
    /// Exits with status 1 if a check fails, 2 on an error; Ctrl-C stops the stack in order.
    Run {
        #[command(flatten)]
        run: RunArgs,
    },
    /// Run a scenario on the process graph while injecting faults into it.
    ///
    /// Kills (SIGKILL) the servo, sensor and estimator at random moments, also while the
    /// servo dithers to probe the tangent and while the estimator holds a request; freezes
    /// (SIGSTOP) the sensor and the estimator; sends bursts of bad force samples (NaN,
    /// infinite, absurd, repeated, backwards, from the future). The summary adds each fault's
    /// recovery, the safe-state latency, the largest normal force, the bad samples sent and
    /// counted, and shared and resident memory before and after (docs/reliability.md).
    /// Exits with status 1 if a check fails, 2 on an error.
    Chaos {
        #[command(flatten)]
        run: RunArgs,
        /// Number of faults, spread over the run (between 1 s in and 1 s before the end), each
        /// given the time it needs; a plan that cannot fit is refused, naming the shortest run
        /// that holds it.
        #[arg(long, default_value_t = 10)]
        kills: usize,
        /// Fault kinds to draw from, comma-separated (default: all the scenario allows):
        /// kill-servo, kill-sensor, kill-estimator, kill-servo-mid-probe,
        /// kill-sensor-mid-probe, kill-estimator-mid-request, freeze-servo, freeze-sensor,
        /// freeze-estimator, bad-samples. The mid-probe and mid-request kinds ask the servo for
        /// a tangent probe when due: surface-tracking and corner only.
        #[arg(long, value_delimiter = ',')]
        faults: Vec<String>,
        /// Take the --faults kinds in turn, in the order given, instead of at random.
        #[arg(long)]
        in_turn: bool,
    },
    /// Show a running stack's processes, health and loop statistics.
    Status {
        /// Stack prefix.
        #[arg(long, default_value = "afs")]
        prefix: String,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Measure latency and jitter against the machine's floor and the usual alternatives.
    ///
    /// hop: message round trip and one-way latency between two processes over iceoryx2 (afs's
    /// services, busy-poll and event wake-up; bare iceoryx2), against a shared-memory atomic
    /// ping-pong (the floor) and a Unix socket, in interleaved rounds. loop: the servo's wake
    /// latency against a bare absolute-time loop at the same priority on the same core, at the
    /// same time. stack: force age at use and servo wake latency, without and with a CPU hog.
    /// Writes .hgrm histograms and SVG percentile plots into --out.
    Bench {
        /// hop, loop, stack or all.
        #[arg(value_enum, default_value = "all")]
        part: afs::tools::bench::Part,
        /// Seconds of measurement per part (stack: this much without and with the hog).
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// Directory for histograms and plots.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Prefix of the benchmark's shared memory (suffixed per part).
        #[arg(long, default_value = "bench")]
        prefix: String,
        /// Print the report as one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// The other end of `afs bench hop` (started by it).
    #[command(hide = true)]
    BenchPeer {
        #[arg(long)]
        prefix: String,
        #[arg(long)]
        socket: PathBuf,
        #[arg(long)]
        cpu: Option<usize>,
    },
    /// Draw the force, position and dither histories of a recording (SVG).
    Plot {
        /// The MCAP file from `afs run --record`.
        file: PathBuf,
        /// Output SVG (default: next to the recording).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Export a recording as one CSV file per topic.
    Export {
        /// The MCAP file from `afs run --record`.
        file: PathBuf,
        /// Directory for the CSV files.
        #[arg(long, default_value = "out/csv")]
        out: PathBuf,
    },
}

fn main() -> ExitCode {
    match run() {
        Ok(code) => code,
        Err(e) => {
            eprintln!("afs: error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run() -> Result<ExitCode> {
    let cli = Cli::parse();
    match cli.command {
        Command::Experiment {
            name,
            out,
            seed,
            json,
            thesis_table,
            config,
        } => {
            let base = match &config {
                Some(path) => afs::boards::load_config(path)?,
                None => Default::default(),
            };
            let opts = Options {
                seed,
                thesis_table,
                base,
            };
            let names: Vec<&str> = if name == "all" {
                NAMES.to_vec()
            } else {
                vec![name.as_str()]
            };
            let mut reports = Vec::new();
            let mut all_passed = true;
            for n in names {
                let (report, passed) = experiment::run(n, &opts, &out)?;
                all_passed &= passed;
                if !json {
                    print_human(&report);
                }
                reports.push(report);
            }
            if json {
                let v = if reports.len() == 1 {
                    reports.pop().unwrap_or_default()
                } else {
                    serde_json::Value::Array(reports)
                };
                say!("{}", serde_json::to_string_pretty(&v)?);
            }
            Ok(if all_passed {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(1)
            })
        }
        Command::Run { run } => run_stack(run, None),
        Command::Chaos {
            run,
            kills,
            faults,
            in_turn,
        } => {
            // None given: every kind the scenario allows (the supervisor decides).
            let kinds = faults
                .iter()
                .map(|f| FaultKind::from_name(f.trim()).map_err(anyhow::Error::msg))
                .collect::<Result<Vec<_>>>()?;
            let seed = run.seed.unwrap_or(1);
            run_stack(
                run,
                Some(supervisor::ChaosOptions {
                    faults: kills,
                    seed,
                    kinds,
                    in_turn,
                }),
            )
        }
        Command::Status { prefix, json } => {
            let v = supervisor::status(&prefix, std::time::Duration::from_secs(2))?;
            if json {
                say!("{}", serde_json::to_string_pretty(&v)?);
            } else {
                print_status(&v);
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Plot { file, out } => {
            let fig = afs::tools::record::figure(&file)?;
            let out = out.unwrap_or_else(|| file.with_extension("svg"));
            afs::tools::plot::render(&fig, &out)?;
            say!("wrote {}", out.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Export { file, out } => {
            for f in afs::tools::record::export_csv(&file, &out)? {
                say!("wrote {}", f.display());
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench {
            part,
            duration,
            out,
            prefix,
            json,
        } => {
            let stop = afs::boards::stop_flag()?;
            let opts = afs::tools::bench::BenchOptions {
                part,
                duration_s: duration,
                out,
                prefix,
            };
            let r = afs::tools::bench::run(&opts, &stop)?;
            if json {
                say!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                print_bench(&r);
            }
            Ok(if r["interrupted"] == true {
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            })
        }
        Command::BenchPeer {
            prefix,
            socket,
            cpu,
        } => {
            afs::tools::bench::peer(&prefix, &socket, cpu)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Messages => {
            for l in afs_shared::msg::layouts() {
                say!("{}", l.markdown());
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// The `checks` of a report, one line each.
fn print_checks(r: &serde_json::Value) {
    let num = |v: &serde_json::Value| match v.as_f64() {
        Some(x) if x.fract() == 0.0 && x.abs() < 1e15 => format!("{x:.0}"),
        Some(x) => format!("{x:.4}"),
        None => v.to_string(),
    };
    for c in r["checks"].as_array().into_iter().flatten() {
        say!(
            "  [{}] {}{}: {} {} {}",
            if c["pass"] == true { "ok" } else { "FAIL" },
            if c["kind"] == "target" {
                "(target) "
            } else {
                ""
            },
            c["name"].as_str().unwrap_or(""),
            num(&c["value"]),
            c["relation"].as_str().unwrap_or(""),
            num(&c["limit"]),
        );
    }
}

fn print_bench(r: &serde_json::Value) {
    for part in ["hop", "loop", "stack"] {
        let Some(series) = r[part]["series"].as_object() else {
            continue;
        };
        say!("{part}:");
        say!(
            "  {:<28} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}  {:>9}",
            "series (µs)",
            "p50",
            "p90",
            "p99",
            "p99.9",
            "p99.99",
            "max",
            "p50/floor"
        );
        for (name, v) in series {
            let s = &v["summary_us"];
            let f = |k: &str| s[k].as_f64().unwrap_or(f64::NAN);
            say!(
                "  {:<28} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2}  {:>9}",
                name,
                f("p50"),
                f("p90"),
                f("p99"),
                f("p99_9"),
                f("p99_99"),
                f("max"),
                v["ratio_to_floor"]["p50"]
                    .as_f64()
                    .map_or("-".to_string(), |x| format!("{x:.2}"))
            );
        }
        if let Some(ts) = r[part]["targets"].as_array() {
            for t in ts {
                say!(
                    "  target: {} = {:.3} {} {} → {}",
                    t["name"].as_str().unwrap_or("?"),
                    t["value"].as_f64().unwrap_or(f64::NAN),
                    t["relation"].as_str().unwrap_or("?"),
                    t["limit"],
                    if t["met"] == true { "met" } else { "NOT met" }
                );
            }
        }
    }
    say!(
        "files in the --out directory; {:.1} s",
        r["wall_s"].as_f64().unwrap_or(0.0)
    );
}

fn print_human(r: &serde_json::Value) {
    say!(
        "{}: {} (plot {}, {:.1} s simulated in {:.2} s CPU)",
        r["experiment"].as_str().unwrap_or("?"),
        if r["passed"].as_bool() == Some(true) {
            "PASS"
        } else {
            "FAIL"
        },
        r["plot"].as_str().unwrap_or("?"),
        r["timing"]["simulated_s"].as_f64().unwrap_or(0.0),
        r["timing"]["cpu_s"].as_f64().unwrap_or(0.0),
    );
    print_checks(r);
}

fn print_run(r: &serde_json::Value) {
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    say!(
        "{} on prefix '{}': {} ({:.1} s simulated in {:.1} s)",
        r["scenario"].as_str().unwrap_or("?"),
        r["prefix"].as_str().unwrap_or("?"),
        if r["passed"].as_bool() == Some(true) {
            "PASS"
        } else {
            "FAIL"
        },
        f(&r["stack"]["duration_s"]),
        f(&r["wall_s"]),
    );
    let t = &r["stack"]["tracking"];
    let rt = &r["reference"]["tracking"];
    say!(
        "  tangent error RMS {:.3}° (lockstep {:.3}°), force deviation RMS {:.3} (lockstep {:.3}), travelled {:.1} mm, estimates {}",
        f(&t["tangent_error_rms_deg"]),
        f(&rt["tangent_error_rms_deg"]),
        f(&t["normal_deviation_rms"]),
        f(&rt["normal_deviation_rms"]),
        f(&t["travelled_m"]) * 1e3,
        t["estimations"]["estimates"]
    );
    if let Some(fr) = r["stack"]["friction"].as_object() {
        say!(
            "  friction {:.3} N before tuning, {:.1} % of it at the end, Aω {:.1} mm/s",
            fr["start_mean_n"].as_f64().unwrap_or(f64::NAN),
            100.0 * fr["end_ratio"].as_f64().unwrap_or(f64::NAN),
            1e3 * fr["settled_a_omega_m_per_s"].as_f64().unwrap_or(f64::NAN)
        );
    }
    let l = &r["loop"];
    if l.is_object() {
        say!(
            "  servo: {} ticks, {} misses; wake jitter p50/p99/p99.9/max {:.1}/{:.1}/{:.1}/{:.1} µs; force age p50/p99/p99.9 {:.0}/{:.0}/{:.0} µs; SCHED_FIFO {}",
            l["ticks"],
            l["misses"],
            f(&l["wake_jitter_us"]["p50"]),
            f(&l["wake_jitter_us"]["p99"]),
            f(&l["wake_jitter_us"]["p99_9"]),
            f(&l["wake_jitter_us"]["max"]),
            f(&l["force_age_us"]["p50"]),
            f(&l["force_age_us"]["p99"]),
            f(&l["force_age_us"]["p99_9"]),
            l["sched_fifo"]
        );
    }
    if let Some(p) = r["processes"].as_array() {
        for x in p {
            say!(
                "  {}: {} restarts{}",
                x["name"].as_str().unwrap_or("?"),
                x["restarts"],
                if x["gave_up"].as_bool() == Some(true) {
                    ", gave up"
                } else {
                    ""
                }
            );
        }
    }
    if let Some(c) = r["chaos"].as_object() {
        say!(
            "  faults: {} of {} injected; back after a kill (max ms): servo {}, sensor {}, estimator {}; beyond the backoff at most {} ms",
            c["injected"],
            c["planned"],
            c["back_after_kill"]["servo"]["max_ms"],
            c["back_after_kill"]["sensor"]["max_ms"],
            c["back_after_kill"]["estimator"]["max_ms"],
            c["back_beyond_backoff_ms_max"],
        );
    }
    let fl = &r["faults"];
    if fl.is_object() {
        say!(
            "  safe state: {} entries, worst {:.2} ms after the last good force sample; largest normal force {:.2} N ({:.2}× preload)",
            fl["safe_entries"],
            f(&fl["safe_after_last_good_ms_max"]),
            f(&fl["normal_force_max_n"]),
            f(&fl["normal_force_max_over_preload"]),
        );
    }
    print_checks(r);
}

fn print_status(v: &serde_json::Value) {
    say!("stack '{}'", v["prefix"].as_str().unwrap_or("?"));
    if let Some(s) = v["supervisor"].as_object() {
        say!(
            "  supervisor pid {}: {} at {:.1}/{:.1} s",
            s["pid"],
            s["scenario"].as_str().unwrap_or("?"),
            s["elapsed_s"].as_f64().unwrap_or(0.0),
            s["duration_s"].as_f64().unwrap_or(0.0)
        );
    }
    if let Some(ps) = v["processes"].as_array() {
        for p in ps {
            say!(
                "  {:<10} pid {:<7} {:<10} restarts {}",
                p["name"].as_str().unwrap_or("?"),
                p["pid"],
                p["state"].as_str().unwrap_or("?"),
                p["restarts"]
            );
        }
    }
    let l = &v["loop"];
    if l.is_object() {
        say!(
            "  servo loop: {} ticks, {} misses, wake jitter p99 {:.1} µs, force age p99 {:.0} µs, safe entries {}",
            l["ticks"],
            l["misses"],
            l["wake_jitter_us"]["p99"].as_f64().unwrap_or(f64::NAN),
            l["force_age_us"]["p99"].as_f64().unwrap_or(f64::NAN),
            l["safe_entries"]
        );
    }
}
