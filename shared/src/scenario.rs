//! Scenarios: the set-ups of the in-process experiments as scripts the multi-process stack runs
//! in real time, and the monitor that turns a run's samples into figures.
//!
//! A [`Scenario`] is a [`SimConfig`] plus a [`ScenarioDriver`] that commands the servo at
//! scenario times (velocity, dither, tuning, when to stop). The servo process runs the driver
//! in its fast loop; [`run_lockstep`] runs the same driver in the deterministic lockstep
//! simulation. Both publish the same [`PlantSample`] and [`ServoSample`] messages
//! ([`plant_sample`], [`servo_sample`]), and the same [`ScenarioMonitor`] turns those into a
//! [`ScenarioReport`], so the real-time stack and its lockstep reference are measured by one
//! piece of code and [`Agreement`] can compare them.

use crate::error::{ScenarioError, UnknownName};
use crate::experiments::{Tick, WindowSummary, on_corner_profile, sliding_periods, window};
use crate::msg::{self, PlantSample, ServoFlags, ServoSample};
use crate::plant::PlantTruth;
use crate::servo::{EstimationCounters, ServoCore, ServoMode};
use crate::sim::{Lockstep, SimConfig};
use crate::surface::{Shape, Surface, SurfaceFrame};
use crate::tuner::{CostTunerParams, TunerConfig};
use crate::window::SlidingWindow;
use serde::Serialize;

/// The scenarios `afs run --scenario` knows.
pub const NAMES: [&str; 4] = [
    "surface-tracking",
    "corner",
    "friction-suppression",
    "friction-id",
];

/// Which scenario.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ScenarioKind {
    /// fig. 5.6: an unknown sinusoid tracked at 5 mm/s with estimation on the force limits.
    SurfaceTracking,
    /// The `corners` profile: four corners.
    Corner,
    /// fig. 4.8 (cost tuner): on-line dither tuning at 10 mm/s.
    FrictionSuppression,
    /// Constant-velocity strokes at several speeds without dither, for the estimator's on-line
    /// friction identification.
    FrictionId,
}

impl ScenarioKind {
    /// By name.
    pub fn from_name(name: &str) -> Result<Self, UnknownName> {
        Ok(match name {
            "surface-tracking" => Self::SurfaceTracking,
            "corner" => Self::Corner,
            "friction-suppression" => Self::FrictionSuppression,
            "friction-id" => Self::FrictionId,
            other => {
                return Err(UnknownName {
                    what: "scenario",
                    name: other.into(),
                    known: NAMES.to_vec(),
                });
            }
        })
    }

    /// The name.
    pub fn name(self) -> &'static str {
        match self {
            Self::SurfaceTracking => "surface-tracking",
            Self::Corner => "corner",
            Self::FrictionSuppression => "friction-suppression",
            Self::FrictionId => "friction-id",
        }
    }
}

/// Tracking speed of the tracking scenarios (m/s), as in `fig5.6` and `corners`.
pub const TRACKING_VELOCITY: f64 = 0.005;
/// Traverse speed of `friction-suppression` (m/s), as in `fig4.8`.
pub const SUPPRESSION_VELOCITY: f64 = 0.01;
/// `friction-suppression`: tuning starts at this scenario time (s).
pub const TUNING_START_S: f64 = 0.5;
/// `friction-id`: stroke speeds (m/s), spanning the 20× the eq. 4.5 fit needs.
pub const ID_SPEEDS: [f64; 6] = [0.002, 0.004, 0.008, 0.016, 0.032, 0.048];
/// `friction-id`: hold at rest before the first leg (s).
pub const ID_HOLD_S: f64 = 1.0;
/// `friction-id`: steady time of each leg after the speed is reached (s).
pub const ID_STEADY_S: f64 = 0.8;
/// The servo's tangential acceleration limit the legs are timed with (m/s²).
const ID_ACCELERATION: f64 = 0.2;

/// `friction-id`: how long a leg at speed `v` lasts (s): the ramp from rest plus the steady
/// time.
pub fn id_leg_duration(v: f64) -> f64 {
    v / ID_ACCELERATION + ID_STEADY_S
}

/// A scenario: its set-up and how long it runs by itself.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Which.
    pub kind: ScenarioKind,
    /// The set-up (the base configuration with the scenario's surface, start and tuner).
    pub cfg: SimConfig,
    /// Where the scenario ends by itself, along the surface (m), if it is a traverse.
    pub end_u_m: Option<f64>,
    /// Its natural length (s): the time it needs in the lockstep, or an upper bound.
    pub natural_duration_s: f64,
}

