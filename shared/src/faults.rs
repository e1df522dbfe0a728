//! Fault injection, the pure part: a seeded plan of faults for `afs chaos`, and the figures
//! that say whether the stack stayed safe through them (from the world and servo samples of
//! each tick, as the supervisor receives them).

use crate::error::UnknownName;
pub use crate::msg::Board;
use crate::msg::{PlantSample, ServoFlags, ServoSample, WrenchFlags, WrenchSample};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// What to inject.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultKind {
    /// SIGKILL at a random moment.
    Kill(Board),
    /// SIGKILL of the servo or sensor while the servo dithers to probe the tangent.
    KillMidProbe(Board),
    /// SIGKILL of the estimator while it holds an unanswered tangent request: frozen
    /// (SIGSTOP) when the probe starts, killed once the request is in its queue.
    KillEstimatorMidRequest,
    /// SIGSTOP: alive but silent, until the supervisor's stall policy kills it (or the
    /// injector sends SIGCONT when the policy is off). A frozen servo freezes the simulated
    /// world with it (the plant runs in its process).
    Freeze(Board),
    /// A burst of bad force samples on the wrench stream, one of each [`BadSample`].
    BadSamples,
    /// SIGKILL of the link board (the process named `link`, docs/link.md): its supervisor
    /// restarts it and the tunnel comes up again.
    KillLink,
    /// The link cut for a while: the stack file's own commands take the network down and up
    /// again (on one machine, `examples/two-hosts.sh` downs its veth pair).
    CutLink,
}

impl FaultKind {
    /// Every kind, by its command-line name.
    pub const ALL: [(&'static str, FaultKind); 12] = [
        ("kill-servo", FaultKind::Kill(Board::Servo)),
        ("kill-sensor", FaultKind::Kill(Board::Sensor)),
        ("kill-estimator", FaultKind::Kill(Board::Estimator)),
        (
            "kill-servo-mid-probe",
            FaultKind::KillMidProbe(Board::Servo),
        ),
        (
            "kill-sensor-mid-probe",
            FaultKind::KillMidProbe(Board::Sensor),
        ),
        (
            "kill-estimator-mid-request",
            FaultKind::KillEstimatorMidRequest,
        ),
        ("freeze-servo", FaultKind::Freeze(Board::Servo)),
        ("freeze-sensor", FaultKind::Freeze(Board::Sensor)),
        ("freeze-estimator", FaultKind::Freeze(Board::Estimator)),
        ("bad-samples", FaultKind::BadSamples),
        ("kill-link", FaultKind::KillLink),
        ("cut-link", FaultKind::CutLink),
    ];

    /// The kind named `name` (one of [`FaultKind::ALL`]).
    pub fn from_name(name: &str) -> Result<Self, UnknownName> {
        Self::ALL
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, k)| *k)
            .ok_or_else(|| UnknownName {
                what: "fault",
                name: name.into(),
                known: Self::ALL.iter().map(|(n, _)| *n).collect(),
            })
    }

    /// The command-line name.
    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(_, k)| *k == self)
            .map_or("?", |(n, _)| n)
    }

    /// True for the kinds that need the servo to probe the tangent (the injector asks it for a
    /// probe when one is due): only scenarios that track a surface probe.
    pub fn needs_probe(self) -> bool {
        matches!(
            self,
            FaultKind::KillMidProbe(_) | FaultKind::KillEstimatorMidRequest
        )
    }

    /// True for the kinds that need a link board in the graph (a process named `link`).
    pub fn needs_link(self) -> bool {
        matches!(self, FaultKind::KillLink | FaultKind::CutLink)
    }

    /// The board the fault ends (None: the bad-sample burst and the link's faults end no
    /// board of the control loop).
    pub fn target(self) -> Option<Board> {
        match self {
            FaultKind::Kill(b) | FaultKind::KillMidProbe(b) | FaultKind::Freeze(b) => Some(b),
            FaultKind::KillEstimatorMidRequest => Some(Board::Estimator),
            FaultKind::BadSamples | FaultKind::KillLink | FaultKind::CutLink => None,
        }
    }
}

