//! The report of `afs run` and `afs chaos` (`--json` prints it; the tests read it back), its
//! checks, and its text summary.

use super::child::ExitRecord;
use super::watch::RunEnd;
pub use crate::boards::sensor::{RdtReport, SensorReport};
use crate::chaos::ChaosReport;
pub use crate::hist::QuantilesUs;
use crate::observe::record::RecordSummary;
use crate::stack::Timeline;
use afs_shared::check::{self, Check};
use afs_shared::faults::FaultFigures;
use afs_shared::join::SampleCounts;
use afs_shared::msg::{FrictionReport, FrictionStatus, LoopFlags, LoopStats};
use afs_shared::scenario::{Agreement, ScenarioReport};
pub use afs_shared::watchdog::GateCounters;
use serde::{Deserialize, Serialize};
use std::fmt;

/// The estimator requests the servo made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RequestCounts {
    /// Requests sent.
    pub requests: u64,
    /// Re-sent after a time-out.
    pub retries: u64,
    /// Answers received.
    pub answers: u64,
}

/// Commands the servo received.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CommandCounts {
    /// Received.
    pub received: u64,
    /// Refused (unknown version or code).
    pub refused: u64,
}

/// The servo loop's statistics (`LoopStats`, latencies in µs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct LoopReport {
    /// Ticks run.
    pub ticks: u64,
    /// Period (µs).
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub period_us: f64,
    /// Ticks that woke a whole period late or ran longer than one.
    pub misses: u64,
    /// Running at SCHED_FIFO.
    pub sched_fifo: bool,
    /// Memory locked.
    pub mlocked: bool,
    /// Pinned to a CPU.
    pub pinned: bool,
    /// Wake latency (µs).
    pub wake_jitter_us: QuantilesUs,
    /// Execution time of a tick (µs).
    pub exec_us: QuantilesUs,
    /// Age of the force data at use (µs).
    pub force_age_us: QuantilesUs,
    /// The gate's verdicts on every force sample (refused ones by reason, and accepted).
    pub bad_samples: GateCounters,
    /// Of those, the samples flagged as injected (`afs chaos`): received and judged.
    #[serde(default)]
    pub injected: GateCounters,
    /// Ticks whose newest force data was too old.
    pub stale_ticks: u64,
    /// Entries into the safe state.
    pub safe_entries: u64,
    /// Ticks in the safe state.
    pub safe_ticks: u64,
    /// Estimator requests.
    pub estimator: RequestCounts,
    /// Samples that could not be published.
    pub publish_failures: u64,
    /// Commands received.
    pub commands: CommandCounts,
}

impl From<&LoopStats> for LoopReport {
    fn from(s: &LoopStats) -> Self {
        Self {
            ticks: s.ticks,
            period_us: s.period_ns as f64 / 1000.0,
            misses: s.misses,
            sched_fifo: s.flags.contains(LoopFlags::SCHED_FIFO),
            mlocked: s.flags.contains(LoopFlags::MLOCKED),
            pinned: s.flags.contains(LoopFlags::PINNED),
            wake_jitter_us: (&s.wake_latency).into(),
            exec_us: (&s.exec).into(),
            force_age_us: (&s.force_age).into(),
            bad_samples: s.gate,
            injected: s.injected,
            stale_ticks: s.stale_ticks,
            safe_entries: s.safe_entries,
            safe_ticks: s.safe_ticks,
            estimator: RequestCounts {
                requests: s.requests,
                retries: s.retries,
                answers: s.answers,
            },
            publish_failures: s.publish_failures,
            commands: CommandCounts {
                received: s.commands,
                refused: s.bad_commands,
            },
        }
    }
}

/// The estimator's on-line friction identification (`FrictionReport`; null where not known).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FrictionIdReport {
    /// Steady windows used.
    pub windows: u64,
    /// Distinct speeds seen.
    pub speeds: u32,
    /// `mu` holds.
    pub mu_valid: bool,
    /// The eq. 4.5 coefficients hold.
    pub law_valid: bool,
    /// μ.
    pub mu: Option<f64>,
    /// Its standard deviation over the windows.
    pub mu_std: Option<f64>,
    /// F_t (N).
    pub kinetic_n: Option<f64>,
    /// F_v (N·s/m).
    pub viscous_n_s_per_m: Option<f64>,
    /// F_s (N).
    pub stribeck_n: Option<f64>,
    /// ẋ_s (m/s).
    pub stribeck_velocity_m_per_s: Option<f64>,
    /// RMS residual of the fit (N).
    pub rms_residual_n: Option<f64>,
}