impl Scenario {
    /// Builds `name` over the base configuration (surface, start, tuner and tracking switches
    /// are the scenario's; everything else comes from `base`).
    pub fn new(name: &str, base: &SimConfig) -> Result<Self, ScenarioError> {
        let kind = ScenarioKind::from_name(name)?;
        let mut cfg = base.clone();
        let origin = cfg.surface.frame.origin_m;
        let (end_u_m, natural) = match kind {
            ScenarioKind::SurfaceTracking => {
                let (amp, wl) = (0.003, 0.12);
                cfg.surface = Surface {
                    frame: SurfaceFrame {
                        origin_m: origin,
                        angle_rad: 0.0,
                    },
                    shape: Shape::Sinusoid {
                        amplitude_m: amp,
                        wavelength_m: wl,
                    },
                };
                cfg.start_u_m = -0.5 * wl;
                cfg.servo.tuner = TunerConfig::Fixed;
                cfg.servo.tracking.enabled = true;
                (Some(0.5 * wl), 400.0)
            }
            ScenarioKind::Corner => {
                let (_, end) = on_corner_profile(&mut cfg);
                cfg.servo.tuner = TunerConfig::Fixed;
                cfg.servo.tracking.enabled = true;
                (Some(end), 600.0)
            }
            ScenarioKind::FrictionSuppression => {
                cfg.servo.tuner = TunerConfig::Cost(CostTunerParams::default());
                cfg.start_u_m = -0.5 * SUPPRESSION_VELOCITY * 6.5;
                (None, 6.5)
            }
            ScenarioKind::FrictionId => {
                cfg.servo.tuner = TunerConfig::Fixed;
                cfg.start_u_m = 0.0;
                cfg.servo.hybrid.tangential_acceleration_m_per_s2 = ID_ACCELERATION;
                let t: f64 = ID_SPEEDS
                    .iter()
                    .map(|v| 2.0 * (id_leg_duration(*v) + v / ID_ACCELERATION))
                    .sum();
                (None, (ID_HOLD_S + t).ceil() + 1.0)
            }
        };
        cfg.validate()?;
        Ok(Self {
            kind,
            cfg,
            end_u_m,
            natural_duration_s: natural,
        })
    }

    /// A fresh driver.
    pub fn driver(&self) -> ScenarioDriver {
        ScenarioDriver {
            kind: self.kind,
            end_u_m: self.end_u_m,
            natural_duration_s: self.natural_duration_s,
            started: false,
            tuning: false,
            id_leg: usize::MAX,
            id_leg_start_s: 0.0,
            id_leg_start_u: 0.0,
        }
    }

    /// A fresh monitor.
    pub fn monitor(&self) -> ScenarioMonitor {
        ScenarioMonitor::new(self)
    }
}

/// Whether a scenario is still running.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DriverState {
    /// Keep going.
    Running,
    /// The scenario reached its end.
    Done,
}

/// The driver's state beyond the scenario time, kept in the world snapshot.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriverMemo {
    /// `friction-id` leg in progress.
    pub leg: Option<u32>,
    /// When it started (s).
    pub leg_start_s: f64,
    /// Where it started (m).
    pub leg_start_u: f64,
}

/// Commands the servo at scenario times. Allocation-free; restartable at any time with
/// [`ScenarioDriver::resume`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScenarioDriver {
    kind: ScenarioKind,
    end_u_m: Option<f64>,
    natural_duration_s: f64,
    started: bool,
    tuning: bool,
    id_leg: usize,
    id_leg_start_s: f64,
    id_leg_start_u: f64,
}