/// The bad force samples of a [`FaultKind::BadSamples`] burst.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BadSample {
    /// A NaN force component.
    Nan,
    /// An infinite moment.
    Infinite,
    /// A force of 10⁶ N, far beyond the sensor's range.
    Absurd,
    /// The newest genuine sample again (the servo sees it as repeated, or as going backwards
    /// if a newer genuine one arrived first).
    Repeat,
    /// A sample of an earlier sensor epoch.
    Backwards,
    /// A sample timestamped one second in the future.
    Future,
}

impl BadSample {
    /// One of each.
    pub const ALL: [BadSample; 6] = [
        BadSample::Nan,
        BadSample::Infinite,
        BadSample::Absurd,
        BadSample::Repeat,
        BadSample::Backwards,
        BadSample::Future,
    ];
}

impl BadSample {
    /// The bad sample of this kind, built from the newest genuine one `g` at `now_ns`
    /// (monotonic); flagged as injected, which the gate ignores.
    pub fn sample(self, g: &WrenchSample, now_ns: u64) -> WrenchSample {
        let mut s = *g;
        s.flags |= WrenchFlags::INJECTED;
        s.publish_ns = now_ns;
        match self {
            BadSample::Nan => s.force_n[0] = f64::NAN,
            BadSample::Infinite => s.torque_nm = f64::INFINITY,
            BadSample::Absurd => s.force_n = [1e6, -1e6],
            BadSample::Repeat => s.publish_ns = g.publish_ns,
            BadSample::Backwards => {
                s.epoch_ns = g.epoch_ns.saturating_sub(1);
                s.seq = g.seq + 1000;
            }
            BadSample::Future => {
                s.seq = g.seq + 1;
                s.sample_ns = now_ns + 1_000_000_000;
            }
        }
        s
    }
}

/// Bad samples sent, by kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct BadCounts {
    /// NaN.
    pub nan: u64,
    /// Infinite.
    pub infinite: u64,
    /// Beyond the rated range.
    pub absurd: u64,
    /// The newest genuine sample again.
    pub repeat: u64,
    /// An earlier epoch.
    pub backwards: u64,
    /// Timestamped in the future.
    pub future: u64,
}

impl BadCounts {
    /// One more of `kind`.
    pub fn count(&mut self, kind: BadSample) {
        *match kind {
            BadSample::Nan => &mut self.nan,
            BadSample::Infinite => &mut self.infinite,
            BadSample::Absurd => &mut self.absurd,
            BadSample::Repeat => &mut self.repeat,
            BadSample::Backwards => &mut self.backwards,
            BadSample::Future => &mut self.future,
        } += 1;
    }

    /// All kinds.
    pub fn total(&self) -> u64 {
        self.nan + self.infinite + self.absurd + self.repeat + self.backwards + self.future
    }
}

/// One planned fault.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PlannedFault {
    /// Simulated time at which it becomes due (s).
    pub at_s: f64,
    /// What.
    pub kind: FaultKind,
}