impl From<&FrictionReport> for FrictionIdReport {
    fn from(f: &FrictionReport) -> Self {
        let num = |v: f64| v.is_finite().then_some(v);
        Self {
            windows: f.windows,
            speeds: f.speeds,
            mu_valid: f.status.contains(FrictionStatus::MU_VALID),
            law_valid: f.status.contains(FrictionStatus::LAW_VALID),
            mu: num(f.mu),
            mu_std: num(f.mu_std),
            kinetic_n: num(f.kinetic_n),
            viscous_n_s_per_m: num(f.viscous_n_s_per_m),
            stribeck_n: num(f.stribeck_n),
            stribeck_velocity_m_per_s: num(f.stribeck_velocity_m_per_s),
            rms_residual_n: num(f.rms_residual_n),
        }
    }
}

/// One process of the graph, as it went.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProcessReport {
    /// Its name in the stack file.
    pub name: String,
    /// Restarts.
    pub restarts: u32,
    /// Times the stall policy killed it.
    pub stalls_killed: u32,
    /// Ran out of restarts.
    pub gave_up: bool,
    /// Where its first start's time went.
    pub first_start: Timeline,
    /// Every end, with each restart's timeline.
    pub exits: Vec<ExitRecord>,
}

/// What the run left behind.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Cleanup {
    /// What the stack leaked: files of the prefix no live node owns (its own, or a dead
    /// process's), and any of its own processes' nodes still alive.
    pub left: Vec<String>,
    /// Clients still attached when the run ended (`afs view`, Python clients): their nodes
    /// and files are theirs, left alone.
    #[serde(default)]
    pub observers: Vec<crate::ipc::Observer>,
}

/// The report of `afs run` (and, with `chaos`, of `afs chaos`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunReport {
    /// Scenario.
    pub scenario: String,
    /// Stack prefix.
    pub prefix: String,
    /// Noise seed (and the fault plan's).
    pub seed: u64,
    /// Simulated seconds run.
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub duration_s: f64,
    /// The servo ran the scenario to its end.
    pub finished: bool,
    /// Stopped by Ctrl-C or SIGTERM.
    pub interrupted: bool,
    /// Why the run ended.
    pub end: RunEnd,
    /// Every check passed (and not interrupted).
    pub passed: bool,
    /// The checks.
    pub checks: Vec<Check>,
    /// The scenario's figures from the stack.
    pub stack: ScenarioReport,
    /// The same from the lockstep reference, replaying the stack's events.
    pub reference: ScenarioReport,
    /// How the two compare.
    pub agreement: Agreement,
    /// The servo loop's statistics (its last report).
    #[serde(rename = "loop")]
    pub loop_stats: Option<LoopReport>,
    /// The sensor board's statistics (its last report).
    pub sensor: Option<SensorReport>,
    /// The estimator's friction identification (its last report).
    pub friction: Option<FrictionIdReport>,
    /// World, controller and force samples counted.
    pub samples: SampleCounts,
    /// What the servo knew of its contact at the end: the stiffness its gains were derived
    /// for, its on-line fit (docs/contact.md). None if it left no snapshot.
    #[serde(default)]
    pub contact: Option<afs_shared::servo::ContactReport>,
    /// The processes.
    pub processes: Vec<ProcessReport>,
    /// The recording, if one was asked for.
    pub record: Option<RecordSummary>,
    /// The live view, if one was asked for.
    #[serde(default)]
    pub view: Option<crate::observe::view::ViewSummary>,
    /// What was left.
    pub cleanup: Cleanup,
    /// Safety figures (safe-state latency, normal force, non-finite forces).
    pub faults: FaultFigures,
    /// The faults injected (`afs chaos` only).
    pub chaos: Option<ChaosReport>,
    /// Wall time (s).
    #[serde(deserialize_with = "afs_shared::nan::or_null")]
    pub wall_s: f64,
}

