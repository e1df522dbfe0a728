//! The messages the afs processes exchange over iceoryx2 shared memory.
//!
//! Every type is `#[repr(C)]`, fixed-size (or a slice of a fixed-size element), free of
//! pointers, and derives `ZeroCopySend` with a stable `#[type_name]` so that a client in another
//! language (iceoryx2's C, C++ or Python bindings) can subscribe with a struct of the same
//! layout and name. Each starts with a `version` ([`VERSION`]); each carries a sequence number
//! and the timestamps of its life on one clock: `CLOCK_MONOTONIC` in nanoseconds, the same for
//! every process on the machine. Byte layouts and service names: `docs/messages.md` (checked by
//! the tests below).
//!
//! Conversions to and from the core's types ([`TangentOutcome`], [`TangentParams`],
//! [`ProbePlan`]) live here so that both ends of a service use the same code.

use crate::arm::JointServoState;
use crate::dither::DitherState;
use crate::error::ConfigError;
use crate::hybrid::HybridState;
use crate::sensor::Wrench;
use crate::servo::{EstimationCounters, ServoDiag, ServoMode, ServoState};
use crate::tangent::{
    MAX_PROBES, ProbePlan, ReprobeReason, TangentError, TangentEstimate, TangentMethod,
    TangentOutcome, TangentParams,
};
use crate::tuner::TunerState;
use crate::window::{PeriodWindowState, SlidingSummary};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

/// Layout version of every message; a reader refuses other versions.
pub const VERSION: u32 = 1;

/// Service names. Stacks are isolated by the iceoryx2 file prefix (`afs_<prefix>_`), not by the
/// names, so a client opens these names with the stack's config.
pub mod service {
    /// [`PlantSample`](super::PlantSample), every servo tick (servo → sensor, recorder).
    pub const PLANT: &str = "afs/plant/state";
    /// [`WrenchSample`](super::WrenchSample), every sensor sample (sensor → servo).
    pub const WRENCH: &str = "afs/sensor/wrench";
    /// [`ServoSample`](super::ServoSample), every servo tick.
    pub const SERVO: &str = "afs/servo/state";
    /// [`LoopStats`](super::LoopStats), 10 Hz.
    pub const LOOP_STATS: &str = "afs/servo/loop_stats";
    /// Request-response: [`TangentRequestHeader`](super::TangentRequestHeader) +
    /// `[ProbeSample]` → [`TangentResponse`](super::TangentResponse).
    pub const TANGENT: &str = "afs/estimator/tangent";
    /// Request-response: [`RotationRequestHeader`](super::RotationRequestHeader) +
    /// `[RotationSample]` → [`RotationResponse`](super::RotationResponse).
    pub const ROTATION: &str = "afs/estimator/rotation";
    /// [`FrictionReport`](super::FrictionReport), about 1 Hz.
    pub const FRICTION: &str = "afs/estimator/friction";
    /// [`SupervisorStatus`](super::SupervisorStatus), 2 Hz.
    pub const SUPERVISOR: &str = "afs/supervisor/status";
    /// [`BoardStartup`](super::BoardStartup), once per board process (boards → supervisor).
    pub const STARTUP: &str = "afs/boards/startup";
    /// [`ServoCommand`], on demand (supervisor, clients → servo).
    pub const COMMAND: &str = "afs/servo/command";
    /// Blackboard of the world's state (key 0: [`WorldSnapshot`](super::WorldSnapshot)),
    /// owned by the supervisor, written by the servo.
    pub const WORLD: &str = "afs/plant/world";
}

/// The world, every servo tick: what the plant simulation knows and the controller does not.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::PlantSample")]
#[repr(C)]
pub struct PlantSample {
    /// [`VERSION`].
    pub version: u32,
    /// Number of contacts (0, 1, 2).
    pub contact_count: u32,
    /// Servo tick index since the world started.
    pub seq: u64,
    /// Monotonic time the tick woke (ns).
    pub tick_ns: u64,
    /// Monotonic time of publication (ns).
    pub publish_ns: u64,
    /// Simulated time (s).
    pub time_s: f64,
    /// Joint angles (rad).
    pub q_rad: [f64; 2],
    /// Joint rates (rad/s).
    pub qd_rad_per_s: [f64; 2],
    /// Tool tip (m, world).
    pub tip_m: [f64; 2],
    /// Tool tip velocity (m/s, world).
    pub tip_velocity_m_per_s: [f64; 2],
    /// Total contact force on the tool (N, world).
    pub contact_force_n: [f64; 2],
    /// Force the sensor feels (N, sensor frame: x along link 2).
    pub sensor_force_n: [f64; 2],
    /// Moment the sensor feels (N·m).
    pub sensor_torque_nm: f64,
    /// Sum of normal pushes (N).
    pub normal_force_n: f64,
    /// Friction along the contact tangent (N).
    pub friction_force_n: f64,
    /// Sliding velocity along the contact tangent (m/s).
    pub sliding_velocity_m_per_s: f64,
    /// Penetration (m).
    pub depth_m: f64,
    /// Surface coordinate of the contact (m).
    pub surface_u_m: f64,
    /// True tangent angle at the contact (rad, world).
    pub tangent_angle_rad: f64,
    /// Joint torques applied (N·m).
    pub torque_nm: [f64; 2],
}

impl PlantSample {
    /// The wrench the sensor feels.
    pub fn sensor_wrench(&self) -> Wrench {
        Wrench {
            force: crate::math::Vec2::new(self.sensor_force_n[0], self.sensor_force_n[1]),
            torque: self.sensor_torque_nm,
        }
    }
}

/// Flag of [`WrenchSample::flags`]: an axis hit its rated range.
pub const WRENCH_SATURATED: u32 = 1;
/// [`WrenchSample::flags`]: a bad sample `afs chaos` injected (for the recording and the
/// supervisor; the servo's gate judges samples by their content, never by this flag).
pub const WRENCH_INJECTED: u32 = 1 << 31;

/// One force-sensor sample.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::WrenchSample")]
#[repr(C)]
pub struct WrenchSample {
    /// [`VERSION`].
    pub version: u32,
    /// [`WRENCH_SATURATED`].
    pub flags: u32,
    /// Sensor sample index since the sensor process started.
    pub seq: u64,
    /// Monotonic time the sensor process started (ns): a restarted sensor has a later epoch
    /// and numbers its samples from 0 again.
    pub epoch_ns: u64,
    /// `seq` of the [`PlantSample`] sampled.
    pub plant_seq: u64,
    /// Its `tick_ns`.
    pub plant_tick_ns: u64,
    /// Monotonic time of the sample (ns).
    pub sample_ns: u64,
    /// Monotonic time of publication (ns).
    pub publish_ns: u64,
    /// Measured force (N, sensor frame).
    pub force_n: [f64; 2],
    /// Measured moment (N·m).
    pub torque_nm: f64,
    /// The zero-load reading taken in free air at start-up, to subtract (N).
    pub tare_force_n: [f64; 2],
    /// Its moment (N·m).
    pub tare_torque_nm: f64,
}