/// How long each kind of fault occupies the stack (simulated s), from its due time until the
/// next fault may come: the wait for its moment, detection, the restart, and the time the
/// board's data must flow again before it is faulted anew. Built from the stack's policies
/// (backoff, stall limits) and the scenario's probe; spans are conservative, so that faults
/// planned back to back do not wait for each other. While the servo is down the simulated
/// world stands still, so its downtime costs no simulated time at all.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FaultSpans {
    /// Restart backoff per board (servo, sensor, estimator) (s).
    pub backoff_s: [f64; 3],
    /// Stall limit per board (s; 0: none, a frozen board is let go after `thaw_s`).
    pub stall_s: [f64; 3],
    /// A board's start-up beyond its backoff, with margin (s): measured 20–70 ms.
    pub start_s: f64,
    /// Data flowing before a board is faulted again (s).
    pub uptime_s: f64,
    /// From asking the servo for a probe to its first stroke: stopping, and the normal force
    /// settling for the probe's hold time (s).
    pub probe_start_s: f64,
    /// The probe run, strokes and ramps (s).
    pub probe_s: f64,
    /// After a request is killed in flight: the servo's time-out before it sends it again, and
    /// the answer (s).
    pub retry_s: f64,
    /// A frozen board with no stall policy is let go after this long (s).
    pub thaw_s: f64,
    /// A bad-sample burst (s).
    pub burst_s: f64,
    /// The link board's restart backoff (s).
    pub link_backoff_s: f64,
    /// From the link board's start, or the end of a cut, until the tunnel carries again:
    /// zenoh's connection retries and the tunnel's discovery, with margin (s).
    pub link_up_s: f64,
    /// How long a cut lasts (s).
    pub cut_s: f64,
    /// zenoh's lease (s): a cut longer than this closes the session, which reconnects within
    /// `link_up_s` of the link's return; a shorter one leaves it to TCP, whose retransmission
    /// backoff doubles, so that data flows again up to the cut's own length after its end.
    pub link_lease_s: f64,
}

impl FaultSpans {
    /// The span of `kind` (s).
    pub fn span(&self, kind: FaultKind) -> f64 {
        let restart = |b: Board| self.backoff_s[b as usize] + self.start_s + self.uptime_s;
        match kind {
            FaultKind::Kill(b) => restart(b),
            FaultKind::Freeze(b) => {
                let stall = self.stall_s[b as usize];
                if stall > 0.0 {
                    stall + restart(b)
                } else {
                    self.thaw_s + self.uptime_s
                }
            }
            FaultKind::KillMidProbe(b) => self.probe_start_s + restart(b),
            FaultKind::KillEstimatorMidRequest => {
                self.probe_start_s + self.probe_s + self.retry_s + restart(Board::Estimator)
            }
            FaultKind::BadSamples => self.burst_s,
            FaultKind::KillLink => self.link_backoff_s + self.start_s + self.link_up_s,
            FaultKind::CutLink => {
                let tcp = if self.cut_s > self.link_lease_s {
                    0.0
                } else {
                    self.cut_s
                };
                self.cut_s + tcp + self.link_up_s
            }
        }
    }

    /// Checks the spans (finite, ≥ 0, and every kind takes some time).
    pub fn validate(&self) -> Result<(), PlanError> {
        let all = self
            .backoff_s
            .iter()
            .chain(&self.stall_s)
            .chain(&[
                self.start_s,
                self.uptime_s,
                self.probe_start_s,
                self.probe_s,
                self.retry_s,
                self.thaw_s,
                self.burst_s,
                self.link_backoff_s,
                self.link_up_s,
                self.cut_s,
                self.link_lease_s,
            ])
            .all(|v| v.is_finite() && *v >= 0.0);
        if all && self.burst_s > 0.0 {
            Ok(())
        } else {
            Err(PlanError::Spans)
        }
    }
}

/// Why a fault plan cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// No kinds to draw from.
    #[error("no fault kinds to draw from")]
    NoKinds,
    /// The window is empty or not a number.
    #[error("the faults need a time window: [{start_s}, {end_s}] s is empty")]
    NoWindow {
        /// Start (s).
        start_s: f64,
        /// End (s).
        end_s: f64,
    },
    /// A span is negative or not a number.
    #[error("the fault spans must be finite and ≥ 0, and a burst must take some time")]
    Spans,
    /// The faults need more time than the window holds.
    #[error(
        "{count} faults need {needed_s:.1} s of simulated time between the window's ends; it holds {window_s:.1} s: use a duration of at least {minimum_duration_s:.0} s, or fewer faults"
    )]
    TooShort {
        /// Faults asked for.
        count: usize,
        /// Simulated time they need at the least (s).
        needed_s: f64,
        /// The window's length (s).
        window_s: f64,
        /// The shortest run that holds them (s): their need plus the time outside the window.
        minimum_duration_s: f64,
    },
}