impl ScenarioDriver {
    /// One tick at scenario time `t` (s) with the contact at `u` (m along the surface).
    pub fn step(&mut self, t: f64, u: f64, servo: &mut ServoCore) -> DriverState {
        if !self.started {
            self.started = true;
            match self.kind {
                ScenarioKind::SurfaceTracking | ScenarioKind::Corner => {
                    servo.set_a_omega(5.0 * TRACKING_VELOCITY);
                    servo.hybrid_mut().set_velocity(TRACKING_VELOCITY);
                }
                ScenarioKind::FrictionSuppression => {
                    servo.hybrid_mut().set_velocity(SUPPRESSION_VELOCITY);
                    servo.set_a_omega(0.2 * SUPPRESSION_VELOCITY);
                }
                ScenarioKind::FrictionId => {
                    servo.set_a_omega(0.0);
                }
            }
        }
        match self.kind {
            ScenarioKind::SurfaceTracking | ScenarioKind::Corner => {
                if self.end_u_m.is_some_and(|end| u >= end) || t >= self.natural_duration_s {
                    return DriverState::Done;
                }
            }
            ScenarioKind::FrictionSuppression => {
                if !self.tuning && t >= TUNING_START_S {
                    self.tuning = true;
                    servo.set_tuning(true);
                }
                if t >= self.natural_duration_s {
                    return DriverState::Done;
                }
            }
            ScenarioKind::FrictionId => {
                // Legs: +v0, −v0, +v1, −v1, …, each timed (the reversal adds the deceleration),
                // after a hold that lets every board connect.
                let next = if self.id_leg == usize::MAX {
                    (t >= ID_HOLD_S).then_some(0)
                } else {
                    let speed = ID_SPEEDS[self.id_leg / 2];
                    let reversal = if self.id_leg == 0 {
                        0.0
                    } else {
                        speed / ID_ACCELERATION
                    };
                    (t - self.id_leg_start_s >= id_leg_duration(speed) + reversal)
                        .then_some(self.id_leg + 1)
                };
                if let Some(leg) = next {
                    if leg >= 2 * ID_SPEEDS.len() {
                        servo.hybrid_mut().set_velocity(0.0);
                        return DriverState::Done;
                    }
                    self.id_leg = leg;
                    self.id_leg_start_s = t;
                    self.id_leg_start_u = u;
                    let v = ID_SPEEDS[leg / 2];
                    servo
                        .hybrid_mut()
                        .set_velocity(if leg % 2 == 0 { v } else { -v });
                }
            }
        }
        DriverState::Running
    }

    /// Carries on at scenario time `t` after a servo restart, from the driver's
    /// [`DriverMemo`] in the world snapshot; the commands it gave are in the controller's own
    /// snapshot ([`ServoCore::restore`]), so nothing is given again.
    pub fn resume(&mut self, t: f64, memo: DriverMemo) {
        self.started = true;
        self.tuning = self.kind == ScenarioKind::FrictionSuppression && t >= TUNING_START_S;
        self.id_leg = memo.leg.map_or(usize::MAX, |l| l as usize);
        self.id_leg_start_s = memo.leg_start_s;
        self.id_leg_start_u = memo.leg_start_u;
    }

    /// What a restarted driver needs to carry on.
    pub fn memo(&self) -> DriverMemo {
        DriverMemo {
            leg: (self.id_leg != usize::MAX).then_some(self.id_leg as u32),
            leg_start_s: self.id_leg_start_s,
            leg_start_u: self.id_leg_start_u,
        }
    }
}

/// The identification's view of a servo sample.
pub fn ident_tick(s: &ServoSample) -> crate::ident::IdentTick {
    crate::ident::IdentTick {
        t: s.time_s,
        velocity_target: s.velocity_target_m_per_s,
        nominal_velocity: s.nominal_velocity_m_per_s,
        a_omega: s.a_omega_m_per_s,
        tangential_force: s.tangential_force_n,
        friction_normalized: s.friction_normalized_n,
        normal_force: s.normal_force_n,
        tangent_velocity: s.tangent_velocity_m_per_s,
        tracking: ServoMode::try_from(s.mode) == Ok(ServoMode::Track)
            && !s.flags.contains(ServoFlags::SAFE)
            && s.flags.contains(ServoFlags::FORCE_VALID),
    }
}

/// The world sample of a tick.
pub fn plant_sample(tr: &PlantTruth, seq: u64, tick_ns: u64) -> PlantSample {
    PlantSample {
        version: msg::VERSION,
        contact_count: u32::try_from(tr.contact_count).unwrap_or(u32::MAX),
        seq,
        tick_ns,
        publish_ns: 0,
        time_s: tr.time_s,
        q_rad: [tr.q[0], tr.q[1]],
        qd_rad_per_s: [tr.qd[0], tr.qd[1]],
        tip_m: [tr.tip.x, tr.tip.y],
        tip_velocity_m_per_s: [tr.tip_velocity.x, tr.tip_velocity.y],
        contact_force_n: [tr.contact_force.x, tr.contact_force.y],
        sensor_force_n: [tr.sensor_wrench.force.x, tr.sensor_wrench.force.y],
        sensor_torque_nm: tr.sensor_wrench.torque,
        normal_force_n: tr.normal_force_n,
        friction_force_n: tr.friction_force_n,
        sliding_velocity_m_per_s: tr.sliding_velocity_m_per_s,
        depth_m: tr.depth_m,
        surface_u_m: tr.surface_u_m,
        tangent_angle_rad: tr.tangent_angle_rad,
        torque_nm: [tr.torque[0], tr.torque[1]],
    }
}