impl WrenchSample {
    /// The reading as a [`Wrench`].
    pub fn wrench(&self) -> Wrench {
        Wrench {
            force: crate::math::Vec2::new(self.force_n[0], self.force_n[1]),
            torque: self.torque_nm,
        }
    }

    /// The tare as a [`Wrench`].
    pub fn tare(&self) -> Wrench {
        Wrench {
            force: crate::math::Vec2::new(self.tare_force_n[0], self.tare_force_n[1]),
            torque: self.tare_torque_nm,
        }
    }
}

/// [`ServoSample::flags`]: the servo is in its safe state.
pub const SERVO_SAFE: u32 = 1;
/// [`ServoSample::flags`]: the force sample used this tick passed the checks.
pub const SERVO_FORCE_VALID: u32 = 2;
/// [`ServoSample::flags`]: the set-point was out of reach and held.
pub const SERVO_SETPOINT_HELD: u32 = 4;
/// [`ServoSample::flags`]: the servo waits for the estimator.
pub const SERVO_AWAITING_ESTIMATE: u32 = 8;

/// The controller's state, every servo tick.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::ServoSample")]
#[repr(C)]
pub struct ServoSample {
    /// [`VERSION`].
    pub version: u32,
    /// [`ServoMode`] as its wire code (`u32::from`, `ServoMode::try_from`).
    pub mode: u32,
    /// `SERVO_*` flags.
    pub flags: u32,
    /// Why the safe state was last entered ([`crate::watchdog::Verdict`] code, 0 = never).
    pub safe_reason: u32,
    /// Servo tick index (the same as the [`PlantSample`] of the tick).
    pub seq: u64,
    /// Monotonic time the tick woke (ns).
    pub tick_ns: u64,
    /// `seq` of the [`WrenchSample`] used (u64::MAX: none yet).
    pub wrench_seq: u64,
    /// Its `sample_ns`.
    pub wrench_sample_ns: u64,
    /// Age of the force data at use: tick time − sample time (ns).
    pub force_age_ns: u64,
    /// Monotonic time of publication (ns).
    pub publish_ns: u64,
    /// Simulated time (s).
    pub time_s: f64,
    /// Measured normal force (N).
    pub normal_force_n: f64,
    /// Measured tangential force (N).
    pub tangential_force_n: f64,
    /// Friction resisting the motion, normalised to the model's reference force (N).
    pub friction_normalized_n: f64,
    /// Commanded Aω (m/s).
    pub a_omega_m_per_s: f64,
    /// Dither amplitude (m).
    pub dither_amplitude_m: f64,
    /// Dither phase (rad).
    pub dither_phase_rad: f64,
    /// Nominal tangential velocity (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Requested nominal velocity (m/s): the nominal velocity ramps towards it.
    pub velocity_target_m_per_s: f64,
    /// Measured tip velocity along the estimated tangent (m/s).
    pub tangent_velocity_m_per_s: f64,
    /// Estimated tangent angle (rad, world).
    pub tangent_angle_rad: f64,
    /// Cartesian set-point (m, world).
    pub set_point_m: [f64; 2],
    /// Joint torques (N·m).
    pub torque_nm: [f64; 2],
    /// Estimations started.
    pub estimations_started: u32,
    /// Accepted estimates.
    pub estimates: u32,
    /// Re-probes.
    pub reprobes: u32,
    /// Failed estimations.
    pub failures: u32,
    /// Estimations abandoned because the force data was lost mid-probe (the safe state).
    pub aborted: u32,
    /// Entries into the safe state.
    pub safe_entries: u32,
    /// Estimations started because they were asked for ([`ServoCommand`]).
    pub estimations_requested: u32,
    /// Reserved (0).
    pub reserved: u32,
}

impl ServoSample {
    /// Fills the controller fields from the core's diagnostics and counters.
    pub fn set_diag(&mut self, d: &ServoDiag, c: &EstimationCounters) {
        self.velocity_target_m_per_s = d.velocity_target_m_per_s;
        if d.safe {
            self.flags |= SERVO_SAFE;
        } else {
            self.flags &= !SERVO_SAFE;
        }
        if d.setpoint_held {
            self.flags |= SERVO_SETPOINT_HELD;
        } else {
            self.flags &= !SERVO_SETPOINT_HELD;
        }
        if d.mode == ServoMode::AwaitingEstimate {
            self.flags |= SERVO_AWAITING_ESTIMATE;
        } else {
            self.flags &= !SERVO_AWAITING_ESTIMATE;
        }
        self.mode = d.mode.into();
        self.normal_force_n = d.normal_force_n;
        self.tangential_force_n = d.tangential_force_n;
        self.friction_normalized_n = d.friction_normalized_n;
        self.a_omega_m_per_s = d.a_omega_m_per_s;
        self.dither_amplitude_m = d.dither_amplitude_m;
        self.dither_phase_rad = d.dither_phase;
        self.nominal_velocity_m_per_s = d.nominal_velocity_m_per_s;
        self.tangent_velocity_m_per_s = d.tangent_velocity_m_per_s;
        self.tangent_angle_rad = d.tangent_angle_rad;
        self.set_point_m = [d.set_point.x, d.set_point.y];
        self.torque_nm = [d.torque[0], d.torque[1]];
        let n = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        self.estimations_started = n(c.started);
        self.estimates = n(c.estimates);
        self.reprobes = n(c.reprobes);
        self.failures = n(c.failures);
        self.aborted = n(c.aborted);
        self.safe_entries = n(c.safe_entries);
        self.estimations_requested = n(c.requested);
    }
}

/// [`ServoCommand::command`]: estimate the tangent now (stop, probe, wait for the estimate,
/// resume), or as soon as the servo tracks again, unless an estimation started since the
/// command was sent (`started_before`).
pub const COMMAND_ESTIMATE_TANGENT: u32 = 1;

/// A command to the servo (thesis §5.3.2: surface tracking on demand).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::ServoCommand")]
#[repr(C)]
pub struct ServoCommand {
    /// [`VERSION`].
    pub version: u32,
    /// `COMMAND_*`.
    pub command: u32,
    /// Sender's sequence number.
    pub seq: u64,
    /// Monotonic time of publication (ns).
    pub publish_ns: u64,
    /// [`COMMAND_ESTIMATE_TANGENT`]: the servo's `estimations_started` the sender last saw; the
    /// command lapses once more estimations than this have started.
    pub started_before: u32,
    /// Reserved (0).
    pub reserved: u32,
}

/// Percentiles of a latency distribution (ns).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::Quantiles")]
#[repr(C)]
pub struct Quantiles {
    /// Median.
    pub p50: u64,
    /// 90th percentile.
    pub p90: u64,
    /// 99th percentile.
    pub p99: u64,
    /// 99.9th percentile.
    pub p999: u64,
    /// 99.99th percentile.
    pub p9999: u64,
    /// Largest.
    pub max: u64,
}

