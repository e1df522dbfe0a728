//! What a chaos run adds to the run report: each fault as it went, recovery times, bad samples
//! sent and counted, the stack's footprint before the first fault and after the last; and the
//! checks that follow from them.

use super::inject::FaultRecord;
use crate::stack::Footprint;
use afs_shared::check::Check;
use afs_shared::faults::BadCounts;
use afs_shared::faults::FaultFigures;
use afs_shared::watchdog::GateCounters;
use serde::{Deserialize, Serialize};
use std::fmt;

/// Heap the supervisor may gain over a chaos run (KiB): its scenario monitor keeps a track
/// sample every 10 ms (≈ 5 KiB per simulated second), so a 2-minute run grows it by about
/// 0.6 MiB; a leak per fault would show as far more.
const RSS_GROWTH_LIMIT_KIB: f64 = 8192.0;

/// Recovery times of the faults of one kind (ms).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct BackSummary {
    /// Faults that came back.
    pub count: usize,
    /// The longest.
    pub max_ms: Option<f64>,
    /// The mean.
    pub mean_ms: Option<f64>,
}

impl BackSummary {
    fn of(records: &[FaultRecord], kind: &str) -> Self {
        let v: Vec<f64> = records
            .iter()
            .filter(|r| r.kind.starts_with(kind))
            .filter_map(|r| r.back_ms)
            .collect();
        Self {
            count: v.len(),
            max_ms: max_of(&v),
            mean_ms: (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64),
        }
    }
}

/// Recovery times by board and kind of fault.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct BackAfterKill {
    /// Servo killed (at a random moment or mid-probe).
    pub servo: BackSummary,
    /// Sensor killed.
    pub sensor: BackSummary,
    /// Estimator killed (also mid-request).
    pub estimator: BackSummary,
    /// Servo frozen (from the freeze).
    pub frozen_servo: BackSummary,
    /// Sensor frozen.
    pub frozen_sensor: BackSummary,
    /// Estimator frozen.
    pub frozen_estimator: BackSummary,
    /// Link board killed (back: its restart's start; the tunnel's return shows on the other
    /// host, docs/link.md).
    #[serde(default)]
    pub link: BackSummary,
}

/// Bad samples sent, and what the servo's gate made of them: every one is judged by the gate
/// or reported with the cause of its drop.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct BadSampleReport {
    /// Sent, by kind.
    pub sent: BadCounts,
    /// Of those, sent while the servo's subscriber was on the service; the others reached no
    /// servo (one being restarted): `not_sent_to_servo`.
    pub to_servo: BadCounts,
    /// Sent while no servo's subscriber was on the service (dropped: no servo to judge them).
    pub not_sent_to_servo: u64,
    /// What the servo's gate made of the injected samples it received, over every servo
    /// incarnation (None: no loop statistics came).
    pub judged_by_servo: Option<GateCounters>,
}

impl BadSampleReport {
    /// Bad samples sent to the servo that its gate never judged (lost on the way, or received
    /// by an incarnation that died before its counts reached its snapshot).
    pub fn unjudged(&self) -> Option<u64> {
        let j = self.judged_by_servo?;
        Some(self.to_servo.total().abs_diff(j.judged()))
    }

    /// Judged samples whose verdict does not fit their kind: NaN and infinite → non-finite,
    /// absurd → out of range, future → future, repeated and backwards → repeat, backwards, or
    /// accepted (a repeat of a sample this servo never saw is not a repeat); anything else
    /// accepted reached the controller.
    pub fn misjudged(&self) -> Option<u64> {
        let (j, b) = (self.judged_by_servo?, &self.to_servo);
        let accepted_beyond_repeats = j.accepted.saturating_sub(b.repeat);
        Some(
            j.non_finite.abs_diff(b.nan + b.infinite)
                + j.out_of_range.abs_diff(b.absurd)
                + j.future.abs_diff(b.future)
                + (j.seq_repeat + j.seq_backwards + j.accepted).abs_diff(b.repeat + b.backwards)
                + j.version
                + accepted_beyond_repeats,
        )
    }
}