/// The controller sample of a tick (the wrench fields are the caller's).
pub fn servo_sample(servo: &ServoCore, seq: u64, tick_ns: u64, time_s: f64) -> ServoSample {
    let mut s = ServoSample {
        version: msg::VERSION,
        seq,
        tick_ns,
        time_s,
        wrench_seq: u64::MAX,
        ..Default::default()
    };
    s.set_diag(servo.diag(), &servo.counters());
    s
}

/// What the monitor needs of one tick, from the two samples of that tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MonitorTick {
    /// Simulated time (s).
    pub t: f64,
    /// True normal force (N).
    pub normal_true: f64,
    /// In contact.
    pub contact: bool,
    /// True tangent angle (rad).
    pub tangent_true: f64,
    /// Contact position along the surface (m).
    pub u: f64,
    /// Tracking (not stopped for an estimate, not safe).
    pub moving: bool,
    /// Estimated tangent angle (rad).
    pub tangent_estimated: f64,
    /// Measured friction resisting the nominal motion (N).
    pub friction: f64,
    /// Measured normal force (N).
    pub normal: f64,
    /// Tip velocity along the estimated tangent in the nominal direction (m/s).
    pub velocity: f64,
    /// Dither phase (rad).
    pub phase: f64,
    /// Commanded Aω (m/s).
    pub a_cmd: f64,
}

impl MonitorTick {
    /// From the world and controller samples of one tick.
    pub fn from_samples(p: &PlantSample, s: &ServoSample) -> Self {
        let dir = if s.velocity_target_m_per_s < 0.0 {
            -1.0
        } else {
            1.0
        };
        Self {
            t: p.time_s,
            normal_true: p.normal_force_n,
            contact: p.contact_count > 0 && p.normal_force_n > 0.0,
            tangent_true: p.tangent_angle_rad,
            u: p.surface_u_m,
            moving: ServoMode::try_from(s.mode) == Ok(ServoMode::Track)
                && !s.flags.contains(ServoFlags::SAFE),
            tangent_estimated: s.tangent_angle_rad,
            friction: -s.tangential_force_n * dir,
            normal: s.normal_force_n,
            velocity: s.tangent_velocity_m_per_s * dir,
            phase: s.dither_phase_rad,
            a_cmd: s.a_omega_m_per_s,
        }
    }
}

/// One recorded instant of a tracking run (every 10 ms).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct TrackSample {
    /// Time (s).
    pub t: f64,
    /// Surface coordinate of the contact (m).
    pub u_m: f64,
    /// True tangent angle at the contact (rad).
    pub true_angle_rad: f64,
    /// Tangent angle the controller uses (rad).
    pub estimated_angle_rad: f64,
    /// True normal force (N).
    pub normal_n: f64,
    /// True while tracking (not stopped for an estimate).
    pub moving: bool,
}

/// A tracking run's figures.
#[derive(Debug, Clone, Serialize)]
pub struct TrackingRun {
    /// RMS of the tangent error while moving (deg).
    pub tangent_error_rms_deg: f64,
    /// Largest |tangent error| while moving (deg).
    pub tangent_error_max_deg: f64,
    /// Worst |F_N − preload| / preload after the first 0.5 s, of the true normal force
    /// averaged over one dither period: the regulated force, without the dither's ripple.
    pub worst_normal_deviation: f64,
    /// Smallest and largest of that period-averaged force (N).
    pub normal_range_n: [f64; 2],
    /// When and where the worst period-averaged deviation happened (s, m).
    pub worst_normal_at: [f64; 2],
    /// RMS of the period-averaged |F_N − preload| / preload after 0.5 s.
    pub normal_deviation_rms: f64,
    /// Smallest and largest instantaneous true normal force after 0.5 s, ripple included (N).
    pub instantaneous_normal_range_n: [f64; 2],
    /// Servo ticks without contact.
    pub ticks_without_contact: usize,
    /// Estimation counters.
    pub estimations: EstimationCounters,
    /// Distance travelled along the surface (m).
    pub travelled_m: f64,
    /// Run time (s).
    pub duration_s: f64,
    /// The estimator's answers (lockstep runs only).
    #[serde(skip)]
    pub estimates: Vec<crate::sim::EstimateLog>,
    /// The record.
    #[serde(skip)]
    pub samples: Vec<TrackSample>,
}