/// [`LoopStats::flags`]: running at SCHED_FIFO.
pub const STATS_SCHED_FIFO: u32 = 1;
/// [`LoopStats::flags`]: memory locked (mlockall).
pub const STATS_MLOCKED: u32 = 2;
/// [`LoopStats::flags`]: pinned to a CPU.
pub const STATS_PINNED: u32 = 4;

/// The servo loop's statistics since it started, published at 10 Hz.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::LoopStats")]
#[repr(C)]
pub struct LoopStats {
    /// [`VERSION`].
    pub version: u32,
    /// `STATS_*` flags.
    pub flags: u32,
    /// Publication index.
    pub seq: u64,
    /// Monotonic time of publication (ns).
    pub publish_ns: u64,
    /// Servo period (ns).
    pub period_ns: u64,
    /// Ticks run.
    pub ticks: u64,
    /// Ticks that woke a whole period or more late, or overran their period.
    pub misses: u64,
    /// Wake-up latency: actual − scheduled wake time (ns).
    pub wake_latency: Quantiles,
    /// Execution time of a tick (ns).
    pub exec: Quantiles,
    /// Age of the force data at use (ns).
    pub force_age: Quantiles,
    /// Force samples rejected: a non-finite value.
    pub bad_non_finite: u64,
    /// Force samples rejected: beyond the sensor's range.
    pub bad_out_of_range: u64,
    /// Force samples rejected: sequence number repeated.
    pub bad_seq_repeat: u64,
    /// Force samples rejected: sequence number went backwards.
    pub bad_seq_backwards: u64,
    /// Force samples rejected: timestamp in the future.
    pub bad_future: u64,
    /// Force samples rejected: wrong message version.
    pub bad_version: u64,
    /// Ticks whose latest force sample was older than the limit.
    pub stale_ticks: u64,
    /// Entries into the safe state.
    pub safe_entries: u64,
    /// Ticks spent in the safe state.
    pub safe_ticks: u64,
    /// Estimator requests sent (including retries).
    pub requests: u64,
    /// Requests re-sent after a time-out.
    pub retries: u64,
    /// Answers received.
    pub answers: u64,
    /// Samples the servo could not publish (no memory to loan).
    pub publish_failures: u64,
    /// Commands received ([`ServoCommand`]).
    pub commands: u64,
    /// Commands refused (unknown version or command code).
    pub bad_commands: u64,
}

/// The tangent estimator's settings, as sent with each request (the estimator is stateless).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::TangentParamsMsg")]
#[repr(C)]
pub struct TangentParamsMsg {
    /// Whole periods per probe.
    pub periods: u32,
    /// Padding (0).
    pub reserved: u32,
    /// [`TangentParams::probe_angles_deg`].
    pub probe_angles_deg: [f64; 2],
    /// [`TangentParams::reprobe_angles_deg`].
    pub reprobe_angles_deg: [f64; 2],
    /// [`TangentParams::amplitude_m`].
    pub amplitude_m: f64,
    /// [`TangentParams::frequency_hz`].
    pub frequency_hz: f64,
    /// [`TangentParams::ramp_s`].
    pub ramp_s: f64,
    /// [`TangentParams::settle_s`].
    pub settle_s: f64,
    /// [`TangentParams::sign_threshold`].
    pub sign_threshold: f64,
    /// [`TangentParams::equal_threshold`].
    pub equal_threshold: f64,
    /// [`TangentParams::max_std_error_deg`].
    pub max_std_error_deg: f64,
    /// [`TangentParams::contact_loss_fraction`].
    pub contact_loss_fraction: f64,
    /// [`TangentParams::noise_std_n`].
    pub noise_std_n: f64,
}

impl From<&TangentParams> for TangentParamsMsg {
    fn from(p: &TangentParams) -> Self {
        Self {
            periods: u32::try_from(p.periods).unwrap_or(u32::MAX),
            reserved: 0,
            probe_angles_deg: p.probe_angles_deg,
            reprobe_angles_deg: p.reprobe_angles_deg,
            amplitude_m: p.amplitude_m,
            frequency_hz: p.frequency_hz,
            ramp_s: p.ramp_s,
            settle_s: p.settle_s,
            sign_threshold: p.sign_threshold,
            equal_threshold: p.equal_threshold,
            max_std_error_deg: p.max_std_error_deg,
            contact_loss_fraction: p.contact_loss_fraction,
            noise_std_n: p.noise_std_n,
        }
    }
}

impl TangentParamsMsg {
    /// Back to the core's settings, checked.
    pub fn to_params(&self) -> Result<TangentParams, ConfigError> {
        let p = TangentParams {
            probe_angles_deg: self.probe_angles_deg,
            reprobe_angles_deg: self.reprobe_angles_deg,
            amplitude_m: self.amplitude_m,
            frequency_hz: self.frequency_hz,
            periods: self.periods as usize,
            ramp_s: self.ramp_s,
            settle_s: self.settle_s,
            sign_threshold: self.sign_threshold,
            equal_threshold: self.equal_threshold,
            max_std_error_deg: self.max_std_error_deg,
            contact_loss_fraction: self.contact_loss_fraction,
            noise_std_n: self.noise_std_n,
        };
        p.validate()?;
        Ok(p)
    }
}

/// A probe plan on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::ProbePlanMsg")]
#[repr(C)]
pub struct ProbePlanMsg {
    /// Number of probes (≤ 6).
    pub count: u32,
    /// Whole periods per probe.
    pub periods: u32,
    /// Offsets δα_i from the estimated tangent (rad).
    pub offsets_rad: [f64; MAX_PROBES],
    /// Stroke amplitude (m).
    pub amplitude_m: f64,
    /// Stroke frequency (Hz).
    pub frequency_hz: f64,
    /// Ramp in and out (s).
    pub ramp_s: f64,
    /// Hold before the first probe (s).
    pub settle_s: f64,
    /// Friction-suppression dither frequency during the strokes (Hz, 0: none).
    pub dither_hz: f64,
}

impl From<&ProbePlan> for ProbePlanMsg {
    fn from(p: &ProbePlan) -> Self {
        Self {
            count: u32::try_from(p.count).unwrap_or(u32::MAX),
            periods: u32::try_from(p.periods).unwrap_or(u32::MAX),
            offsets_rad: p.offsets,
            amplitude_m: p.amplitude_m,
            frequency_hz: p.frequency_hz,
            ramp_s: p.ramp_s,
            settle_s: p.settle_s,
            dither_hz: p.dither_hz,
        }
    }
}

