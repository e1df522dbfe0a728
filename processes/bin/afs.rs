//! `afs`: the command-line front of the afs stack.
//!
//! ```text
//! afs experiment fig4.8 --out out --json     # deterministic in-process experiment
//! ```

use afs::supervisor;
use afs::tools::experiment::{self, ExperimentArgs};
use afs_shared::faults::FaultKind;
use anyhow::{Context, Result};
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

/// Prints a report's text form (which ends its own lines), ignoring a closed stdout.
macro_rules! show {
    ($report:expr) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stdout().lock(), "{}", $report);
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
    /// surface-tracking, corner, friction-suppression, friction-id or insertion.
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
    /// The servo rate (Hz): 10000 (the thesis's rig), 1000 (Franka FCI), 500 (UR e-Series);
    /// the stack file's `[sim.servo] rate_hz`, as `afs experiment --rate-hz`.
    #[arg(long, value_name = "HZ")]
    rate_hz: Option<f64>,
    /// The world the servo drives: `builtin` or `mujoco` (`[sim.world] kind`), as `afs
    /// experiment --plant`.
    #[arg(long, value_parser = ["builtin", "mujoco"])]
    plant: Option<String>,
    /// A MuJoCo model of your own arm (implies --plant mujoco; `[sim.world] mjcf`), as `afs
    /// experiment --mjcf` (docs/mujoco.md, *Your own arm*).
    #[arg(long, value_name = "FILE")]
    mjcf: Option<PathBuf>,
    /// Wall time the run may take (s) before the supervisor stops it and fails it (check
    /// `reached_end`); default: the stack file's `wall_limit_s`, or 1.5 × the duration + 30 s.
    #[arg(long, value_name = "S")]
    wall_limit_s: Option<f64>,
    /// Record every topic to this MCAP file (Foxglove opens it).
    #[arg(long)]
    record: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
    /// No progress line on stderr.
    #[arg(long)]
    quiet: bool,
    /// Serve a live view to Foxglove or Lichtblick on HOST:PORT (default 127.0.0.1:8765;
    /// port 0 picks a free one). The address is printed on stderr; open it with
    /// examples/foxglove-layout.json.
    #[arg(long, value_name = "HOST:PORT", num_args = 0..=1, default_missing_value = afs::observe::view::DEFAULT_ADDR)]
    foxglove: Option<String>,
    /// Rate of each high-rate stream in the live view (world, controller, force, /live), Hz.
    #[arg(long, value_name = "HZ", default_value_t = 100.0)]
    foxglove_hz: f64,
}