impl RunReport {
    /// True when every check passed and the run was not interrupted.
    pub fn all_passed(checks: &[Check], interrupted: bool) -> bool {
        check::all_pass(checks) && !interrupted
    }
}

impl fmt::Display for RunReport {
    /// The text summary `afs run` prints.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{} on prefix '{}': {} ({:.1} s simulated in {:.1} s)",
            self.scenario,
            self.prefix,
            if self.passed { "PASS" } else { "FAIL" },
            self.stack.duration_s,
            self.wall_s,
        )?;
        let (t, rt) = (&self.stack.tracking, &self.reference.tracking);
        writeln!(
            f,
            "  tangent error RMS {:.3}° (lockstep {:.3}°), force deviation RMS {:.3} (lockstep {:.3}), travelled {:.1} mm, estimates {}",
            t.tangent_error_rms_deg,
            rt.tangent_error_rms_deg,
            t.normal_deviation_rms,
            rt.normal_deviation_rms,
            t.travelled_m * 1e3,
            t.estimations.estimates
        )?;
        if let Some(fr) = &self.stack.friction {
            writeln!(
                f,
                "  friction {:.3} N before tuning, {:.1} % of it at the end, Aω {:.1} mm/s",
                fr.start_mean_n,
                100.0 * fr.end_ratio,
                1e3 * fr.settled_a_omega_m_per_s
            )?;
        }
        if let Some(c) = &self.contact {
            let fit = match (c.fitted_n_per_m, c.fitted_std_error_n_per_m) {
                (Some(k), Some(e)) => format!("{:.3e} ± {:.1e} N/m", k, e),
                _ => "none".to_string(),
            };
            writeln!(
                f,
                "  contact: gains for {:.3e} N/m ({} adopted), fitted {fit}; β {:.3}, damping added {:.0} N·s/m",
                c.stiffness_in_use_n_per_m,
                c.adoptions,
                c.rate_feedforward,
                c.added_damping_n_s_per_m
            )?;
        }
        if let Some(l) = &self.loop_stats {
            writeln!(
                f,
                "  servo: {} ticks, {} misses; wake jitter p50/p99/p99.9/max {:.1}/{:.1}/{:.1}/{:.1} µs; force age p50/p99/p99.9 {:.0}/{:.0}/{:.0} µs; SCHED_FIFO {}",
                l.ticks,
                l.misses,
                l.wake_jitter_us.p50,
                l.wake_jitter_us.p99,
                l.wake_jitter_us.p99_9,
                l.wake_jitter_us.max,
                l.force_age_us.p50,
                l.force_age_us.p99,
                l.force_age_us.p99_9,
                l.sched_fifo
            )?;
        }
        if let Some(r) = self.sensor.as_ref().and_then(|s| s.rdt.as_ref()) {
            writeln!(f, "  sensor (RDT): {r}")?;
        }
        for p in &self.processes {
            writeln!(
                f,
                "  {}: {} restarts{}",
                p.name,
                p.restarts,
                if p.gave_up { ", gave up" } else { "" }
            )?;
        }
        if let Some(c) = &self.chaos {
            write!(f, "{c}")?;
        }
        let fl = &self.faults;
        writeln!(
            f,
            "  safe state: {} entries, worst {:.2} ms after the last good force sample; largest normal force {:.2} N ({:.2}× preload)",
            fl.safe_entries,
            fl.safe_after_last_good_ms_max,
            fl.normal_force_max_n,
            fl.normal_force_max_over_preload,
        )?;
        for o in &self.cleanup.observers {
            writeln!(
                f,
                "  observer still attached at the end (its files left alone): {} pid {} on {}",
                if o.name.is_empty() {
                    "(unnamed)"
                } else {
                    &o.name
                },
                o.pid,
                o.services.join(", ")
            )?;
        }
        for c in &self.checks {
            writeln!(f, "  {}", c.line())?;
        }
        Ok(())
    }
}