impl ProbePlanMsg {
    /// Back to the core's plan; `None` if the numbers cannot be a plan.
    pub fn to_plan(&self) -> Option<ProbePlan> {
        let count = self.count as usize;
        let finite = self.offsets_rad.iter().all(|o| o.is_finite())
            && [
                self.amplitude_m,
                self.frequency_hz,
                self.ramp_s,
                self.settle_s,
                self.dither_hz,
            ]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0);
        (count <= MAX_PROBES && self.periods > 0 && self.frequency_hz > 0.0 && finite).then_some(
            ProbePlan {
                offsets: self.offsets_rad,
                count,
                amplitude_m: self.amplitude_m,
                frequency_hz: self.frequency_hz,
                periods: self.periods as usize,
                ramp_s: self.ramp_s,
                settle_s: self.settle_s,
                dither_hz: self.dither_hz,
            },
        )
    }
}

/// Header of a tangent-estimation request; the payload is the `[ProbeSample]` record.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::TangentRequestHeader")]
#[repr(C)]
pub struct TangentRequestHeader {
    /// [`VERSION`].
    pub version: u32,
    /// 1 when the record is a re-probe set.
    pub reprobe: u32,
    /// Identifies the estimation; the same for its retries.
    pub request_id: u64,
    /// 0 for the first send, then 1, 2, … for retries.
    pub attempt: u32,
    /// Padding (0).
    pub reserved: u32,
    /// Monotonic time of sending (ns).
    pub publish_ns: u64,
    /// The estimated tangent angle the offsets refer to (rad, world).
    pub base_angle_rad: f64,
    /// The probes that ran.
    pub plan: ProbePlanMsg,
    /// The estimator's settings.
    pub params: TangentParamsMsg,
}

/// [`TangentResponse::outcome`]: an estimate.
pub const OUTCOME_ESTIMATE: u32 = 0;
/// [`TangentResponse::outcome`]: run [`TangentResponse::plan`] and ask again.
pub const OUTCOME_REPROBE: u32 = 1;
/// [`TangentResponse::outcome`]: no trustworthy estimate ([`TangentResponse::code`] says why).
pub const OUTCOME_FAILED: u32 = 2;
/// [`TangentResponse::outcome`]: the request itself was malformed.
pub const OUTCOME_BAD_REQUEST: u32 = 3;

/// The estimator's answer.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::TangentResponse")]
#[repr(C)]
pub struct TangentResponse {
    /// [`VERSION`].
    pub version: u32,
    /// `OUTCOME_*`.
    pub outcome: u32,
    /// The request's id.
    pub request_id: u64,
    /// Monotonic time of the answer (ns).
    pub publish_ns: u64,
    /// Re-probe reason or error: 1 fold, 2 equal responses, 3 ambiguous (re-probe or
    /// unresolved); 10 contact lost, 11 missing data, 12 too noisy, 13 uncertain.
    pub code: u32,
    /// 0 motion regression, 1 commanded ratio.
    pub method: u32,
    /// Probes used.
    pub probes: u32,
    /// Re-projection iterations.
    pub iterations: u32,
    /// α0 = estimated − true tangent (rad).
    pub alpha0_rad: f64,
    /// Corrected tangent angle (rad, world).
    pub tangent_angle_rad: f64,
    /// Standard error of α0 (rad).
    pub std_error_rad: f64,
    /// Residual RMS (N).
    pub residual_n: f64,
    /// Noise of the in-phase responses (N).
    pub noise_n: f64,
    /// Signal-to-noise ratio.
    pub snr: f64,
    /// Effective contact stiffness (N/m).
    pub stiffness_n_per_m: f64,
    /// Thesis eq. 5.8 cross-check (rad, NaN if none).
    pub thesis_alpha0_rad: f64,
    /// Eq. 6.1 cross-check (rad, NaN if none).
    pub thesis_6_1_alpha0_rad: f64,
    /// Signed-ratio cross-check (rad, NaN if none).
    pub ratio_alpha0_rad: f64,
    /// The two numbers of an error (e.g. probe and force for contact lost).
    pub error_values: [f64; 2],
    /// The re-probe plan.
    pub plan: ProbePlanMsg,
}

fn reason_code(r: ReprobeReason) -> u32 {
    match r {
        ReprobeReason::Fold => 1,
        ReprobeReason::EqualResponses => 2,
        ReprobeReason::Ambiguous => 3,
    }
}

fn reason_from(c: u32) -> Option<ReprobeReason> {
    Some(match c {
        1 => ReprobeReason::Fold,
        2 => ReprobeReason::EqualResponses,
        3 => ReprobeReason::Ambiguous,
        _ => return None,
    })
}

fn opt(v: Option<f64>) -> f64 {
    v.unwrap_or(f64::NAN)
}