/// The chaos part of the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChaosReport {
    /// Faults planned.
    pub planned: usize,
    /// Faults injected.
    pub injected: usize,
    /// Each fault as it went.
    pub faults: Vec<FaultRecord>,
    /// Recovery times.
    pub back_after_kill: BackAfterKill,
    /// Longest time from a freeze to the stall policy's kill (ms).
    pub freeze_detected_ms_max: Option<f64>,
    /// Longest time beyond its backoff for a killed board's data to be back (ms).
    pub back_beyond_backoff_ms_max: Option<f64>,
    /// Bad samples.
    pub bad_samples: BadSampleReport,
    /// The stack's footprint while steady before the first fault.
    pub steady_before_first_fault: Option<Footprint>,
    /// The same after the last.
    pub steady_after_last_fault: Option<Footprint>,
}

/// What the run measured that the chaos checks need.
pub struct Measured<'a> {
    /// Safety figures.
    pub faults: &'a FaultFigures,
    /// The preload (N); in an insertion, the insertion force.
    pub preload_n: f64,
    /// The largest normal force allowed, over the preload: in general and in the 0.5 s after
    /// a servo restart (targets: 2 and 1.5 while tracking; an insertion's force limit, 3×
    /// the insertion force, for both).
    pub force_limits: (f64, f64),
    /// The servo was restarted.
    pub servo_restarted: bool,
    /// The servo drove a robot, whose packets clock it: its safe-state latency is judged on the
    /// robot's time, from the sensor's silence (a simulated robot's time runs slower than the
    /// wall clock).
    pub robot: bool,
}

impl ChaosReport {
    /// The report of the injector's `records` (with each one's restart timeline), the bad
    /// samples (sent, and judged by the servo's gate), and the footprints.
    pub fn new(
        planned: usize,
        faults: Vec<FaultRecord>,
        bad_samples: BadSampleReport,
        steady: [Option<Footprint>; 2],
    ) -> Self {
        let detected: Vec<f64> = faults.iter().filter_map(|r| r.detected_ms).collect();
        let [steady_before_first_fault, steady_after_last_fault] = steady;
        Self {
            planned,
            injected: faults.len(),
            back_after_kill: BackAfterKill {
                servo: BackSummary::of(&faults, "kill-servo"),
                sensor: BackSummary::of(&faults, "kill-sensor"),
                estimator: BackSummary::of(&faults, "kill-estimator"),
                frozen_servo: BackSummary::of(&faults, "freeze-servo"),
                frozen_sensor: BackSummary::of(&faults, "freeze-sensor"),
                frozen_estimator: BackSummary::of(&faults, "freeze-estimator"),
                link: BackSummary::of(&faults, "kill-link"),
            },
            freeze_detected_ms_max: max_of(&detected),
            back_beyond_backoff_ms_max: max_of(&beyond_backoff(&faults)),
            bad_samples,
            faults,
            steady_before_first_fault,
            steady_after_last_fault,
        }
    }