/// `count` faults drawn from `kinds` (at random, or in turn when `in_turn`), due at simulated
/// times in `[start_s, end_s]`, each given its span (`spans`) before the next is due, so the
/// plan always fits: drawn at random, a kind is only drawn if the faults still to come fit in
/// what is left with the shortest kind; taken in turn, the whole plan must fit. The free time
/// left over is spread at random between the faults. The same seed gives the same plan.
/// `outside_s` is the run time outside the window, to name the shortest run in the error.
pub fn plan(
    seed: u64,
    count: usize,
    (start_s, end_s): (f64, f64),
    kinds: &[FaultKind],
    in_turn: bool,
    spans: &FaultSpans,
    outside_s: f64,
) -> Result<Vec<PlannedFault>, PlanError> {
    if kinds.is_empty() {
        return Err(PlanError::NoKinds);
    }
    if !(start_s.is_finite() && end_s.is_finite() && start_s >= 0.0 && end_s > start_s) {
        return Err(PlanError::NoWindow { start_s, end_s });
    }
    spans.validate()?;
    let window = end_s - start_s;
    let span = |k: FaultKind| spans.span(k);
    let too_short = |needed_s: f64| PlanError::TooShort {
        count,
        needed_s,
        window_s: window,
        minimum_duration_s: (needed_s + outside_s).ceil(),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut uniform = move || (f64::from(rng.next_u32()) + 0.5) / (f64::from(u32::MAX) + 1.0);
    // The kinds, in order.
    let chosen: Vec<FaultKind> = if in_turn {
        let chosen: Vec<FaultKind> = (0..count).map(|i| kinds[i % kinds.len()]).collect();
        let needed: f64 = chosen.iter().map(|k| span(*k)).sum();
        if needed > window {
            return Err(too_short(needed));
        }
        chosen
    } else {
        let shortest = kinds.iter().map(|k| span(*k)).fold(f64::INFINITY, f64::min);
        if shortest * count as f64 > window {
            return Err(too_short(shortest * count as f64));
        }
        let mut used = 0.0;
        let mut chosen = Vec::with_capacity(count);
        for i in 0..count {
            let after = shortest * (count - i - 1) as f64;
            let fits: Vec<FaultKind> = kinds
                .iter()
                .copied()
                .filter(|k| used + span(*k) + after <= window)
                .collect();
            // The shortest kind always fits (checked above, and kept so at every draw).
            let k = fits[((uniform() * fits.len() as f64) as usize).min(fits.len() - 1)];
            used += span(k);
            chosen.push(k);
        }
        chosen
    };
    // The free time, cut at random into a gap before each fault and one after the last.
    let free = window - chosen.iter().map(|k| span(*k)).sum::<f64>();
    let weights: Vec<f64> = (0..=count).map(|_| -uniform().ln()).collect();
    let total: f64 = weights.iter().sum();
    let mut t = start_s;
    Ok(chosen
        .iter()
        .zip(&weights)
        .map(|(k, w)| {
            t += free * w / total;
            let f = PlannedFault { at_s: t, kind: *k };
            t += span(*k);
            f
        })
        .collect())
}

/// A servo tick this much later than the one before means the servo itself did not run (the
/// machine stalled it): the data it then finds too old is its own lateness, not a fault of the
/// sensor (ns).
pub const SERVO_STALL_NS: u64 = 500_000;

/// Ticks after a servo restart whose normal force is reported apart (0.5 s at 10 kHz).
pub const SERVO_RESTART_TICKS: u64 = 5_000;

/// What [`FaultMonitor`] measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FaultFigures {
    /// Times the servo entered its safe state after having had good force data.
    pub safe_entries: u64,
    /// Of those, entries with the servo itself stalled (a tick more than
    /// [`SERVO_STALL_NS`] after the one before) since its last good data.
    pub safe_entries_servo_stalled: u64,
    /// Longest time from the last good force sample (its sampling instant) to the first servo
    /// tick in the safe state, over the entries where the servo ran on time (ms).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub safe_after_last_good_ms_max: f64,
    /// Mean of that time over the same entries (ms).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub safe_after_last_good_ms_mean: f64,
    /// Longest such time over every entry, those with the servo stalled included (ms).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub safe_after_last_good_ms_max_all: f64,
    /// Longest time, on the servo's own clock (its samples' `time_s`: the simulated time, or a
    /// robot's), from the first tick that found no new force sample to the first tick in the
    /// safe state, over every entry (ms): the servo's reaction to a silent sensor, whatever the
    /// wall clock did (a simulated robot's time runs slower than it).
    #[serde(default, deserialize_with = "crate::nan::or_null")]
    pub safe_after_silence_ms_max: f64,
    /// Largest true normal force after the settling time (N), outside the
    /// [`SERVO_RESTART_TICKS`] after each servo restart.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub normal_force_max_n: f64,
    /// That over the preload.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub normal_force_max_over_preload: f64,
    /// Simulated time of the largest normal force (s).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub normal_force_max_at_s: f64,
    /// Largest true normal force in the [`SERVO_RESTART_TICKS`] after a servo restart (N): a
    /// restarted controller resumes the world but not its own state (force-loop integrator,
    /// a probe in progress), which is a transient of its own.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub normal_force_max_after_servo_restart_n: f64,
    /// Servo ticks whose measured force (what the controller used) was NaN or infinite.
    pub controller_non_finite: u64,
    /// Largest |measured normal or tangential force| the controller used (N).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub controller_force_max_abs_n: f64,
}

