//! `afs`: the command-line front of the afs stack.
//!
//! ```text
//! afs experiment fig4.8 --out out --json     # deterministic in-process experiment
//! ```

use afs::experiment;
use afs_shared::experiments::{NAMES, Options};
use anyhow::Result;
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

/// Active force sensing (Ipri 1995): force-guided assembly with tuned dither.
#[derive(Parser)]
#[command(name = "afs", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
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
                Some(path) => experiment::load_config(path)?,
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
                println!("{}", serde_json::to_string_pretty(&v)?);
            }
            Ok(if all_passed {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(1)
            })
        }
    }
}

fn print_human(r: &serde_json::Value) {
    println!(
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
    if let Some(checks) = r["checks"].as_array() {
        for c in checks {
            println!(
                "  [{}] {}: {:.4} {} {}",
                if c["pass"].as_bool() == Some(true) {
                    "ok"
                } else {
                    "FAIL"
                },
                c["name"].as_str().unwrap_or(""),
                c["value"].as_f64().unwrap_or(f64::NAN),
                c["relation"].as_str().unwrap_or(""),
                c["limit"].as_f64().unwrap_or(f64::NAN),
            );
        }
    }
}