/// Streams [`MonitorTick`]s into a [`TrackingRun`].
#[derive(Debug, Clone)]
pub struct TrackingMonitor {
    preload: f64,
    period: SlidingWindow,
    sq: f64,
    n: f64,
    max_err: f64,
    worst: f64,
    worst_at: [f64; 2],
    fmin: f64,
    fmax: f64,
    imin: f64,
    imax: f64,
    dev_sq: f64,
    dev_n: f64,
    lost: usize,
    u0: Option<f64>,
    last: MonitorTick,
    ticks: u64,
    samples: Vec<TrackSample>,
}

impl TrackingMonitor {
    /// A monitor for a preload (N), with the dither period in ticks.
    pub fn new(preload: f64, period_ticks: usize) -> Self {
        Self {
            preload,
            period: SlidingWindow::new(period_ticks.max(1)),
            sq: 0.0,
            n: 0.0,
            max_err: 0.0,
            worst: 0.0,
            worst_at: [0.0; 2],
            fmin: f64::INFINITY,
            fmax: f64::NEG_INFINITY,
            imin: f64::INFINITY,
            imax: f64::NEG_INFINITY,
            dev_sq: 0.0,
            dev_n: 0.0,
            lost: 0,
            u0: None,
            last: MonitorTick::default(),
            ticks: 0,
            samples: Vec::new(),
        }
    }

    /// One tick.
    pub fn push(&mut self, m: &MonitorTick) {
        if self.u0.is_none() {
            self.u0 = Some(m.u);
        }
        if !m.contact {
            self.lost += 1;
        }
        let err = crate::math::wrap_angle(m.tangent_estimated - m.tangent_true).to_degrees();
        if m.moving {
            self.sq += err * err;
            self.n += 1.0;
            self.max_err = self.max_err.max(err.abs());
        }
        self.period.push(m.normal_true);
        if m.t >= 0.5 {
            let mean = self.period.mean();
            let dev = (mean - self.preload).abs() / self.preload;
            self.dev_sq += dev * dev;
            self.dev_n += 1.0;
            if dev > self.worst {
                self.worst = dev;
                self.worst_at = [m.t, m.u];
            }
            self.fmin = self.fmin.min(mean);
            self.fmax = self.fmax.max(mean);
            self.imin = self.imin.min(m.normal_true);
            self.imax = self.imax.max(m.normal_true);
        }
        if self.ticks.is_multiple_of(100) {
            self.samples.push(TrackSample {
                t: m.t,
                u_m: m.u,
                true_angle_rad: m.tangent_true,
                estimated_angle_rad: m.tangent_estimated,
                normal_n: m.normal_true,
                moving: m.moving,
            });
        }
        self.ticks += 1;
        self.last = *m;
    }

    /// The figures so far.
    pub fn finish(&self, estimations: EstimationCounters) -> TrackingRun {
        TrackingRun {
            tangent_error_rms_deg: (self.sq / self.n.max(1.0)).sqrt(),
            tangent_error_max_deg: self.max_err,
            worst_normal_deviation: self.worst,
            normal_range_n: [self.fmin, self.fmax],
            worst_normal_at: self.worst_at,
            normal_deviation_rms: (self.dev_sq / self.dev_n.max(1.0)).sqrt(),
            instantaneous_normal_range_n: [self.imin, self.imax],
            ticks_without_contact: self.lost,
            estimations,
            travelled_m: self.last.u - self.u0.unwrap_or(self.last.u),
            duration_s: self.last.t,
            estimates: Vec::new(),
            samples: self.samples.clone(),
        }
    }
}

/// Friction-suppression figures (as `fig4.8`'s, for one tuner).
#[derive(Debug, Clone, Serialize)]
pub struct FrictionRun {
    /// Mean friction before tuning, 0.15 s to 0.5 s (N).
    pub start_mean_n: f64,
    /// Mean over the last 3 whole dither periods (N).
    pub end_mean_n: f64,
    /// end / start.
    pub end_ratio: f64,
    /// First time after tuning started that the 3-period mean fell below 25 % of the start (s).
    pub time_to_quarter_s: Option<f64>,
    /// Worst |F_N − preload| / preload after 0.5 s, true force.
    pub worst_normal_deviation: f64,
    /// Commanded Aω averaged over the last second (m/s).
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