fn from_opt(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl TangentResponse {
    /// The wire form of an outcome.
    pub fn from_outcome(request_id: u64, o: &TangentOutcome) -> Self {
        let mut r = Self {
            version: VERSION,
            request_id,
            thesis_alpha0_rad: f64::NAN,
            thesis_6_1_alpha0_rad: f64::NAN,
            ratio_alpha0_rad: f64::NAN,
            ..Default::default()
        };
        match o {
            TangentOutcome::Estimate(e) => {
                r.outcome = OUTCOME_ESTIMATE;
                r.method = match e.method {
                    TangentMethod::MotionRegression => 0,
                    TangentMethod::CommandedRatio => 1,
                };
                r.probes = u32::try_from(e.probes).unwrap_or(u32::MAX);
                r.iterations = u32::try_from(e.iterations).unwrap_or(u32::MAX);
                r.alpha0_rad = e.alpha0_rad;
                r.tangent_angle_rad = e.tangent_angle_rad;
                r.std_error_rad = e.std_error_rad;
                r.residual_n = e.residual_n;
                r.noise_n = e.noise_n;
                r.snr = e.snr;
                r.stiffness_n_per_m = e.stiffness_n_per_m;
                r.thesis_alpha0_rad = opt(e.thesis_alpha0_rad);
                r.thesis_6_1_alpha0_rad = opt(e.thesis_6_1_alpha0_rad);
                r.ratio_alpha0_rad = opt(e.ratio_alpha0_rad);
            }
            TangentOutcome::Reprobe { reason, plan } => {
                r.outcome = OUTCOME_REPROBE;
                r.code = reason_code(*reason);
                r.plan = plan.into();
            }
            TangentOutcome::Failed(err) => {
                r.outcome = OUTCOME_FAILED;
                let (code, a, b) = match *err {
                    TangentError::ContactLost { probe, min_n } => (10, probe as f64, min_n),
                    TangentError::MissingData { probe, samples } => {
                        (11, probe as f64, samples as f64)
                    }
                    TangentError::TooNoisy { signal_n, noise_n } => (12, signal_n, noise_n),
                    TangentError::Uncertain {
                        std_error_deg,
                        limit_deg,
                    } => (13, std_error_deg, limit_deg),
                    TangentError::Unresolved(reason) => (reason_code(reason), 0.0, 0.0),
                };
                r.code = code;
                r.error_values = [a, b];
            }
        }
        r
    }

    /// A refusal of a malformed request.
    pub fn bad_request(request_id: u64) -> Self {
        Self {
            version: VERSION,
            outcome: OUTCOME_BAD_REQUEST,
            request_id,
            ..Default::default()
        }
    }

    /// Back to the core's outcome; `None` for a bad request or a malformed answer.
    pub fn to_outcome(&self) -> Option<TangentOutcome> {
        if self.version != VERSION {
            return None;
        }
        let count = |v: f64| {
            if v.is_finite() && v >= 0.0 {
                v as usize
            } else {
                0
            }
        };
        Some(match self.outcome {
            OUTCOME_ESTIMATE => {
                if !(self.alpha0_rad.is_finite() && self.tangent_angle_rad.is_finite()) {
                    return None;
                }
                TangentOutcome::Estimate(TangentEstimate {
                    alpha0_rad: self.alpha0_rad,
                    tangent_angle_rad: self.tangent_angle_rad,
                    method: if self.method == 1 {
                        TangentMethod::CommandedRatio
                    } else {
                        TangentMethod::MotionRegression
                    },
                    std_error_rad: self.std_error_rad,
                    residual_n: self.residual_n,
                    noise_n: self.noise_n,
                    snr: self.snr,
                    thesis_alpha0_rad: from_opt(self.thesis_alpha0_rad),
                    thesis_6_1_alpha0_rad: from_opt(self.thesis_6_1_alpha0_rad),
                    ratio_alpha0_rad: from_opt(self.ratio_alpha0_rad),
                    stiffness_n_per_m: self.stiffness_n_per_m,
                    probes: self.probes as usize,
                    iterations: self.iterations as usize,
                })
            }
            OUTCOME_REPROBE => TangentOutcome::Reprobe {
                reason: reason_from(self.code)?,
                plan: self.plan.to_plan()?,
            },
            OUTCOME_FAILED => {
                let [a, b] = self.error_values;
                TangentOutcome::Failed(match self.code {
                    10 => TangentError::ContactLost {
                        probe: count(a),
                        min_n: b,
                    },
                    11 => TangentError::MissingData {
                        probe: count(a),
                        samples: count(b),
                    },
                    12 => TangentError::TooNoisy {
                        signal_n: a,
                        noise_n: b,
                    },
                    13 => TangentError::Uncertain {
                        std_error_deg: a,
                        limit_deg: b,
                    },
                    c => TangentError::Unresolved(reason_from(c)?),
                })
            }
            _ => return None,
        })
    }
}

/// One wrench sample of a rotational dither (rotation-centre request payload).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::RotationSample")]
#[repr(C)]
pub struct RotationSample {
    /// Time (s).
    pub t: f64,
    /// Dither phase φ (rad): the commanded rotation is A sin φ.
    pub phase: f64,
    /// Measured force (N, world).
    pub force_n: [f64; 2],
    /// Which dither centre (index into the header's centres).
    pub dither: u32,
    /// Padding (0).
    pub reserved: u32,
}

/// Most dither centres a rotation request can carry.
pub const MAX_CENTRES: usize = 6;

/// Header of a rotation-centre request; the payload is `[RotationSample]`.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::RotationRequestHeader")]
#[repr(C)]
pub struct RotationRequestHeader {
    /// [`VERSION`].
    pub version: u32,
    /// Number of dither centres (3 to 6).
    pub centres: u32,
    /// Request id.
    pub request_id: u64,
    /// Monotonic time of sending (ns).
    pub publish_ns: u64,
    /// Dither centres (m, world).
    pub centre_m: [[f64; 2]; MAX_CENTRES],
    /// Dither amplitude (rad).
    pub amplitude_rad: f64,
    /// Friction-suppression dither superposed (Hz, 0: none), removed before the lock-in.
    pub suppression_hz: f64,
}

/// The rotation-centre answer.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::RotationResponse")]
#[repr(C)]
pub struct RotationResponse {
    /// [`VERSION`].
    pub version: u32,
    /// 0 estimate, 2 failed (singular or too few samples), 3 bad request.
    pub outcome: u32,
    /// The request's id.
    pub request_id: u64,
    /// Monotonic time of the answer (ns).
    pub publish_ns: u64,
    /// Instantaneous centre of rotation P (m, world).
    pub centre_m: [f64; 2],
    /// The thesis's unsigned form (NaN if it found none).
    pub thesis_centre_m: [f64; 2],
    /// Fitted response matrix A = ∂g/∂c, row-major (N per m per rad).
    pub response_matrix: [f64; 4],
    /// |diagonal| / |off-diagonal| of A.
    pub coupling: f64,
}

/// [`FrictionReport::status`]: `mu` holds.
pub const FRICTION_MU_VALID: u32 = 1;
/// [`FrictionReport::status`]: the eq. 4.5 coefficients hold.
pub const FRICTION_LAW_VALID: u32 = 2;

/// On-line friction identification from the streams (estimator, about 1 Hz).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::FrictionReport")]
#[repr(C)]
pub struct FrictionReport {
    /// [`VERSION`].
    pub version: u32,
    /// `FRICTION_*` flags.
    pub status: u32,
    /// Publication index.
    pub seq: u64,
    /// Monotonic time of publication (ns).
    pub publish_ns: u64,
    /// Steady undithered windows used.
    pub windows: u64,
    /// Distinct speed levels seen.
    pub speeds: u32,
    /// Padding (0).
    pub reserved: u32,
    /// Friction coefficient μ = mean friction / mean normal force, latest window.
    pub mu: f64,
    /// Spread of μ over the windows at that speed.
    pub mu_std: f64,
    /// Eq. 4.5: F_t (N at the reference normal force).
    pub kinetic_n: f64,
    /// F_v (N·s/m).
    pub viscous_n_s_per_m: f64,
    /// F_s (N).
    pub stribeck_n: f64,
    /// ẋ_s (m/s).
    pub stribeck_velocity_m_per_s: f64,
    /// RMS residual of the fit (N).
    pub rms_residual_n: f64,
}

/// One process in [`SupervisorStatus`].
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::ProcessStatus")]
#[repr(C)]
pub struct ProcessStatus {
    /// Name, NUL-padded UTF-8.
    pub name: [u8; 16],
    /// Process id (0: not running).
    pub pid: i32,
    /// 0 starting, 1 running, 2 waiting to restart, 3 exited, 4 failed (gave up).
    pub state: u32,
    /// Restarts so far.
    pub restarts: u32,
    /// Last exit status (−signal if killed, i32::MIN if none).
    pub last_exit: i32,
}

/// Most processes a stack can have.
pub const MAX_PROCESSES: usize = 8;

/// The supervisor's view of the stack (2 Hz).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::SupervisorStatus")]
#[repr(C)]
pub struct SupervisorStatus {
    /// [`VERSION`].
    pub version: u32,
    /// Number of valid entries in `processes`.
    pub process_count: u32,
    /// Publication index.
    pub seq: u64,
    /// Monotonic time of publication (ns).
    pub publish_ns: u64,
    /// Supervisor's process id.
    pub pid: i32,
    /// 0 starting, 1 running, 2 stopping.
    pub phase: u32,
    /// Scenario name, NUL-padded.
    pub scenario: [u8; 32],
    /// Seconds since the scenario started.
    pub elapsed_s: f64,
    /// Planned duration (s).
    pub duration_s: f64,
    /// The processes.
    pub processes: [ProcessStatus; MAX_PROCESSES],
}

/// Copies `s` into a NUL-padded fixed buffer (truncating at a character boundary).
pub fn fixed_str<const N: usize>(s: &str) -> [u8; N] {
    let mut out = [0u8; N];
    let mut end = s.len().min(N);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    out[..end].copy_from_slice(&s.as_bytes()[..end]);
    out
}

/// The text of a NUL-padded fixed buffer.
pub fn str_of(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).into_owned()
}