/// Runs a stack (with faults if `chaos` is set) and prints its summary.
fn run_stack(a: RunArgs, chaos: Option<afs::stack::ChaosOptions>) -> Result<ExitCode> {
    if let Some(d) = a.duration
        && !(d.is_finite() && d >= 0.0)
    {
        anyhow::bail!("--duration {d} must be a number of seconds ≥ 0");
    }
    let foxglove = a
        .foxglove
        .as_deref()
        .map(|addr| afs::observe::view::ViewSettings::parse(addr, a.foxglove_hz))
        .transpose()?;
    let stop = afs::boards::stop_flag()?;
    let opts = afs::stack::RunOptions {
        config: a.config,
        scenario: a.scenario,
        duration: a.duration,
        prefix: a.prefix,
        seed: a.seed,
        sim: afs::stack::SimOverrides {
            rate_hz: a.rate_hz,
            plant: a.plant,
            mjcf: a.mjcf,
        },
        wall_limit_s: a.wall_limit_s,
        record: a.record,
        progress: !a.quiet,
        chaos,
        foxglove,
    };
    let report = supervisor::run(&opts, &stop)?;
    if a.json {
        say!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        show!(report);
    }
    Ok(if report.passed {
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
    Experiment(ExperimentArgs),
    /// Print the byte layout of every message exchanged over iceoryx2 (docs/messages.md).
    Messages {
        /// Print each message's line of the wire-compatibility table instead
        /// (`name version size fingerprint`, shared/src/msg/versions.txt).
        #[arg(long)]
        table: bool,
    },
    /// Print the iceoryx2 config that lets the upstream `iox2` CLI (iceoryx2-cli 0.10) and any
    /// iceoryx2 program see a running stack, or write it as DIR/config/iceoryx2.toml
    /// (docs/stack.md, *Inspecting a stack with iox2*).
    #[command(name = "iox2-config")]
    Iox2Config {
        /// The stack's prefix.
        #[arg(long, default_value = "afs")]
        prefix: String,
        /// Write DIR/config/iceoryx2.toml (iceoryx2 reads it from the working directory)
        /// instead of printing the config.
        #[arg(long, value_name = "DIR")]
        write: Option<PathBuf>,
    },
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
    /// infinite, absurd, repeated, backwards, from the future); kills the link board and cuts
    /// the link to another host. The summary adds each fault's
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
        /// Fault kinds to draw from, comma-separated (default: all the scenario and the stack
        /// file allow): kill-servo, kill-sensor, kill-estimator, kill-servo-mid-probe,
        /// kill-sensor-mid-probe, kill-estimator-mid-request, freeze-servo, freeze-sensor,
        /// freeze-estimator, bad-samples, kill-link, cut-link. The mid-probe and mid-request
        /// kinds ask the servo for a tangent probe when due: surface-tracking and corner only.
        /// kill-link needs the link board (a process named `link`), cut-link also the
        /// commands that cut and restore the link (the stack file's [chaos] table,
        /// docs/link.md).
        #[arg(long, value_delimiter = ',')]
        faults: Vec<String>,
        /// Take the --faults kinds in turn, in the order given, instead of at random.
        #[arg(long)]
        in_turn: bool,
    },
    /// Stream a force/torque sensor speaking ATI's RDT over UDP (an ATI Net F/T, Axia80, or
    /// `afs-netft`) onto a prefix's wrench topic, for any client, and report its rate, loss,
    /// reordering and receive jitter (docs/sensor.md).
    ///
    /// Exits with status 2 and says why if the device does not answer, answers with datagrams
    /// that are not RDT records, or streams to another client.
    Sensor {
        #[command(flatten)]
        rdt: afs::boards::sensor::rdt::RdtArgs,
        /// The device's internal sample rate (Hz): the rate of its sample counter.
        #[arg(long, default_value_t = 7000.0)]
        rate_hz: f64,
        /// Prefix whose wrench topic gets the samples.
        #[arg(long, default_value = "afs")]
        prefix: String,
        /// Seconds to stream after the first record (0: until Ctrl-C).
        #[arg(long, default_value_t = 0.0)]
        duration: f64,
        /// Record the samples to this MCAP file.
        #[arg(long)]
        record: Option<PathBuf>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Record a running stack's streams to an MCAP file (the topics of `afs run --record`),
    /// from this host or from another one that its link board reaches (docs/link.md), until the
    /// stack stops, --duration passes or Ctrl-C. Reports the servo stream's gaps (sequence
    /// numbers that did not arrive), one JSON object with --json.
    Record {
        /// The stack's prefix.
        #[arg(long, default_value = "afs")]
        prefix: String,
        /// The MCAP file to write.
        #[arg(long)]
        out: PathBuf,
        /// Stop after this many seconds (0: when the stack stops).
        #[arg(long, default_value_t = 0.0)]
        duration: f64,
        /// Print the summary as one JSON object.
        #[arg(long)]
        json: bool,
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
    /// Attach a live view to a running stack: a Foxglove WebSocket server publishing its
    /// topics (the recording's topics and schemas), until the stack ends or Ctrl-C.
    ///
    /// Reads the stack's streams like any subscriber (the supervisor's `--foxglove` reads
    /// the samples it already has instead). Prints the address on stderr, and a summary at
    /// the end (one JSON object with --json).
    View {
        /// The stack's prefix.
        #[arg(long, default_value = "afs")]
        prefix: String,
        /// Address to serve on (port 0 picks a free one).
        #[arg(long, value_name = "HOST:PORT", default_value = afs::observe::view::DEFAULT_ADDR)]
        foxglove: String,
        /// Rate of each high-rate stream (Hz).
        #[arg(long, value_name = "HZ", default_value_t = 100.0)]
        foxglove_hz: f64,
        /// Print the summary as one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Measure latency and jitter against the machine's floor and the usual alternatives.
    ///
    /// hop: message round trip and one-way latency between two processes over iceoryx2 (afs's
    /// services, busy-poll and event wake-up; bare iceoryx2), against a shared-memory atomic
    /// ping-pong (the floor) and a Unix socket, in interleaved rounds. loop: the servo's wake
    /// latency against a bare absolute-time loop at the same priority on the same core, at the
    /// same time. stack: force age at use and servo wake latency, without and with a CPU hog, and with a
    /// Foxglove client on the live view (their wake p99 ratio). link: a servo sample's age on
    /// arrival on one host and across the link board to a second prefix, an estimator request's
    /// round trip across it, the servo's wake latency with the link and without (docs/link.md;
    /// needs afs-link, not part of all). world: MuJoCo's step against the built-in plant's
    /// (docs/mujoco.md). robot: afs's FCI client holding the robot of --config's [robot] table,
    /// from a state received to its command sent (docs/franka.md; not part of all).
    /// Writes .hgrm histograms and SVG percentile plots into --out.
    Bench {
        /// hop, loop, stack, link, world, robot or all (hop, loop and stack).
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
        /// robot: a stack file with a [robot] table (docs/franka.md).
        #[arg(long)]
        config: Option<PathBuf>,
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
    /// Draw the process graph of a stack (SVG): the boards, the supervisor, the link board and
    /// the clients, and the iceoryx2 services each one writes and reads (the README's picture).
    Graph {
        /// Output SVG.
        #[arg(long, default_value = "docs/stack.svg")]
        out: PathBuf,
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

/// Prints `r` as one JSON object with `json`, else as text.
fn print<R: serde::Serialize + std::fmt::Display>(r: &R, json: bool) -> Result<()> {
    if json {
        say!("{}", serde_json::to_string_pretty(r)?);
    } else {
        show!(r);
    }
    Ok(())
}

fn run() -> Result<ExitCode> {
    let cli = Cli::parse();
    match cli.command {
        Command::Experiment(a) => experiment::command(&a, &*afs::boards::stop_flag()?),
        Command::Run { run } => run_stack(run, None),
        Command::Chaos {
            run,
            kills,
            faults,
            in_turn,
        } => chaos(run, kills, &faults, in_turn),
        Command::View {
            prefix,
            foxglove,
            foxglove_hz,
            json,
        } => {
            let settings = afs::observe::view::ViewSettings::parse(&foxglove, foxglove_hz)?;
            let stop = afs::boards::stop_flag()?;
            print(&afs::observe::view::attach(&prefix, settings, &stop)?, json)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Record {
            prefix,
            out,
            duration,
            json,
        } => {
            let stop = afs::boards::stop_flag()?;
            let r = afs::observe::record::record_stack(&prefix, &out, duration, &stop)?;
            print(&r, json)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Status { prefix, json } => {
            let status = supervisor::status(&prefix, std::time::Duration::from_secs(2))?;
            print(&status, json)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Sensor {
            rdt,
            rate_hz,
            prefix,
            duration,
            record,
            json,
        } => {
            let stop = afs::boards::stop_flag()?;
            let opts = afs::tools::sensor::SensorOptions {
                rdt: rdt.settings(rate_hz)?,
                prefix,
                duration_s: duration,
                record,
                answer_within_s: 1.0,
            };
            print(&afs::tools::sensor::run(&opts, &stop)?, json)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Graph { out } => {
            afs::tools::graph::render(&out)?;
            say!("wrote {}", out.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Plot { file, out } => {
            let fig = afs::observe::record::figure(&file)?;
            let out = out.unwrap_or_else(|| file.with_extension("svg"));
            afs::tools::plot::render(&fig, &out)?;
            say!("wrote {}", out.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Export { file, out } => {
            for f in afs::observe::record::export_csv(&file, &out)? {
                say!("wrote {}", f.display());
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench {
            part,
            duration,
            out,
            prefix,
            config,
            json,
        } => {
            let stop = afs::boards::stop_flag()?;
            let opts = afs::tools::bench::BenchOptions {
                part,
                duration_s: duration,
                out,
                prefix,
                config,
            };
            let report = afs::tools::bench::run(&opts, &stop)?;
            print(&report, json)?;
            Ok(if report.interrupted {
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
        Command::Iox2Config { prefix, write } => iox2_config(&prefix, write.as_deref()),
        Command::Messages { table } => {
            for l in afs_shared::msg::layouts() {
                if !table {
                    say!("{}", l.markdown());
                } else if l.version.is_some() {
                    say!("{}", l.table_line());
                }
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// `afs chaos`: the run with `kills` faults of the kinds named (none: every kind the stack
/// and scenario allow, the supervisor decides).
fn chaos(run: RunArgs, kills: usize, faults: &[String], in_turn: bool) -> Result<ExitCode> {
    let kinds = faults
        .iter()
        .map(|f| FaultKind::from_name(f.trim()).map_err(anyhow::Error::msg))
        .collect::<Result<Vec<_>>>()?;
    let seed = run.seed.unwrap_or(1);
    run_stack(
        run,
        Some(afs::stack::ChaosOptions {
            faults: kills,
            seed,
            kinds,
            in_turn,
        }),
    )
}

/// `afs iox2-config`: the stack's iceoryx2 config, printed or written as
/// DIR/config/iceoryx2.toml.
fn iox2_config(prefix: &str, write: Option<&std::path::Path>) -> Result<ExitCode> {
    let text = afs::ipc::config_toml(prefix)?;
    match write {
        None => say!("{text}"),
        Some(dir) => {
            let conf = dir.join("config");
            std::fs::create_dir_all(&conf)
                .with_context(|| format!("creating {}", conf.display()))?;
            let file = conf.join("iceoryx2.toml");
            std::fs::write(&file, text).with_context(|| format!("writing {}", file.display()))?;
            say!(
                "wrote {}; run the iox2 CLI from {} (e.g. `cd {} && iox2 node list`)",
                file.display(),
                dir.display(),
                dir.display()
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