    fn note_invalid(&mut self, seq: u64) {
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
        self.tracking.push(&m);
        if s.estimations_requested as usize > self.counters.requested {
            self.requested.push(s.seq);
        }
        self.counters = EstimationCounters {
            started: s.estimations_started as usize,
            requested: s.estimations_requested as usize,
            estimates: s.estimates as usize,
            reprobes: s.reprobes as usize,
            failures: s.failures as usize,
            aborted: s.aborted as usize,
            safe_entries: s.safe_entries as usize,
            ..self.counters
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
            scenario: self.kind.name(),
            ticks: self.count,
            safe_ticks: self.safe_ticks,
            duration_s: tracking.duration_s,
            tracking,
            friction,
        }
    }
}

/// What a scenario run measured.
#[derive(Debug, Clone, Serialize)]
pub struct ScenarioReport {
    /// Scenario name.
    pub scenario: &'static str,
    /// Servo ticks seen.
    pub ticks: u64,
    /// Ticks in the safe state.
    pub safe_ticks: u64,
    /// Simulated time covered (s).
    pub duration_s: f64,
    /// Tangent tracking and force regulation.
    pub tracking: TrackingRun,
    /// Friction suppression (`friction-suppression` only).
    pub friction: Option<FrictionRun>,
}

/// Runs `scenario` for `duration_s` (or to its end) in the lockstep simulation: the reference
/// the real-time stack is compared with. Tick `seq` (from 1, as the servo numbers them) steps
/// the world from simulated time (seq − 1)·dt.
pub fn run_lockstep(scenario: &Scenario, duration_s: f64) -> Result<ScenarioReport, ScenarioError> {
    run_lockstep_replay(scenario, duration_s, &Replay::default())
}

/// Events of a real-time run that the lockstep reference goes through at the same ticks
/// ([`ScenarioMonitor::replay`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct Replay<'a> {
    /// Ticks whose force data the servo could not use, in order.
    pub force_invalid: &'a [TickRange],
    /// Ticks at which the servo started an estimation it was asked for, in order.
    pub requested: &'a [u64],
    /// Ticks run first by a restarted servo, in order.
    pub servo_restarts: &'a [u64],
}

/// [`run_lockstep`], going through the real-time run's events at the same ticks (`replay`,
/// from [`ScenarioMonitor::replay`]): the servo's force input is made invalid on the ticks the
/// stack could not use its force data, so the reference goes through the same safe-state
/// episodes (a scheduling hiccup of the machine aborts a probe run and shifts every later
/// event: part of both runs rather than a disagreement), the servo is asked for a tangent
/// estimate on the ticks the stack's servo started one on request, and it is restarted from
/// its own state ([`Lockstep::restart_servo`]) before the ticks a restarted servo ran first.
pub fn run_lockstep_replay(
    scenario: &Scenario,
    duration_s: f64,
    replay: &Replay<'_>,
) -> Result<ScenarioReport, ScenarioError> {
    let invalid = replay.force_invalid;
    let mut sim = Lockstep::new(&scenario.cfg)?;
    let mut driver = scenario.driver();
    let mut monitor = scenario.monitor();
    let dt = sim.dt();
    let limit = (duration_s.min(scenario.natural_duration_s) / dt).round() as u64;
    let mut next = 0;
    for seq in 1..=limit {
        let t = (seq - 1) as f64 * dt;
        let u = sim.truth().surface_u_m;
        if replay.servo_restarts.binary_search(&seq).is_ok() {
            sim.restart_servo()
                .map_err(|reason| ScenarioError::Restart { tick: seq, reason })?;
        }
        if driver.step(t, u, sim.servo_mut()) == DriverState::Done {
            break;
        }
        while next < invalid.len() && invalid[next].first + invalid[next].len <= seq {
            next += 1;
        }
        let valid = !invalid.get(next).is_some_and(|r| r.contains(seq));
        sim.set_force_valid(valid);
        if replay.requested.binary_search(&seq).is_ok() {
            sim.servo_mut().request_tangent_estimate();
        }
        sim.step();
        let p = plant_sample(sim.truth(), seq, 0);
        let mut s = servo_sample(sim.servo(), seq, 0, sim.time());
        if valid {
            s.flags |= ServoFlags::FORCE_VALID;
        }
        monitor.push(&p, &s);
    }
    let mut report = monitor.report();
    report.tracking.estimates = sim.estimates().to_vec();
    Ok(report)
}