/// The world's state the servo keeps in the supervisor's blackboard so that a restarted servo
/// resumes the world where it was (key 0 of [`service::WORLD`]).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::WorldSnapshot")]
#[repr(C)]
pub struct WorldSnapshot {
    /// [`VERSION`]; 0 means "no snapshot yet".
    pub version: u32,
    /// The scenario driver's leg (friction-id), u32::MAX if none.
    pub driver_leg: u32,
    /// Servo tick the snapshot was taken at; the restarted servo continues at `seq + 1`.
    pub seq: u64,
    /// Simulated time (s).
    pub time_s: f64,
    /// Joint angles (rad).
    pub q_rad: [f64; 2],
    /// Joint rates (rad/s).
    pub qd_rad_per_s: [f64; 2],
    /// Friction slots: face index (u64::MAX empty).
    pub friction_face: [u64; 2],
    /// Friction slots: bristle deflection (m).
    pub friction_deflection_m: [f64; 2],
    /// The driver's leg start: time (s) and surface position (m).
    pub driver_leg_start: [f64; 2],
    /// The controller ([`crate::servo::ServoCore::state`]): a restarted servo carries on
    /// with it.
    pub controller: ServoState,
    /// The world sample of tick `seq`, exactly as published (written before it is sent): a
    /// restarted servo sends it again, so the tick reaches subscribers whether or not its
    /// predecessor died before sending it; a subscriber drops the identical repeat.
    pub plant: PlantSample,
}

/// [`BoardStartup::board`] of the plant/servo board.
pub const BOARD_SERVO: u32 = 0;
/// [`BoardStartup::board`] of the force-sensor board.
pub const BOARD_SENSOR: u32 = 1;
/// [`BoardStartup::board`] of the estimator board.
pub const BOARD_ESTIMATOR: u32 = 2;

/// A board process's start-up, phase by phase, published once when its data first flows: what
/// a (re)start spent its time on. Each field is the monotonic time (ns) the phase ended; 0 if
/// the board has no such phase.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::BoardStartup")]
#[repr(C)]
pub struct BoardStartup {
    /// [`VERSION`].
    pub version: u32,
    /// Which board ([`BOARD_SERVO`], [`BOARD_SENSOR`], [`BOARD_ESTIMATOR`]).
    pub board: u32,
    /// Its process id.
    pub pid: i32,
    /// Reserved (0).
    pub reserved: u32,
    /// `main` entered (after the loader and the command line).
    pub main_ns: u64,
    /// The iceoryx2 node created (with the dead-node clean-up iceoryx2 does on creation).
    pub node_ns: u64,
    /// Its services opened and ports created.
    pub ports_ns: u64,
    /// The board's own preparation done: the sensor model and its tare, the servo's world
    /// restored from the snapshot.
    pub prepared_ns: u64,
    /// First input in hand: the sensor's first world sample, the servo's first good force
    /// sample.
    pub input_ns: u64,
    /// Real-time set-up done (memory locked, pinned, SCHED_FIFO).
    pub rt_ns: u64,
    /// First output published.
    pub data_ns: u64,
}

/// One field of a message's byte layout.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldLayout {
    /// Field name.
    pub name: &'static str,
    /// Type as a C-like spelling (`f64[2]` is two f64).
    pub ty: &'static str,
    /// Byte offset.
    pub offset: usize,
    /// Byte size.
    pub size: usize,
}

/// A message's byte layout, for `docs/messages.md` and clients in other languages.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MessageLayout {
    /// Rust type.
    pub rust: &'static str,
    /// The iceoryx2 type name a client must use.
    pub type_name: &'static str,
    /// Total size (bytes).
    pub size: usize,
    /// Alignment (bytes).
    pub align: usize,
    /// Fields in order.
    pub fields: Vec<FieldLayout>,
}

fn field_size<T, F>(_: fn(&T) -> &F) -> usize {
    core::mem::size_of::<F>()
}

macro_rules! layout {
    ($ty:ty, $rust:literal, [$($field:ident : $fty:literal),* $(,)?]) => {
        MessageLayout {
            rust: $rust,
            // SAFETY: type_name returns the derive attribute's string.
            type_name: unsafe { <$ty as ZeroCopySend>::type_name() },
            size: core::mem::size_of::<$ty>(),
            align: core::mem::align_of::<$ty>(),
            fields: vec![$(FieldLayout {
                name: stringify!($field),
                ty: $fty,
                offset: core::mem::offset_of!($ty, $field),
                size: field_size::<$ty, _>(|x| &x.$field),
            }),*],
        }
    };
}

impl MessageLayout {
    /// The layout as a Markdown table (what `docs/messages.md` shows).
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "### `{}` (type name `{}`, {} bytes, align {})\n\n| offset | size | type | field |\n|---:|---:|---|---|\n",
            self.rust, self.type_name, self.size, self.align
        );
        let mut end = 0;
        for f in &self.fields {
            if f.offset > end {
                s += &format!("| {end} | {} | pad | |\n", f.offset - end);
            }
            s += &format!("| {} | {} | {} | `{}` |\n", f.offset, f.size, f.ty, f.name);
            end = f.offset + f.size;
        }
        if self.size > end {
            s += &format!("| {end} | {} | pad | |\n", self.size - end);
        }
        s
    }
}