/// Safety figures of a run, tick by tick.
#[derive(Debug, Clone)]
pub struct FaultMonitor {
    preload_n: f64,
    settle_s: f64,
    last_good_ns: Option<u64>,
    was_safe: bool,
    last_tick_ns: Option<u64>,
    /// Longest tick-to-tick interval since the last tick with good data (ns).
    gap_since_good_ns: u64,
    /// A tick this much later than the one before is the servo's own stall (ns).
    stall_ns: u64,
    /// The newest force sample's number, and the servo's time of the first tick without a newer
    /// one (s; None while each tick has a new one).
    newest_seq: Option<u64>,
    silent_from_s: Option<f64>,
    silence_max_s: f64,
    entries: u64,
    stalled_entries: u64,
    latency_sum_ns: u64,
    latency_max_ns: u64,
    latency_max_all_ns: u64,
    normal_max: f64,
    normal_max_at: f64,
    restart_max: f64,
    restart_from: Option<u64>,
    non_finite: u64,
    force_max_abs: f64,
}

impl FaultMonitor {
    /// A monitor for a preload (N); the normal force counts from `settle_s` of simulated time
    /// (the first contact's transient is not a fault's).
    pub fn new(preload_n: f64, settle_s: f64) -> Self {
        Self {
            preload_n,
            settle_s,
            last_good_ns: None,
            was_safe: false,
            last_tick_ns: None,
            gap_since_good_ns: 0,
            stall_ns: SERVO_STALL_NS,
            newest_seq: None,
            silent_from_s: None,
            silence_max_s: 0.0,
            entries: 0,
            stalled_entries: 0,
            latency_sum_ns: 0,
            latency_max_ns: 0,
            latency_max_all_ns: 0,
            normal_max: 0.0,
            normal_max_at: 0.0,
            restart_max: 0.0,
            restart_from: None,
            non_finite: 0,
            force_max_abs: 0.0,
        }
    }

    /// For a servo ticking every `period_ns`: a tick more than five periods after the one before
    /// is its own stall (at least [`SERVO_STALL_NS`], five ticks at 10 kHz; 5 ms at a robot's
    /// 1 kHz).
    #[must_use]
    pub fn with_period_ns(mut self, period_ns: u64) -> Self {
        self.stall_ns = SERVO_STALL_NS.max(period_ns.saturating_mul(5));
        self
    }

