//! What a scenario run measured: the monitor that turns a run's samples into a
//! [`ScenarioReport`], and the ticks it notes for the reference to replay.

use super::{Replay, Scenario};
use super::{ScenarioKind, TUNING_START_S};
use crate::insertion::monitor::{InsertionMonitor, InsertionRun};
use crate::monitor::{MonitorTick, TrackingMonitor, TrackingRun};
use crate::msg::{PegSample, PlantSample, ServoFlags, ServoSample};
use crate::servo::EstimationCounters;
use crate::ticks::{Tick, WindowSummary, sliding_periods, window};
use serde::{Deserialize, Serialize};

/// Friction-suppression figures (as `fig4.8`'s, for one tuner).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FrictionRun {
    /// Mean friction before tuning, 0.15 s to 0.5 s (N).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub start_mean_n: f64,
    /// Mean over the last 3 whole dither periods (N).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub end_mean_n: f64,
    /// end / start.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub end_ratio: f64,
    /// First time after tuning started that the 3-period mean fell below 25 % of the start (s).
    pub time_to_quarter_s: Option<f64>,
    /// Worst |F_N − preload| / preload after 0.5 s, true force.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub worst_normal_deviation: f64,
    /// Commanded Aω averaged over the last second (m/s).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub settled_a_omega_m_per_s: f64,
    /// Statistics over the last second.
    pub last_second: WindowSummary,
}

/// Turns a run's ticks into a [`ScenarioReport`].
#[derive(Debug, Clone)]
pub struct ScenarioMonitor {
    kind: ScenarioKind,
    preload: f64,
    tracking: TrackingMonitor,
    ticks: Vec<Tick>,
    last_phase: f64,
    count: u64,
    counters: EstimationCounters,
    safe_ticks: u64,
    invalid: Vec<TickRange>,
    requested: Vec<u64>,
    restarts: Vec<u64>,
    /// The insertion's monitor (`insertion` only) and the last tick it saw.
    insertion: Option<(InsertionMonitor, u64)>,
}

/// A run of consecutive servo ticks, by sequence number.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct TickRange {
    /// First tick's sequence number.
    pub first: u64,
    /// Number of ticks.
    pub len: u64,
}

impl TickRange {
    /// True when `seq` lies in the range.
    pub fn contains(&self, seq: u64) -> bool {
        seq >= self.first && seq - self.first < self.len
    }
}

/// A run's force-invalid tick ranges walked in tick order: the one place a lockstep reference
/// asks whether the stack could use its force data at a tick.
#[derive(Debug, Clone, Copy)]
pub struct InvalidTicks<'a> {
    ranges: &'a [TickRange],
    next: usize,
}

impl<'a> InvalidTicks<'a> {
    /// Over `ranges`, in order (as [`ScenarioMonitor::replay`] gives them).
    pub fn new(ranges: &'a [TickRange]) -> Self {
        Self { ranges, next: 0 }
    }

    /// Whether the force data of tick `seq` was valid; ticks are asked in increasing order.
    pub fn valid(&mut self, seq: u64) -> bool {
        while self
            .ranges
            .get(self.next)
            .is_some_and(|r| r.first + r.len <= seq)
        {
            self.next += 1;
        }
        !self.ranges.get(self.next).is_some_and(|r| r.contains(seq))
    }
}

/// Most force-invalid tick ranges a monitor keeps (later ones are merged into the last).
const MAX_INVALID_RANGES: usize = 100_000;

impl ScenarioMonitor {
    /// A monitor for `scenario`.
    pub fn new(scenario: &Scenario) -> Self {
        let cfg = &scenario.cfg;
        let period = (cfg.servo.rate_hz / cfg.servo.dither.frequency_hz).round() as usize;
        Self {
            kind: scenario.kind,
            preload: cfg.servo.hybrid.preload_n,
            tracking: TrackingMonitor::new(cfg.servo.hybrid.preload_n, period),
            ticks: Vec::new(),
            last_phase: 0.0,
            count: 0,
            counters: EstimationCounters::default(),
            safe_ticks: 0,
            invalid: Vec::new(),
            requested: Vec::new(),
            restarts: Vec::new(),
            insertion: scenario.insertion.map(|o| {
                (
                    InsertionMonitor::new(cfg.servo.dt(), o.fit(), o.force_limit_n()),
                    0,
                )
            }),
        }
    }

    /// One tick of the insertion (`insertion` only; a tick seen before, such as a restarted
    /// servo's repeat of its predecessor's last, is skipped).
    pub fn push_peg(&mut self, p: &PegSample) {
        if let Some((m, last)) = &mut self.insertion
            && p.seq > *last
        {
            *last = p.seq;
            m.push(&p.tick());
        }
    }

    /// The ticks whose force input the servo did not use (stale, out of range, absent), as
    /// ranges of sequence numbers: what [`run_lockstep_replay`] replays.
    pub fn force_invalid(&self) -> &[TickRange] {
        &self.invalid
    }