/// The layouts of every message, in the order `docs/messages.md` lists them.
pub fn layouts() -> Vec<MessageLayout> {
    vec![
        layout!(WrenchSample, "WrenchSample", [
            version: "u32", flags: "u32", seq: "u64", epoch_ns: "u64", plant_seq: "u64",
            plant_tick_ns: "u64", sample_ns: "u64", publish_ns: "u64", force_n: "f64[2]",
            torque_nm: "f64", tare_force_n: "f64[2]", tare_torque_nm: "f64",
        ]),
        layout!(PlantSample, "PlantSample", [
            version: "u32", contact_count: "u32", seq: "u64", tick_ns: "u64",
            publish_ns: "u64", time_s: "f64", q_rad: "f64[2]", qd_rad_per_s: "f64[2]",
            tip_m: "f64[2]", tip_velocity_m_per_s: "f64[2]", contact_force_n: "f64[2]",
            sensor_force_n: "f64[2]", sensor_torque_nm: "f64", normal_force_n: "f64",
            friction_force_n: "f64", sliding_velocity_m_per_s: "f64", depth_m: "f64",
            surface_u_m: "f64", tangent_angle_rad: "f64", torque_nm: "f64[2]",
        ]),
        layout!(ServoSample, "ServoSample", [
            version: "u32", mode: "u32", flags: "u32", safe_reason: "u32", seq: "u64",
            tick_ns: "u64", wrench_seq: "u64", wrench_sample_ns: "u64", force_age_ns: "u64",
            publish_ns: "u64", time_s: "f64", normal_force_n: "f64",
            tangential_force_n: "f64", friction_normalized_n: "f64", a_omega_m_per_s: "f64",
            dither_amplitude_m: "f64", dither_phase_rad: "f64",
            nominal_velocity_m_per_s: "f64", velocity_target_m_per_s: "f64",
            tangent_velocity_m_per_s: "f64",
            tangent_angle_rad: "f64", set_point_m: "f64[2]", torque_nm: "f64[2]",
            estimations_started: "u32", estimates: "u32", reprobes: "u32", failures: "u32",
            aborted: "u32", safe_entries: "u32", estimations_requested: "u32", reserved: "u32",
        ]),
        layout!(ServoCommand, "ServoCommand", [
            version: "u32", command: "u32", seq: "u64", publish_ns: "u64",
            started_before: "u32", reserved: "u32",
        ]),
        layout!(Quantiles, "Quantiles", [
            p50: "u64", p90: "u64", p99: "u64", p999: "u64", p9999: "u64", max: "u64",
        ]),
        layout!(LoopStats, "LoopStats", [
            version: "u32", flags: "u32", seq: "u64", publish_ns: "u64", period_ns: "u64",
            ticks: "u64", misses: "u64", wake_latency: "Quantiles", exec: "Quantiles",
            force_age: "Quantiles", bad_non_finite: "u64", bad_out_of_range: "u64",
            bad_seq_repeat: "u64", bad_seq_backwards: "u64", bad_future: "u64",
            bad_version: "u64", stale_ticks: "u64", safe_entries: "u64", safe_ticks: "u64",
            requests: "u64", retries: "u64", answers: "u64", publish_failures: "u64",
            commands: "u64", bad_commands: "u64",
        ]),
        layout!(crate::tangent::ProbeSample, "ProbeSample", [
            t: "f64", force: "f64[2]", tip: "f64[2]", phase: "f64", probe: "u8",
            measured: "bool",
        ]),
        layout!(ProbePlanMsg, "ProbePlanMsg", [
            count: "u32", periods: "u32", offsets_rad: "f64[6]", amplitude_m: "f64",
            frequency_hz: "f64", ramp_s: "f64", settle_s: "f64", dither_hz: "f64",
        ]),
        layout!(TangentParamsMsg, "TangentParamsMsg", [
            periods: "u32", reserved: "u32", probe_angles_deg: "f64[2]",
            reprobe_angles_deg: "f64[2]", amplitude_m: "f64", frequency_hz: "f64",
            ramp_s: "f64", settle_s: "f64", sign_threshold: "f64", equal_threshold: "f64",
            max_std_error_deg: "f64", contact_loss_fraction: "f64", noise_std_n: "f64",
        ]),
        layout!(TangentRequestHeader, "TangentRequestHeader", [
            version: "u32", reprobe: "u32", request_id: "u64", attempt: "u32",
            reserved: "u32", publish_ns: "u64", base_angle_rad: "f64", plan: "ProbePlanMsg",
            params: "TangentParamsMsg",
        ]),
        layout!(TangentResponse, "TangentResponse", [
            version: "u32", outcome: "u32", request_id: "u64", publish_ns: "u64",
            code: "u32", method: "u32", probes: "u32", iterations: "u32",
            alpha0_rad: "f64", tangent_angle_rad: "f64", std_error_rad: "f64",
            residual_n: "f64", noise_n: "f64", snr: "f64", stiffness_n_per_m: "f64",
            thesis_alpha0_rad: "f64", thesis_6_1_alpha0_rad: "f64", ratio_alpha0_rad: "f64",
            error_values: "f64[2]", plan: "ProbePlanMsg",
        ]),
        layout!(RotationSample, "RotationSample", [
            t: "f64", phase: "f64", force_n: "f64[2]", dither: "u32", reserved: "u32",
        ]),
        layout!(RotationRequestHeader, "RotationRequestHeader", [
            version: "u32", centres: "u32", request_id: "u64", publish_ns: "u64",
            centre_m: "f64[6][2]", amplitude_rad: "f64", suppression_hz: "f64",
        ]),
        layout!(RotationResponse, "RotationResponse", [
            version: "u32", outcome: "u32", request_id: "u64", publish_ns: "u64",
            centre_m: "f64[2]", thesis_centre_m: "f64[2]", response_matrix: "f64[4]",
            coupling: "f64",
        ]),
        layout!(FrictionReport, "FrictionReport", [
            version: "u32", status: "u32", seq: "u64", publish_ns: "u64", windows: "u64",
            speeds: "u32", reserved: "u32", mu: "f64", mu_std: "f64", kinetic_n: "f64",
            viscous_n_s_per_m: "f64", stribeck_n: "f64", stribeck_velocity_m_per_s: "f64",
            rms_residual_n: "f64",
        ]),
        layout!(ProcessStatus, "ProcessStatus", [
            name: "u8[16]", pid: "i32", state: "u32", restarts: "u32", last_exit: "i32",
        ]),
        layout!(SupervisorStatus, "SupervisorStatus", [
            version: "u32", process_count: "u32", seq: "u64", publish_ns: "u64", pid: "i32",
            phase: "u32", scenario: "u8[32]", elapsed_s: "f64", duration_s: "f64",
            processes: "ProcessStatus[8]",
        ]),
        layout!(BoardStartup, "BoardStartup", [
            version: "u32", board: "u32", pid: "i32", reserved: "u32", main_ns: "u64",
            node_ns: "u64", ports_ns: "u64", prepared_ns: "u64", input_ns: "u64",
            rt_ns: "u64", data_ns: "u64",
        ]),
        layout!(WorldSnapshot, "WorldSnapshot", [
            version: "u32", driver_leg: "u32", seq: "u64", time_s: "f64", q_rad: "f64[2]",
            qd_rad_per_s: "f64[2]", friction_face: "u64[2]",
            friction_deflection_m: "f64[2]", driver_leg_start: "f64[2]",
            controller: "ServoState", plant: "PlantSample",
        ]),
        layout!(ServoState, "ServoState", [
            mode: "u32", flags: "u32", last_trigger: "u32", reserved: "u32",
            counters: "u32[10]", joints: "JointServoState", hybrid: "HybridState",
            dither: "DitherState", tuner: "TunerState", tare: "f64[3]", last_q_d_rad: "f64[2]",
            resume_velocity_m_per_s: "f64", normal_filtered_n: "f64", odometer_m: "f64[2]",
            last_estimate: "f64[2]", curvature_per_m: "f64", curve_base_rad: "f64",
            drift_rad: "f64", stopped_settled_s: "f64[2]", normal_window: "SlidingSummary",
            safe: "f64[4]", resume_a_omega_m_per_s: "f64", last_stroke_m: "f64[2]",
        ]),
        layout!(JointServoState, "JointServoState", [
            integral_rad_s: "f64[2]", integrating: "u32", reserved: "u32",
        ]),
        layout!(HybridState, "HybridState", [
            origin_m: "f64[2]", tangent_angle_rad: "f64", s_m: "f64", s_dot_m_per_s: "f64",
            velocity_target_m_per_s: "f64", depth_m: "f64", depth_rate_m_per_s: "f64",
            preload_n: "f64", hooke_stiffness_n_per_m: "f64",
        ]),
        layout!(DitherState, "DitherState", [
            phase_rad: "f64", amplitude_m: "f64", sin_cos: "f64[2]", wrapped: "u32",
            reserved: "u32",
        ]),
        layout!(TunerState, "TunerState", [
            a_omega_m_per_s: "f64", stribeck_velocity_estimate_m_per_s: "f64",
            transmission: "f64", friction_scale: "f64", window: "SlidingSummary",
            periods: "PeriodWindowState",
        ]),
        layout!(SlidingSummary, "SlidingSummary", [
            len: "u64", mean: "f64", variance: "f64",
        ]),
        layout!(PeriodWindowState, "PeriodWindowState", [
            current: "f64[8]", ring: "f64[16][8]", filled: "u32", head: "u32",
        ]),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/messages.md shows every message's layout exactly as compiled (regenerate it with
    /// `afs messages` after changing a message), and every field is listed: the fields' sizes
    /// plus padding add up to the size.
    #[test]
    fn layouts_match_the_documentation() {
        let doc = include_str!("../../docs/messages.md");
        for l in layouts() {
            let listed: usize = l.fields.iter().map(|f| f.size).sum();
            assert!(listed <= l.size, "{}", l.rust);
            let last = l.fields.last().map_or(0, |f| f.offset + f.size);
            assert!(
                l.size - last < l.align,
                "{}: a field is missing at the end",
                l.rust
            );
            for w in l.fields.windows(2) {
                assert!(
                    w[1].offset - (w[0].offset + w[0].size) < 8,
                    "{}: a field is missing before {}",
                    l.rust,
                    w[1].name
                );
            }
            assert!(
                doc.contains(&l.markdown()),
                "docs/messages.md is out of date for {}; run `afs messages`:\n{}",
                l.rust,
                l.markdown()
            );
        }
    }

    /// The type names clients must use.
    #[test]
    fn type_names_are_stable() {
        // SAFETY: type_name only returns the attribute's string.
        unsafe {
            assert_eq!(
                <WrenchSample as ZeroCopySend>::type_name(),
                "afs::WrenchSample"
            );
            assert_eq!(
                <PlantSample as ZeroCopySend>::type_name(),
                "afs::PlantSample"
            );
            assert_eq!(
                <ServoSample as ZeroCopySend>::type_name(),
                "afs::ServoSample"
            );
            assert_eq!(<LoopStats as ZeroCopySend>::type_name(), "afs::LoopStats");
        }
    }

    /// Every outcome survives the wire.
    #[test]
    fn tangent_outcomes_round_trip() {
        let params = TangentParams::default();
        let outcomes = [
            TangentOutcome::Estimate(TangentEstimate {
                alpha0_rad: 0.01,
                tangent_angle_rad: 0.2,
                method: TangentMethod::MotionRegression,
                std_error_rad: 1e-4,
                residual_n: 0.001,
                noise_n: 0.002,
                snr: 50.0,
                thesis_alpha0_rad: Some(0.011),
                thesis_6_1_alpha0_rad: None,
                ratio_alpha0_rad: Some(0.0105),
                stiffness_n_per_m: 1300.0,
                probes: 2,
                iterations: 3,
            }),
            TangentOutcome::Reprobe {
                reason: ReprobeReason::Fold,
                plan: params.reprobe_plan(),
            },
            TangentOutcome::Failed(TangentError::ContactLost {
                probe: 1,
                min_n: 0.1,
            }),
            TangentOutcome::Failed(TangentError::MissingData {
                probe: 0,
                samples: 3,
            }),
            TangentOutcome::Failed(TangentError::TooNoisy {
                signal_n: 0.01,
                noise_n: 0.02,
            }),
            TangentOutcome::Failed(TangentError::Uncertain {
                std_error_deg: 0.7,
                limit_deg: 0.5,
            }),
            TangentOutcome::Failed(TangentError::Unresolved(ReprobeReason::EqualResponses)),
        ];
        for o in outcomes {
            let wire = TangentResponse::from_outcome(7, &o);
            assert_eq!(wire.request_id, 7);
            assert_eq!(wire.to_outcome(), Some(o), "{o:?}");
        }
        assert_eq!(TangentResponse::bad_request(3).to_outcome(), None);
        let mut wrong = TangentResponse::from_outcome(1, &outcomes[0]);
        wrong.version = 99;
        assert_eq!(wrong.to_outcome(), None);
    }

    /// Settings and plans survive the wire; a malformed one is refused.
    #[test]
    fn params_and_plans_round_trip() {
        let p = TangentParams::default();
        assert_eq!(TangentParamsMsg::from(&p).to_params(), Ok(p));
        let mut bad = TangentParamsMsg::from(&p);
        bad.amplitude_m = f64::NAN;
        assert!(bad.to_params().is_err());
        let plan = p.first_plan();
        assert_eq!(ProbePlanMsg::from(&plan).to_plan(), Some(plan));
        let mut bad = ProbePlanMsg::from(&plan);
        bad.count = 9;
        assert_eq!(bad.to_plan(), None);
    }

    /// Fixed strings truncate on a character boundary and read back.
    #[test]
    fn fixed_strings() {
        let b: [u8; 6] = fixed_str("servo");
        assert_eq!(str_of(&b), "servo");
        let b: [u8; 4] = fixed_str("añbc");
        assert_eq!(str_of(&b), "añb");
        let b: [u8; 2] = fixed_str("ñx");
        assert_eq!(str_of(&b), "ñ");
    }
}