    /// One tick's samples (the same tick).
    pub fn push(&mut self, p: &PlantSample, s: &ServoSample) {
        let safe = s.flags.contains(ServoFlags::SAFE);
        if let Some(prev) = self.last_tick_ns {
            self.gap_since_good_ns = self.gap_since_good_ns.max(s.tick_ns.saturating_sub(prev));
        }
        self.last_tick_ns = Some(s.tick_ns);
        if safe
            && !self.was_safe
            && let Some(good) = self.last_good_ns
        {
            let latency = s.tick_ns.saturating_sub(good);
            self.entries += 1;
            self.latency_max_all_ns = self.latency_max_all_ns.max(latency);
            let silent = s.time_s - self.silent_from_s.unwrap_or(s.time_s);
            self.silence_max_s = self.silence_max_s.max(silent);
            if self.gap_since_good_ns > self.stall_ns {
                self.stalled_entries += 1;
            } else {
                self.latency_sum_ns += latency;
                self.latency_max_ns = self.latency_max_ns.max(latency);
            }
        }
        self.was_safe = safe;
        let fresh =
            s.flags.contains(ServoFlags::FORCE_VALID) && self.newest_seq != Some(s.wrench_seq);
        if fresh {
            self.newest_seq = Some(s.wrench_seq);
            self.silent_from_s = None;
        } else if self.silent_from_s.is_none() {
            self.silent_from_s = Some(s.time_s);
        }
        if s.flags.contains(ServoFlags::FORCE_VALID) {
            self.last_good_ns = Some(s.wrench_sample_ns);
            self.gap_since_good_ns = 0;
        }
        let measured = [s.normal_force_n, s.tangential_force_n];
        if measured.iter().any(|v| !v.is_finite()) {
            self.non_finite += 1;
        } else {
            for v in measured {
                self.force_max_abs = self.force_max_abs.max(v.abs());
            }
        }
        let after_restart = self
            .restart_from
            .is_some_and(|r| p.seq >= r && p.seq - r < SERVO_RESTART_TICKS);
        if after_restart {
            self.restart_max = self.restart_max.max(p.normal_force_n);
        } else if p.time_s >= self.settle_s && p.normal_force_n > self.normal_max {
            self.normal_max = p.normal_force_n;
            self.normal_max_at = p.time_s;
        }
    }

    /// A restarted servo runs the world on from tick `seq`.
    pub fn servo_restarted_at(&mut self, seq: u64) {
        self.restart_from = Some(seq);
    }

    /// The figures so far.
    pub fn figures(&self) -> FaultFigures {
        let on_time = self.entries - self.stalled_entries;
        FaultFigures {
            safe_entries: self.entries,
            safe_entries_servo_stalled: self.stalled_entries,
            safe_after_last_good_ms_max: self.latency_max_ns as f64 * 1e-6,
            safe_after_last_good_ms_mean: if on_time == 0 {
                0.0
            } else {
                self.latency_sum_ns as f64 * 1e-6 / on_time as f64
            },
            safe_after_last_good_ms_max_all: self.latency_max_all_ns as f64 * 1e-6,
            // To the microsecond: the servo's time is a sum of periods (a robot's in whole
            // milliseconds), whose rounding must not make 2 ms read as 2.000000000000668.
            safe_after_silence_ms_max: (self.silence_max_s * 1e6).round() * 1e-3,
            normal_force_max_n: self.normal_max,
            normal_force_max_over_preload: self.normal_max / self.preload_n,
            normal_force_max_at_s: self.normal_max_at,
            normal_force_max_after_servo_restart_n: self.restart_max,
            controller_non_finite: self.non_finite,
            controller_force_max_abs_n: self.force_max_abs,
        }
    }
}

#[cfg(test)]
#[path = "faults_tests.rs"]
mod tests;