    /// The ticks at which the servo started an estimation it was asked for.
    pub fn requested(&self) -> &[u64] {
        &self.requested
    }

    /// A restarted servo runs the world on from tick `seq` (the supervisor knows; the samples
    /// do not tell).
    pub fn servo_restarted_at(&mut self, seq: u64) {
        if self.restarts.last().is_none_or(|&l| seq > l) {
            self.restarts.push(seq);
        }
    }

    /// What [`run_lockstep_replay`] needs to go through the same events as the stack.
    pub fn replay(&self) -> Replay<'_> {
        Replay {
            force_invalid: &self.invalid,
            requested: &self.requested,
            servo_restarts: &self.restarts,
        }
    }

    pub(crate) fn note_invalid(&mut self, seq: u64) {
        let full = self.invalid.len() >= MAX_INVALID_RANGES;
        match self.invalid.last_mut() {
            Some(r) if seq == r.first + r.len => r.len += 1,
            Some(r) if full && seq > r.first => {
                r.len = seq - r.first + 1;
            }
            _ => self.invalid.push(TickRange { first: seq, len: 1 }),
        }
    }

    /// One tick's samples.
    pub fn push(&mut self, p: &PlantSample, s: &ServoSample) {
        let m = MonitorTick::from_samples(p, s);
        if self.kind != ScenarioKind::Insertion {
            self.tracking.push(&m);
        }
        if s.estimations_requested > self.counters.requested {
            self.requested.push(s.seq);
        }
        self.counters = EstimationCounters {
            started: s.estimations_started,
            requested: s.estimations_requested,
            estimates: s.estimates,
            reprobes: s.reprobes,
            failures: s.failures,
            aborted: s.aborted,
            safe_entries: s.safe_entries,
            force_triggers: s.force_triggers,
            slope_triggers: s.slope_triggers,
            contact_losses: s.contact_losses,
        };
        if s.flags.contains(ServoFlags::SAFE) {
            self.safe_ticks += 1;
        }
        if !s.flags.contains(ServoFlags::FORCE_VALID) {
            self.note_invalid(s.seq);
        }
        if self.kind == ScenarioKind::FrictionSuppression {
            let period_end = m.phase < self.last_phase;
            self.last_phase = m.phase;
            self.ticks.push(Tick {
                t: m.t,
                friction: m.friction,
                normal: m.normal,
                normal_true: m.normal_true,
                scale: 0.0,
                velocity: m.velocity,
                phase: m.phase,
                period_end,
                a_cmd: m.a_cmd,
                contact: m.contact,
            });
        }
        self.count += 1;
    }

    /// Ticks seen.
    pub fn ticks(&self) -> u64 {
        self.count
    }

    /// The report so far.
    pub fn report(&self) -> ScenarioReport {
        let tracking = self.tracking.finish(self.counters);
        let friction = (self.kind == ScenarioKind::FrictionSuppression && !self.ticks.is_empty())
            .then(|| {
                let ticks = &self.ticks;
                let t_end = ticks.last().map_or(0.0, |k| k.t);
                let start = window(ticks, 0.15, TUNING_START_S).mean_force_n;
                let sliding = sliding_periods(ticks, 3);
                let end = sliding.last().map_or(f64::NAN, |p| p[1]);
                let quarter = sliding
                    .iter()
                    .find(|p| p[0] > TUNING_START_S && p[1] < 0.25 * start)
                    .map(|p| p[0] - TUNING_START_S);
                let worst = ticks
                    .iter()
                    .filter(|k| k.t >= 0.5)
                    .map(|k| (k.normal_true - self.preload).abs() / self.preload)
                    .fold(0.0, f64::max);
                let last: Vec<&Tick> = ticks.iter().filter(|k| k.t > t_end - 1.0).collect();
                FrictionRun {
                    start_mean_n: start,
                    end_mean_n: end,
                    end_ratio: end / start,
                    time_to_quarter_s: quarter,
                    worst_normal_deviation: worst,
                    settled_a_omega_m_per_s: last.iter().map(|k| k.a_cmd).sum::<f64>()
                        / last.len().max(1) as f64,
                    last_second: window(ticks, t_end - 1.0, t_end),
                }
            });
        ScenarioReport {
            scenario: self.kind.name().into(),
            ticks: self.count,
            safe_ticks: self.safe_ticks,
            duration_s: tracking.duration_s,
            tracking,
            friction,
            insertion: self.insertion.as_ref().map(|(m, _)| m.report()),
        }
    }
}

/// What a scenario run measured.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ScenarioReport {
    /// Scenario name.
    pub scenario: String,
    /// Servo ticks seen.
    pub ticks: u64,
    /// Ticks in the safe state.
    pub safe_ticks: u64,
    /// Simulated time covered (s).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub duration_s: f64,
    /// Tangent tracking and force regulation.
    pub tracking: TrackingRun,
    /// Friction suppression (`friction-suppression` only).
    pub friction: Option<FrictionRun>,
    /// The insertion (`insertion` only).
    #[serde(default)]
    pub insertion: Option<InsertionRun>,
}