/// One compared figure.
#[derive(Debug, Clone, Serialize)]
pub struct Compared {
    /// Figure.
    pub name: &'static str,
    /// Real-time stack.
    pub stack: f64,
    /// Lockstep reference.
    pub reference: f64,
    /// Allowed |stack − reference|.
    pub tolerance: f64,
    /// Within tolerance.
    pub agrees: bool,
}

/// How the real-time stack's figures compare with the lockstep reference's.
#[derive(Debug, Clone, Serialize)]
pub struct Agreement {
    /// Every figure within its tolerance.
    pub agrees: bool,
    /// The figures.
    pub figures: Vec<Compared>,
}

/// Compares a stack run with its lockstep reference. The tolerances (justified in
/// `docs/stack.md`): the stack's sensor samples on its own clock, so its noise meets the plant
/// at other instants and its force data is 0.1–0.3 ms older; the estimator answers a few
/// milliseconds later; a scheduling hiccup longer than the force-age limit sends the servo to
/// its safe state for some tens of milliseconds. These move the figures by amounts of the
/// order of their seed-to-seed spread, which is what the tolerances allow. The worst
/// period-mean force deviation is reported but not compared: one safe-state episode sets it.
pub fn compare(stack: &ScenarioReport, reference: &ScenarioReport) -> Agreement {
    let mut figures = Vec::new();
    let mut add = |name: &'static str, a: f64, b: f64, tol: f64| {
        let agrees = (a - b).abs() <= tol || (a.is_nan() && b.is_nan());
        figures.push(Compared {
            name,
            stack: a,
            reference: b,
            tolerance: tol,
            agrees,
        });
    };
    let (s, r) = (&stack.tracking, &reference.tracking);
    add(
        "tangent error RMS (deg)",
        s.tangent_error_rms_deg,
        r.tangent_error_rms_deg,
        0.25 + 0.25 * r.tangent_error_rms_deg,
    );
    add(
        "RMS period-mean normal-force deviation (fraction)",
        s.normal_deviation_rms,
        r.normal_deviation_rms,
        0.01 + 0.25 * r.normal_deviation_rms,
    );
    add(
        "tangent estimates completed",
        s.estimations.estimates as f64,
        r.estimations.estimates as f64,
        1.0,
    );
    if let (Some(sf), Some(rf)) = (&stack.friction, &reference.friction) {
        add(
            "mean friction before tuning (N)",
            sf.start_mean_n,
            rf.start_mean_n,
            0.1 * rf.start_mean_n.abs(),
        );
        add(
            "mean friction at the end / before tuning",
            sf.end_ratio,
            rf.end_ratio,
            0.05,
        );
        add(
            "settled Aω (m/s)",
            sf.settled_a_omega_m_per_s,
            rf.settled_a_omega_m_per_s,
            0.15 * rf.settled_a_omega_m_per_s.abs(),
        );
    }
    Agreement {
        agrees: figures.iter().all(|f| f.agrees),
        figures,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unknown names are refused with the list of known ones; every known one builds.
    #[test]
    fn scenarios_build_by_name() {
        let base = SimConfig::default();
        for n in NAMES {
            let s = Scenario::new(n, &base).unwrap();
            assert_eq!(s.kind.name(), n);
        }
        let e = Scenario::new("nope", &base).unwrap_err();
        assert!(matches!(e, ScenarioError::Unknown(_)), "{e:?}");
        assert!(e.to_string().contains("surface-tracking"), "{e}");
    }

    /// The surface-tracking scenario run through the lockstep gives the same figures, bit for
    /// bit, as the `fig5.6` experiment's code over the same 3 s (one monitor measures both).
    #[test]
    fn lockstep_reference_matches_the_experiment_code() {
        let base = SimConfig::default();
        let s = Scenario::new("surface-tracking", &base).unwrap();
        let r = run_lockstep(&s, 3.0).unwrap();
        assert_eq!(r.ticks, 30_000);
        let e = crate::experiments::run_tracking(
            &s.cfg,
            TRACKING_VELOCITY,
            s.end_u_m.unwrap(),
            5.0 * TRACKING_VELOCITY,
            3.0,
        )
        .unwrap();
        assert_eq!(r.tracking.tangent_error_rms_deg, e.tangent_error_rms_deg);
        assert_eq!(r.tracking.worst_normal_deviation, e.worst_normal_deviation);
        assert_eq!(r.tracking.travelled_m, e.travelled_m);
        assert_eq!(r.tracking.ticks_without_contact, 0);
        let c = compare(&r, &r);
        assert!(c.agrees);
    }

    /// Replaying force-invalid ticks: the reference goes through the same safe-state episodes
    /// at the same ticks and its monitor sees exactly the replayed ranges; with none it is the
    /// plain reference, bit for bit.
    #[test]
    fn the_reference_replays_the_stacks_invalid_force_ticks() {
        let base = SimConfig::default();
        let s = Scenario::new("surface-tracking", &base).unwrap();
        let plain = run_lockstep(&s, 1.0).unwrap();
        let none = run_lockstep_replay(&s, 1.0, &Replay::default()).unwrap();
        assert_eq!(
            plain.tracking.tangent_error_rms_deg,
            none.tracking.tangent_error_rms_deg
        );
        assert_eq!(none.safe_ticks, 0);
        let gaps = [
            TickRange {
                first: 3000,
                len: 25,
            },
            TickRange {
                first: 6000,
                len: 1,
            },
        ];
        let replayed = run_lockstep_replay(
            &s,
            1.0,
            &Replay {
                force_invalid: &gaps,
                ..Replay::default()
            },
        )
        .unwrap();
        // Each gap enters the safe state, which lasts until the data has been good for the
        // recovery time (20 ms = 200 ticks) after the gap.
        assert!(replayed.safe_ticks >= 2 * 200, "{}", replayed.safe_ticks);
        assert!(
            replayed.safe_ticks <= 25 + 1 + 2 * 201,
            "{}",
            replayed.safe_ticks
        );
        let mut m = s.monitor();
        for r in gaps {
            for seq in r.first..r.first + r.len {
                m.note_invalid(seq);
            }
        }
        assert_eq!(m.force_invalid(), gaps);
    }

    /// The friction-id driver strokes back and forth at each speed and then stops.
    #[test]
    fn friction_id_driver_visits_every_speed() {
        let base = SimConfig::default();
        let s = Scenario::new("friction-id", &base).unwrap();
        let mut sim = Lockstep::new(&s.cfg).unwrap();
        let mut d = s.driver();
        let mut seen = Vec::new();
        let dt = sim.dt();
        let mut k = 0u64;
        loop {
            let t = k as f64 * dt;
            if d.step(t, sim.truth().surface_u_m, sim.servo_mut()) == DriverState::Done {
                break;
            }
            let v = sim.servo().hybrid().velocity_target();
            if v != 0.0 && seen.last() != Some(&v) {
                seen.push(v);
            }
            sim.step();
            k += 1;
            assert!(t < s.natural_duration_s, "did not finish");
        }
        let expected: Vec<f64> = ID_SPEEDS.iter().flat_map(|v| [*v, -*v]).collect();
        assert_eq!(seen, expected);
    }

    /// The estimator's on-line identification, fed the friction-id scenario's servo samples
    /// from the lockstep, finds F_t within 5 % and μ within 5 % of the configured law.
    #[test]
    fn online_identification_on_the_friction_id_scenario() {
        let base = SimConfig::default();
        let s = Scenario::new("friction-id", &base).unwrap();
        let mut sim = Lockstep::new(&s.cfg).unwrap();
        let mut d = s.driver();
        let mut id = crate::ident::OnlineFrictionId::new(0.2, 0.25, 4096);
        let dt = sim.dt();
        for seq in 0.. {
            let t = seq as f64 * dt;
            if d.step(t, sim.truth().surface_u_m, sim.servo_mut()) == DriverState::Done {
                break;
            }
            sim.step();
            let mut ss = servo_sample(sim.servo(), seq, 0, sim.time());
            ss.flags |= ServoFlags::FORCE_VALID;
            id.push(&ident_tick(&ss));
        }
        let r = id.report();
        let truth = s.cfg.plant.friction;
        eprintln!("{r:?} truth {truth:?}");
        assert_eq!(r.speeds, ID_SPEEDS.len());
        let fit = r.fit.expect("a fit").law;
        assert!(
            (fit.kinetic_n / truth.kinetic_n - 1.0).abs() < 0.05,
            "{fit:?}"
        );
        let (mu, _) = r.mu.unwrap();
        let ref_n = s.cfg.plant.reference_normal_force_n;
        let mu_true = truth.resistance(0.048) / ref_n;
        assert!((mu / mu_true - 1.0).abs() < 0.05, "μ {mu} vs {mu_true}");
    }
}