    /// The checks that follow from the faults: correctness (every fault injected and back,
    /// bad samples counted, no file of a dead process, the heap flat) and targets (safe within
    /// 2 ms, the normal force within 2× the preload and 1.5× after a servo restart, a killed
    /// sensor back within 500 ms, any killed board within 300 ms beyond its backoff).
    pub fn checks(&self, m: &Measured<'_>) -> Vec<Check> {
        let f = m.faults;
        let mut checks = vec![Check::at_least(
            "faults_injected",
            "faults injected (of those planned)",
            self.injected as f64,
            self.planned as f64,
        )];
        let not_back = self
            .faults
            .iter()
            .filter(|r| r.pid != 0 && r.back_ms.is_none() && !r.thawed)
            .count();
        checks.push(Check::at_most(
            "boards_not_back",
            "faulted boards that did not come back",
            not_back as f64,
            0.0,
        ));
        if f.safe_entries > 0 {
            let (id, name, value) = if m.robot {
                (
                    "safe_after_silence_ms",
                    "worst robot time from the sensor's silence to the impedance hold (ms)",
                    f.safe_after_silence_ms_max,
                )
            } else {
                (
                    "safe_after_last_good_ms",
                    "worst time from the last good force sample to the safe state (ms)",
                    f.safe_after_last_good_ms_max,
                )
            };
            checks.push(Check::at_most(id, name, value, 2.0).target());
        }
        checks.push(
            Check::at_most(
                "normal_force_over_preload",
                "largest true normal force / preload (outside 0.5 s after a servo restart)",
                f.normal_force_max_over_preload,
                m.force_limits.0,
            )
            .target(),
        );
        if m.servo_restarted {
            checks.push(
                Check::at_most(
                    "normal_force_over_preload_after_servo_restart",
                    "largest true normal force / preload in the 0.5 s after a servo restart",
                    f.normal_force_max_after_servo_restart_n / m.preload_n,
                    m.force_limits.1,
                )
                .target(),
            );
        }
        if let Some(worst) = self.back_after_kill.sensor.max_ms {
            checks.push(
                Check::at_most(
                    "sensor_back_ms",
                    "worst time for a killed sensor's data to be back (ms)",
                    worst,
                    500.0,
                )
                .target(),
            );
        }
        if let Some(worst) = self.back_beyond_backoff_ms_max {
            checks.push(
                Check::at_most(
                    "back_beyond_backoff_ms",
                    "worst time beyond the backoff for a killed board's data to be back (ms)",
                    worst,
                    300.0,
                )
                .target(),
            );
        }
        let b = &self.bad_samples;
        if b.sent.total() > 0 {
            checks.push(Check::at_most(
                "bad_samples_unjudged",
                "bad samples sent to the servo that its gate did not judge",
                b.unjudged().map_or(f64::NAN, |n| n as f64),
                0.0,
            ));
            checks.push(Check::at_most(
                "bad_samples_misjudged",
                "bad samples the gate judged other than their kind (or let through)",
                b.misjudged().map_or(f64::NAN, |n| n as f64),
                0.0,
            ));
        }
        if let (Some(before), Some(after)) = (
            &self.steady_before_first_fault,
            &self.steady_after_last_fault,
        ) {
            checks.push(Check::at_most(
                "stale_files_after_faults",
                "iceoryx2 files of dead processes after the last fault",
                after.stale_files.len() as f64,
                0.0,
            ));
            checks.push(Check::at_most(
                "supervisor_heap_growth_kib",
                "supervisor heap growth over the faults (RssAnon, KiB)",
                after.supervisor_rss_kib.anon as f64 - before.supervisor_rss_kib.anon as f64,
                RSS_GROWTH_LIMIT_KIB,
            ));
        }
        checks
    }
}

impl fmt::Display for ChaosReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ms = |v: Option<f64>| v.map_or("-".into(), |x| format!("{x:.1}"));
        let b = &self.back_after_kill;
        writeln!(
            f,
            "  faults: {} of {} injected; back after a kill (max ms): servo {}, sensor {}, estimator {}; beyond the backoff at most {} ms",
            self.injected,
            self.planned,
            ms(b.servo.max_ms),
            ms(b.sensor.max_ms),
            ms(b.estimator.max_ms),
            ms(self.back_beyond_backoff_ms_max),
        )
    }
}

/// For each killed board that came back, the time its data took beyond the restart backoff
/// (ms): start-up, clean-up and the supervisor's polling (not the link board, whose data
/// flows on the other host).
fn beyond_backoff(records: &[FaultRecord]) -> Vec<f64> {
    records
        .iter()
        .filter(|r| r.kind.starts_with("kill-") && r.kind != "kill-link")
        .filter_map(|r| Some(r.back_ms? - r.restart?.backoff_ms?))
        .collect()
}

/// The largest of `v` (None when empty).
fn max_of(v: &[f64]) -> Option<f64> {
    v.iter().copied().reduce(f64::max)
}
