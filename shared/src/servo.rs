//! The fast loop of the plant/servo board: one tick of hybrid control, friction-suppression
//! dither and its tuner, inverse kinematics and the PID joint servos.
//!
//! [`ServoCore::step`] is what the servo process runs at 10 kHz and what the lockstep
//! simulation runs in simulated time. It allocates nothing, takes no lock, does no I/O and
//! never panics on bad numbers: a non-finite force is treated as missing data (force loop and
//! tuner frozen), an unreachable set-point holds the last reachable one.

use crate::arm::{
    Arm, ArmParams, Elbow, JointServo, JointServoState, PidGains, tune_pid_for_bandwidth,
};
use crate::dither::{Dither, DitherParams, DitherState};
use crate::error::{ConfigError, SnapshotError};
use crate::friction::FrictionLaw;
use crate::hybrid::{
    HybridCommand, HybridController, HybridParams, HybridState, SetpointOffset, TaskFrame,
};
use crate::math::Vec2;
use crate::probe::ProbeRunner;
use crate::sensor::Wrench;
use crate::tangent::{ProbePlan, ProbeSample, TangentOutcome, TangentParams};
use crate::tuner::{Tuner, TunerConfig, TunerContext, TunerInput, TunerReport, TunerState};
use crate::window::SlidingSummary;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};

/// Settings of the servo board.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServoParams {
    /// Servo rate (Hz); thesis-style default 10 kHz.
    pub rate_hz: f64,
    /// Closed-loop joint bandwidths (Hz); thesis §4.5.1: ≈3 Hz and ≈15 Hz.
    pub joint_bandwidth_hz: [f64; 2],
    /// Damping ratio of the joint PD part.
    pub joint_damping_ratio: f64,
    /// Integral corner of the joint PIDs as a fraction of their natural frequency.
    pub joint_integral_ratio: f64,
    /// Hybrid controller.
    pub hybrid: HybridParams,
    /// Dither.
    pub dither: DitherParams,
    /// Dither tuner.
    pub tuner: TunerConfig,
    /// Friction model the tuner uses (identified beforehand, eq. 4.23).
    pub friction_model: FrictionLaw,
    /// Normal force at which `friction_model` holds (N).
    pub friction_model_reference_n: f64,
    /// Tool mass beyond the sensor (kg), for the tuner's oscillation model.
    pub tool_mass_kg: f64,
    /// Add the arm's inverse dynamics of the commanded motion, `M(q_d) q̈_d + h(q_d, q̇_d)`,
    /// to the PID torques. Without it the dither's joint-2 acceleration couples into joint 1
    /// through M12 away from the decoupled point and shakes the normal force.
    pub inertia_feedforward: bool,
    /// Add the joint torques that transmit the preload along the estimated normal,
    /// `−J(q)ᵀ F_d n̂`, recomputed every tick. Without it the joint integrators hold the preload
    /// as a fixed torque, and the force it transmits changes with the configuration as the tool
    /// moves (0.25 % per mm here), which tilts the tangent estimate by about 0.35°.
    pub preload_feedforward: bool,
    /// Tangent-estimation probes (thesis §5.3).
    pub tangent: TangentParams,
    /// When to start a tangent estimation on its own (thesis §5.3.2).
    pub tracking: TrackingParams,
    /// What to do while the force data cannot be trusted.
    pub safe: SafeParams,
}

/// The safe state, entered whenever the force data cannot be trusted (stale, missing or
/// insane): the tangential velocity ramps to zero at the controller's acceleration limit, the
/// dither decays to nothing within a few tens of milliseconds, the force loop freezes and the normal set-point backs off by a fraction of the
/// preload's penetration, so the normal force can only fall below the preload, never rise.
/// Once fresh data has been good for `recovery_s` the force loop restores the preload, and
/// motion and dither resume when the force has settled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafeParams {
    /// Back-off along the normal, as a fraction of the preload penetration F_d/k̂.
    pub backoff_fraction: f64,
    /// Time over which the back-off is applied (s).
    pub backoff_s: f64,
    /// Time constant of the dither's decay (s).
    pub dither_decay_s: f64,
    /// Good data needed before leaving the safe state (s).
    pub recovery_s: f64,
}

impl Default for SafeParams {
    fn default() -> Self {
        Self {
            backoff_fraction: 0.3,
            backoff_s: 0.01,
            dither_decay_s: 0.02,
            recovery_s: 0.02,
        }
    }
}

impl SafeParams {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.backoff_fraction.is_finite() && (0.0..=1.0).contains(&self.backoff_fraction)) {
            return Err(ConfigError::setting(
                "servo.safe.backoff_fraction",
                self.backoff_fraction,
                "must lie in [0, 1]",
            ));
        }
        for (n, v) in [
            ("backoff_s", self.backoff_s),
            ("dither_decay_s", self.dither_decay_s),
            ("recovery_s", self.recovery_s),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 10.0) {
                return Err(ConfigError::setting(
                    format!("servo.safe.{n}"),
                    v,
                    "must lie in (0, 10] s",
                ));
            }
        }
        Ok(())
    }
}

/// Where the safe state is.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SafeState {
    /// Velocity and Aω to restore.
    resume_velocity: f64,
    resume_a_omega: f64,
    /// Back-off still to apply (m).
    backoff_left: f64,
    /// Time the data has been good again (s).
    good_for_s: f64,
}

/// Limits on the force feedback that start a tangent estimation (thesis §5.3.2: "a sudden
/// change in force level ... could signal loss of contact or attempts to push into the
/// environment"), plus the drift of the force loop's normal set-point per unit of travel,
/// which is the tangent error the force loop is absorbing.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackingParams {
    /// Trigger estimations automatically.
    pub enabled: bool,
    /// Trigger when the normal force, averaged over one period of the friction-suppression
    /// dither (which removes the dither's own ripple), leaves the preload by this fraction.
    pub force_trigger_fraction: f64,
    /// Further first-order smoothing of that average (s).
    pub force_filter_s: f64,
    /// Trigger when the normal set-point drifts by this angle against the travel (deg): the
    /// force loop's set-point rate over the nominal speed, low-passed over `slope_window_m`, is
    /// the tangent error it is absorbing.
    pub slope_trigger_deg: f64,
    /// Travel over which the drift is averaged (m).
    pub slope_window_m: f64,
    /// Travel after an estimate before the drift and travel triggers re-arm (m).
    pub min_travel_m: f64,
    /// Estimate at least every this much travel (m); 0 disables.
    pub max_travel_m: f64,
    /// Turn the tangent between estimates at the curvature the last two estimates imply.
    pub curvature_feedforward: bool,
    /// Largest curvature fed forward (1/m). Two estimates implying more are taken to straddle a
    /// corner, not a curve, and no curvature is fed forward.
    pub max_curvature_per_m: f64,
    /// A change of tangent larger than this between two estimates is a corner whatever the
    /// distance (deg).
    pub corner_angle_deg: f64,
}

impl Default for TrackingParams {
    fn default() -> Self {
        Self {
            enabled: false,
            force_trigger_fraction: 0.2,
            force_filter_s: 0.002,
            slope_trigger_deg: 0.75,
            slope_window_m: 0.002,
            min_travel_m: 0.001,
            max_travel_m: 0.0,
            curvature_feedforward: true,
            max_curvature_per_m: 10.0,
            corner_angle_deg: 5.0,
        }
    }
}

wire_code! {
    /// What the fast loop is doing (its wire code: 0 track, 1 stopping, 2 probing, 3 awaiting
    /// estimate, 4 resuming).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
    #[serde(rename_all = "snake_case")]
    pub enum ServoMode {
        /// Hybrid control along the estimated tangent.
        #[default]
        Track = 0,
        /// Decelerating to a stop before probing.
        Stopping = 1,
        /// Running tangent-probe strokes.
        Probing = 2,
        /// Strokes done; holding the preload until the estimate arrives.
        AwaitingEstimate = 3,
        /// Estimate applied; holding until the normal force is back at the preload, then
        /// moving on.
        Resuming = 4,
    }
}

wire_code! {
    /// Why an estimation started (its code in [`ServoState::last_trigger`]; 0 is none).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
    #[serde(rename_all = "snake_case")]
    pub enum Trigger {
        /// Asked for by the caller.
        Request = 1,
        /// The normal force left its band.
        Force = 2,
        /// The normal set-point drifted against the travel.
        Slope = 3,
        /// Periodic, by travel.
        Travel = 4,
    }
}

/// A finished probe run waiting for the estimator.
#[derive(Debug, Clone, Copy)]
pub struct ProbeRequest<'a> {
    /// The plan that ran.
    pub plan: &'a ProbePlan,
    /// Estimated tangent angle the offsets refer to (rad).
    pub base_angle: f64,
    /// Recorded samples.
    pub samples: &'a [ProbeSample],
    /// True when this run is a re-probe.
    pub reprobe: bool,
}

/// Counters of the tangent estimation.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct EstimationCounters {
    /// Estimations started.
    pub started: usize,
    /// Of those, asked for by the caller ([`ServoCore::request_tangent_estimate`]).
    pub requested: usize,
    /// Accepted estimates.
    pub estimates: usize,
    /// Re-probes asked for.
    pub reprobes: usize,
    /// Failed estimations (tangent kept).
    pub failures: usize,
    /// Started by the force limit.
    pub force_triggers: usize,
    /// Started by the set-point drift.
    pub slope_triggers: usize,
    /// Estimations abandoned because the force data was lost mid-probe.
    pub aborted: usize,
    /// Entries into the safe state.
    pub safe_entries: usize,
}

impl Default for ServoParams {
    fn default() -> Self {
        Self {
            rate_hz: 10_000.0,
            joint_bandwidth_hz: [3.0, 15.0],
            joint_damping_ratio: 0.7,
            joint_integral_ratio: 0.1,
            hybrid: HybridParams::default(),
            dither: DitherParams::default(),
            tuner: TunerConfig::default(),
            friction_model: FrictionLaw::THESIS,
            friction_model_reference_n: 2.5,
            tool_mass_kg: 0.05,
            inertia_feedforward: true,
            preload_feedforward: true,
            tangent: TangentParams::default(),
            tracking: TrackingParams::default(),
            safe: SafeParams::default(),
        }
    }
}

impl ServoParams {
    /// Checks every setting; the message names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.rate_hz.is_finite() && (100.0..=100_000.0).contains(&self.rate_hz)) {
            return Err(ConfigError::setting(
                "servo.rate_hz",
                self.rate_hz,
                "must lie in [100, 100000]",
            ));
        }
        for (j, b) in self.joint_bandwidth_hz.iter().enumerate() {
            if !(b.is_finite() && *b > 0.0 && *b < self.rate_hz / 20.0) {
                return Err(ConfigError::setting(
                    format!("servo.joint_bandwidth_hz[{j}]"),
                    *b,
                    format!("must be > 0 and below rate_hz/20 = {}", self.rate_hz / 20.0),
                ));
            }
        }
        if !(self.joint_damping_ratio.is_finite() && self.joint_damping_ratio > 0.0) {
            return Err(ConfigError::setting(
                "servo.joint_damping_ratio",
                self.joint_damping_ratio,
                "must be > 0",
            ));
        }
        if !(self.joint_integral_ratio.is_finite()
            && self.joint_integral_ratio >= 0.0
            && self.joint_integral_ratio < 1.0)
        {
            return Err(ConfigError::setting(
                "servo.joint_integral_ratio",
                self.joint_integral_ratio,
                "must lie in [0, 1)",
            ));
        }
        self.hybrid.validate()?;
        self.dither.validate()?;
        self.safe.validate()?;
        self.tuner.validate()?;
        self.friction_model.validate()?;
        if !(self.friction_model_reference_n.is_finite() && self.friction_model_reference_n > 0.0) {
            return Err(ConfigError::setting(
                "servo.friction_model_reference_n",
                self.friction_model_reference_n,
                "must be > 0",
            ));
        }
        if !(self.tool_mass_kg.is_finite() && self.tool_mass_kg >= 0.0) {
            return Err(ConfigError::setting(
                "servo.tool_mass_kg",
                self.tool_mass_kg,
                "must be ≥ 0",
            ));
        }
        Ok(())
    }

    /// Servo period (s).
    pub fn dt(&self) -> f64 {
        1.0 / self.rate_hz
    }
}

/// One tick's inputs: encoder readings and the latest force sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ServoInput {
    /// Joint angles (rad).
    pub q: Vector2<f64>,
    /// Joint rates (rad/s).
    pub qd: Vector2<f64>,
    /// Latest wrench in the sensor frame.
    pub wrench: Wrench,
    /// False when the force data must not be used (stale, missing or insane).
    pub force_valid: bool,
}

/// What the fast loop did on its last tick.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct ServoDiag {
    /// Cartesian set-point (m).
    pub set_point: Vec2,
    /// Measured normal force (N).
    pub normal_force_n: f64,
    /// Measured tangential force along t̂ (N).
    pub tangential_force_n: f64,
    /// Friction resisting the nominal motion, normalised to the model's reference force (N).
    pub friction_normalized_n: f64,
    /// Commanded Aω (m/s).
    pub a_omega_m_per_s: f64,
    /// Dither amplitude (m).
    pub dither_amplitude_m: f64,
    /// Dither phase (rad).
    pub dither_phase: f64,
    /// Nominal tangential velocity (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Measured tip velocity along t̂ (m/s).
    pub tangent_velocity_m_per_s: f64,
    /// Joint torques (N·m).
    pub torque: Vector2<f64>,
    /// True if the last set-point was out of reach (held).
    pub setpoint_held: bool,
    /// Mode.
    pub mode: ServoMode,
    /// Estimated tangent angle in use (rad).
    pub tangent_angle_rad: f64,
    /// Requested nominal velocity (m/s).
    pub velocity_target_m_per_s: f64,
    /// In the safe state.
    pub safe: bool,
}

/// The fast loop.
#[derive(Debug, Clone)]
pub struct ServoCore {
    params: ServoParams,
    arm: Arm,
    elbow: Elbow,
    pid: JointServo,
    hybrid: HybridController,
    dither: Dither,
    tuner: Tuner,
    ctx: TunerContext,
    amplitude_bound: f64,
    tuning: bool,
    force_control: bool,
    tare: Wrench,
    last_q_d: Vector2<f64>,
    diag: ServoDiag,
    mode: ServoMode,
    probe: ProbeRunner,
    reprobe: bool,
    resume_velocity: f64,
    normal_filtered: f64,
    force_armed: bool,
    counters: EstimationCounters,
    last_outcome: Option<TangentOutcome>,
    last_trigger: Option<Trigger>,
    /// Arc length travelled since the last accepted estimate (m).
    odometer: f64,
    /// Arc length travelled in all (m).
    odometer_total: f64,
    /// Last accepted estimate: (tangent angle rad, odometer_total m).
    last_estimate: Option<(f64, f64)>,
    /// Curvature fed forward (1/m) and the angle it turns from (rad).
    curvature: f64,
    curve_base: f64,
    /// Low-passed tangent error the force loop is absorbing (rad).
    drift: f64,
    /// Time spent stopped, and time the normal force has been back at the preload (s).
    stopped_s: f64,
    settled_s: f64,
    /// Normal force over the last dither period (moving average, allocated once).
    normal_window: crate::window::SlidingWindow,
    /// The safe state, while in it.
    safe: Option<SafeState>,
    /// Aω to restore when `Resuming` ends (after the safe state).
    resume_a_omega: Option<f64>,
    /// The probe stroke commanded last tick (to absorb it if the probe is abandoned).
    last_stroke: SetpointOffset,
}

wire_flags! {
    /// [`ServoState::flags`].
    pub struct ServoStateFlags {
        /// On-line tuning on.
        const TUNING = 1;
        /// The normal force loop on.
        const FORCE_CONTROL = 2;
        /// The force trigger armed.
        const FORCE_ARMED = 4;
        /// In the safe state (the `safe` field holds it).
        const SAFE = 8;
        /// An Aω to restore when `Resuming` ends.
        const RESUME_A_OMEGA = 16;
        /// An accepted estimate so far (`last_estimate`).
        const LAST_ESTIMATE = 32;
    }
}

/// Everything the fast loop carries from one tick to the next, for a snapshot: a servo built
/// with the same settings and start ([`ServoCore::new`]) and given this state
/// ([`ServoCore::restore`]) carries on where the one that took it stopped. Two things come
/// back in brief: the moving average of the normal force over a dither period (and the thesis
/// tuner's friction window) keep their mean and variance, not their samples
/// ([`crate::window::SlidingSummary`]); and a probe run in progress, whose record is not kept,
/// starts again from its beginning (stop, settle, strokes), as does one whose estimate was
/// awaited.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
#[type_name("afs::ServoState")]
#[repr(C)]
pub struct ServoState {
    /// [`ServoMode`] as its wire code.
    pub mode: u32,
    /// [`ServoStateFlags`].
    pub flags: ServoStateFlags,
    /// What started the last estimation: 0 none, 1 request, 2 force, 3 slope, 4 travel.
    pub last_trigger: u32,
    /// Reserved (0).
    pub reserved: u32,
    /// [`EstimationCounters`]: started, requested, estimates, reprobes, failures,
    /// force_triggers, slope_triggers, aborted, safe_entries, and a reserved 0.
    pub counters: [u32; 10],
    /// Joint servos.
    pub joints: JointServoState,
    /// Hybrid controller (task frame, set-points, force loop).
    pub hybrid: HybridState,
    /// Dither oscillator.
    pub dither: DitherState,
    /// Dither tuner.
    pub tuner: TunerState,
    /// Sensor zero-load reading: force (N), moment (N·m).
    pub tare: [f64; 3],
    /// Last reachable joint set-point (rad).
    pub last_q_d_rad: [f64; 2],
    /// Velocity to go back to after an estimation (m/s).
    pub resume_velocity_m_per_s: f64,
    /// Filtered dither-period mean of the normal force (N).
    pub normal_filtered_n: f64,
    /// Travel since the last accepted estimate, and in all (m).
    pub odometer_m: [f64; 2],
    /// Last accepted estimate: tangent angle (rad) and total travel at it (m).
    pub last_estimate: [f64; 2],
    /// Curvature fed forward (1/m).
    pub curvature_per_m: f64,
    /// The angle it turns from (rad).
    pub curve_base_rad: f64,
    /// Low-passed tangent error the force loop absorbs (rad).
    pub drift_rad: f64,
    /// Time stopped, and time the normal force has been settled (s).
    pub stopped_settled_s: [f64; 2],
    /// Moving average of the normal force over a dither period, in brief.
    pub normal_window: SlidingSummary,
    /// Safe state: velocity and Aω to restore (m/s), back-off left (m), good data for (s).
    pub safe: [f64; 4],
    /// Aω to restore when `Resuming` ends (m/s).
    pub resume_a_omega_m_per_s: f64,
    /// The probe stroke commanded last tick (m), absorbed into the set-point if a probe run
    /// is restarted.
    pub last_stroke_m: [f64; 2],
}

impl ServoState {
    /// Checks that every number is finite and the codes are known (a snapshot that is not must
    /// not be restored).
    pub fn check(&self) -> Result<(), SnapshotError> {
        let mut finite = true;
        let mut all = |v: &[f64]| finite &= v.iter().all(|x| x.is_finite());
        let (j, h, d, t) = (&self.joints, &self.hybrid, &self.dither, &self.tuner);
        all(&j.integral_rad_s);
        all(&h.origin_m);
        all(&[
            h.tangent_angle_rad,
            h.s_m,
            h.s_dot_m_per_s,
            h.velocity_target_m_per_s,
            h.depth_m,
            h.depth_rate_m_per_s,
            h.preload_n,
            h.hooke_stiffness_n_per_m,
        ]);
        all(&[d.phase_rad, d.amplitude_m, d.sin_cos[0], d.sin_cos[1]]);
        all(&[
            t.a_omega_m_per_s,
            t.stribeck_velocity_estimate_m_per_s,
            t.transmission,
            t.friction_scale,
            t.window.mean,
            t.window.variance,
        ]);
        all(&t.periods.current);
        for p in &t.periods.ring {
            all(p);
        }
        all(&self.tare);
        all(&self.last_q_d_rad);
        all(&[
            self.resume_velocity_m_per_s,
            self.normal_filtered_n,
            self.curvature_per_m,
            self.curve_base_rad,
            self.drift_rad,
            self.normal_window.mean,
            self.normal_window.variance,
            self.resume_a_omega_m_per_s,
        ]);
        all(&self.odometer_m);
        all(&self.last_estimate);
        all(&self.stopped_settled_s);
        all(&self.safe);
        all(&self.last_stroke_m);
        if !finite {
            Err(SnapshotError::NotFinite)
        } else if ServoMode::try_from(self.mode).is_err()
            || (self.last_trigger != 0 && Trigger::try_from(self.last_trigger).is_err())
        {
            Err(SnapshotError::UnknownCode)
        } else {
            Ok(())
        }
    }
}

/// Probe samples are recorded every this many servo ticks (1 kHz at 10 kHz).
pub const PROBE_DECIMATION: usize = 10;

/// The PID joint servos' Cartesian stiffness along direction `n` at `q`:
/// `1 / (nᵀ J Kp⁻¹ Jᵀ n)` (N/m).
pub fn servo_stiffness_along(arm: &Arm, q: Vector2<f64>, kp: [f64; 2], n: Vec2) -> f64 {
    let j = arm.jacobian(q);
    let kinv = Matrix2::new(1.0 / kp[0], 0.0, 0.0, 1.0 / kp[1]);
    let c = j * kinv * j.transpose();
    1.0 / n.dot(&(c * n))
}

impl ServoCore {
    /// A servo holding the arm at `q0` in contact, with the measured sensor-frame wrench
    /// `wrench0` and an estimated tangent `tangent_angle` (rad, world).
    pub fn new(
        params: ServoParams,
        arm_params: ArmParams,
        elbow: Elbow,
        q0: Vector2<f64>,
        wrench0: Wrench,
        tangent_angle: f64,
    ) -> Result<Self, ConfigError> {
        params.validate()?;
        Arm::validate(&arm_params)?;
        let arm = Arm::new(arm_params);
        let m = arm.mass_matrix(q0);
        let gains: [PidGains; 2] = [0, 1].map(|j| {
            tune_pid_for_bandwidth(
                m[(j, j)],
                params.joint_bandwidth_hz[j],
                params.joint_damping_ratio,
                params.joint_integral_ratio,
            )
        });
        let mut pid = JointServo::new(gains, arm_params.torque_limit_nm);
        let f0 = Self::to_world(&arm, q0, wrench0);
        let mut hold = -(arm.jacobian(q0).transpose() * f0);
        if params.preload_feedforward {
            // The feedforward carries the preload along the estimated normal; the integrators
            // start with the rest.
            let n0 = crate::math::perp(crate::math::unit(tangent_angle));
            hold -= -(arm.jacobian(q0).transpose() * (n0 * params.hybrid.preload_n));
        }
        pid.preset_torque(hold);
        let frame = TaskFrame::new(arm.forward(q0), tangent_angle);
        let k_servo = servo_stiffness_along(&arm, q0, [gains[0].kp, gains[1].kp], frame.normal());
        let hybrid = HybridController::new(params.hybrid, frame, k_servo);
        let amplitude_bound = params.dither.amplitude_bound(
            params.hybrid.preload_n,
            params.hybrid.stiffness_estimate_n_per_m,
        );
        let omega = params.dither.omega();
        let ctx = TunerContext {
            law: params.friction_model,
            omega,
            dt: params.dt(),
            a_min: 1e-4,
            a_max: amplitude_bound * omega,
            tool_mass_kg: params.tool_mass_kg,
        };
        let tuner = Tuner::new(&params.tuner, &ctx, 0.0);
        let probe_capacity = [params.tangent.first_plan(), params.tangent.reprobe_plan()]
            .iter()
            .map(|p| ProbeRunner::samples_needed(p, params.rate_hz, PROBE_DECIMATION))
            .max()
            .unwrap_or(0);
        Ok(Self {
            params,
            arm,
            elbow,
            pid,
            hybrid,
            dither: Dither::new(params.dither.frequency_hz),
            tuner,
            ctx,
            amplitude_bound,
            tuning: false,
            force_control: true,
            tare: Wrench::default(),
            last_q_d: q0,
            diag: ServoDiag::default(),
            mode: ServoMode::Track,
            probe: ProbeRunner::new(probe_capacity, PROBE_DECIMATION),
            reprobe: false,
            resume_velocity: 0.0,
            normal_filtered: params.hybrid.preload_n,
            force_armed: true,
            counters: EstimationCounters::default(),
            last_outcome: None,
            last_trigger: None,
            odometer: 0.0,
            odometer_total: 0.0,
            last_estimate: None,
            curvature: 0.0,
            curve_base: tangent_angle,
            drift: 0.0,
            stopped_s: 0.0,
            settled_s: 0.0,
            normal_window: crate::window::SlidingWindow::new(
                (params.rate_hz / params.dither.frequency_hz)
                    .round()
                    .max(1.0) as usize,
            ),
            safe: None,
            resume_a_omega: None,
            last_stroke: SetpointOffset::default(),
        })
    }

    fn to_world(arm: &Arm, q: Vector2<f64>, w: Wrench) -> Vec2 {
        Self::to_world_at(&arm.pose(q), w)
    }

    /// Sensor-frame force to world: rotation by the link-2 angle q1+q2.
    fn to_world_at(p: &crate::arm::Pose, w: Wrench) -> Vec2 {
        let (s, c) = (p.s12, p.c12);
        Vec2::new(c * w.force.x - s * w.force.y, s * w.force.x + c * w.force.y)
    }

    /// Sets the sensor's zero-load reading (taken in free air before contact); it is
    /// subtracted from every reading.
    pub fn set_tare(&mut self, tare: Wrench) {
        if tare.force.x.is_finite() && tare.force.y.is_finite() && tare.torque.is_finite() {
            self.tare = tare;
        }
    }

    /// The sensor's zero-load reading in use.
    pub fn tare(&self) -> Wrench {
        self.tare
    }

    /// Settings.
    pub fn params(&self) -> &ServoParams {
        &self.params
    }

    /// The hybrid controller (task frame, set-points).
    pub fn hybrid(&self) -> &HybridController {
        &self.hybrid
    }

    /// Mutable access to the hybrid controller (velocity, tangent feed-forward).
    pub fn hybrid_mut(&mut self) -> &mut HybridController {
        &mut self.hybrid
    }

    /// Joint PID gains.
    pub fn gains(&self) -> [PidGains; 2] {
        self.pid.gains
    }

    /// Largest admissible dither amplitude (m).
    pub fn amplitude_bound(&self) -> f64 {
        self.amplitude_bound
    }

    /// Tuner context (model, bounds).
    pub fn tuner_context(&self) -> &TunerContext {
        &self.ctx
    }

    /// Sets Aω (m/s) directly (and the tuner's starting point).
    pub fn set_a_omega(&mut self, a: f64) {
        self.tuner.set(a);
        self.dither.set_velocity_amplitude(a, self.amplitude_bound);
    }

    /// Switches the normal force loop on or off (off holds the normal set-point, e.g. while the
    /// tool is lifted off to re-zero the sensor).
    pub fn set_force_control(&mut self, on: bool) {
        self.force_control = on;
    }

    /// Switches on-line tuning on or off (off holds the current Aω).
    pub fn set_tuning(&mut self, on: bool) {
        self.tuning = on;
    }

    /// The tuner's report.
    pub fn tuner_report(&self) -> TunerReport {
        self.tuner.report(&self.ctx)
    }

    /// Name of the configured tuner.
    pub fn tuner_name(&self) -> &'static str {
        self.tuner.name()
    }

    /// Last tick's diagnostics.
    pub fn diag(&self) -> &ServoDiag {
        &self.diag
    }

    /// Current mode.
    pub fn mode(&self) -> ServoMode {
        self.mode
    }

    /// Estimation counters.
    pub fn counters(&self) -> EstimationCounters {
        self.counters
    }

    /// The last estimator answer applied.
    pub fn last_outcome(&self) -> Option<&TangentOutcome> {
        self.last_outcome.as_ref()
    }

    /// What started the last estimation.
    pub fn last_trigger(&self) -> Option<Trigger> {
        self.last_trigger
    }

    /// Everything it carries from tick to tick ([`ServoState`]).
    pub fn state(&self) -> ServoState {
        let c = &self.counters;
        let n = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        let flag = |on: bool, f: ServoStateFlags| {
            if on { f } else { ServoStateFlags::empty() }
        };
        let safe = self.safe.map_or([0.0; 4], |s| {
            [
                s.resume_velocity,
                s.resume_a_omega,
                s.backoff_left,
                s.good_for_s,
            ]
        });
        let (angle, at) = self.last_estimate.unwrap_or((0.0, 0.0));
        ServoState {
            mode: self.mode.into(),
            flags: flag(self.tuning, ServoStateFlags::TUNING)
                | flag(self.force_control, ServoStateFlags::FORCE_CONTROL)
                | flag(self.force_armed, ServoStateFlags::FORCE_ARMED)
                | flag(self.safe.is_some(), ServoStateFlags::SAFE)
                | flag(
                    self.resume_a_omega.is_some(),
                    ServoStateFlags::RESUME_A_OMEGA,
                )
                | flag(self.last_estimate.is_some(), ServoStateFlags::LAST_ESTIMATE),
            last_trigger: self.last_trigger.map_or(0, u32::from),
            reserved: 0,
            counters: [
                n(c.started),
                n(c.requested),
                n(c.estimates),
                n(c.reprobes),
                n(c.failures),
                n(c.force_triggers),
                n(c.slope_triggers),
                n(c.aborted),
                n(c.safe_entries),
                0,
            ],
            joints: self.pid.state(),
            hybrid: self.hybrid.state(),
            dither: self.dither.state(),
            tuner: self.tuner.state(),
            tare: [self.tare.force.x, self.tare.force.y, self.tare.torque],
            last_q_d_rad: [self.last_q_d[0], self.last_q_d[1]],
            resume_velocity_m_per_s: self.resume_velocity,
            normal_filtered_n: self.normal_filtered,
            odometer_m: [self.odometer, self.odometer_total],
            last_estimate: [angle, at],
            curvature_per_m: self.curvature,
            curve_base_rad: self.curve_base,
            drift_rad: self.drift,
            stopped_settled_s: [self.stopped_s, self.settled_s],
            normal_window: self.normal_window.summary(),
            safe,
            resume_a_omega_m_per_s: self.resume_a_omega.unwrap_or(0.0),
            last_stroke_m: [
                self.last_stroke.displacement.x,
                self.last_stroke.displacement.y,
            ],
        }
    }

    /// Carries on from a state taken by [`ServoCore::state`] of a servo with the same settings
    /// and start. A probe run in progress, or one whose estimate was awaited, starts again from
    /// its beginning: its record is not in the state, and an answer to it would go to the
    /// process that asked. Refuses (and changes nothing) a state with a non-finite number or an
    /// unknown code.
    pub fn restore(&mut self, st: &ServoState) -> Result<(), SnapshotError> {
        st.check()?;
        let mode = ServoMode::try_from(st.mode).unwrap_or_default();
        let has = |f: ServoStateFlags| st.flags.contains(f);
        let c = st.counters.map(|v| v as usize);
        self.counters = EstimationCounters {
            started: c[0],
            requested: c[1],
            estimates: c[2],
            reprobes: c[3],
            failures: c[4],
            force_triggers: c[5],
            slope_triggers: c[6],
            aborted: c[7],
            safe_entries: c[8],
        };
        self.pid.restore(&st.joints);
        self.hybrid.restore(&st.hybrid);
        self.dither.restore(&st.dither);
        self.tuner.restore(&st.tuner);
        self.tuning = has(ServoStateFlags::TUNING);
        self.force_control = has(ServoStateFlags::FORCE_CONTROL);
        self.force_armed = has(ServoStateFlags::FORCE_ARMED);
        self.last_trigger = Trigger::try_from(st.last_trigger).ok();
        self.tare = Wrench {
            force: Vec2::new(st.tare[0], st.tare[1]),
            torque: st.tare[2],
        };
        self.last_q_d = Vector2::new(st.last_q_d_rad[0], st.last_q_d_rad[1]);
        self.resume_velocity = st.resume_velocity_m_per_s;
        self.normal_filtered = st.normal_filtered_n;
        [self.odometer, self.odometer_total] = st.odometer_m;
        self.last_estimate = has(ServoStateFlags::LAST_ESTIMATE)
            .then_some((st.last_estimate[0], st.last_estimate[1]));
        self.curvature = st.curvature_per_m;
        self.curve_base = st.curve_base_rad;
        self.drift = st.drift_rad;
        [self.stopped_s, self.settled_s] = st.stopped_settled_s;
        self.normal_window.refill(&st.normal_window);
        self.safe = has(ServoStateFlags::SAFE).then_some(SafeState {
            resume_velocity: st.safe[0],
            resume_a_omega: st.safe[1],
            backoff_left: st.safe[2],
            good_for_s: st.safe[3],
        });
        self.resume_a_omega =
            has(ServoStateFlags::RESUME_A_OMEGA).then_some(st.resume_a_omega_m_per_s);
        self.last_stroke = SetpointOffset::default();
        self.probe.reset();
        self.reprobe = false;
        self.mode = mode;
        if matches!(mode, ServoMode::Probing | ServoMode::AwaitingEstimate) {
            // The arm stands where the last stroke took it: keep the set-point there, and probe
            // again from the start (stop, settle, strokes).
            if mode == ServoMode::Probing {
                self.hybrid
                    .absorb_offset(Vec2::new(st.last_stroke_m[0], st.last_stroke_m[1]));
            }
            self.stopped_s = 0.0;
            self.settled_s = 0.0;
            self.mode = ServoMode::Stopping;
        }
        Ok(())
    }

    /// Starts a tangent estimation: stop, then probe (thesis §5.3.2). Ignored unless tracking.
    pub fn request_tangent_estimate(&mut self) {
        if self.mode == ServoMode::Track {
            self.begin_estimation(Trigger::Request);
        }
    }

    fn begin_estimation(&mut self, why: Trigger) {
        self.counters.started += 1;
        match why {
            Trigger::Request => self.counters.requested += 1,
            Trigger::Force => self.counters.force_triggers += 1,
            Trigger::Slope => self.counters.slope_triggers += 1,
            Trigger::Travel => {}
        }
        self.last_trigger = Some(why);
        self.stopped_s = 0.0;
        self.settled_s = 0.0;
        self.resume_velocity = self.hybrid.velocity_target();
        self.hybrid.set_velocity(0.0);
        self.mode = ServoMode::Stopping;
    }

    /// The finished probe run, while the servo waits for its estimate.
    pub fn pending_probe(&self) -> Option<ProbeRequest<'_>> {
        (self.mode == ServoMode::AwaitingEstimate).then(|| ProbeRequest {
            plan: self.probe.plan(),
            base_angle: self.probe.base_angle(),
            samples: self.probe.samples(),
            reprobe: self.reprobe,
        })
    }

    /// Applies the estimator's answer: feed the new tangent forward and resume, run the
    /// re-probe plan, or keep the old tangent and resume.
    pub fn apply_tangent_outcome(&mut self, outcome: &TangentOutcome) {
        if self.mode != ServoMode::AwaitingEstimate {
            return;
        }
        self.last_outcome = Some(*outcome);
        match outcome {
            TangentOutcome::Estimate(e) => {
                self.counters.estimates += 1;
                let t = self.params.tracking;
                let angle = e.tangent_angle_rad;
                self.curvature = match self.last_estimate {
                    Some((prev, at)) if t.curvature_feedforward => {
                        let ds = self.odometer_total - at;
                        let dth = crate::math::wrap_angle(angle - prev);
                        let corner = dth.abs() > t.corner_angle_deg.to_radians()
                            || self.last_trigger == Some(Trigger::Force)
                            || ds <= 1e-3
                            || (dth / ds).abs() > t.max_curvature_per_m;
                        if corner { 0.0 } else { dth / ds }
                    }
                    _ => 0.0,
                };
                self.last_estimate = Some((angle, self.odometer_total));
                self.curve_base = angle;
                self.odometer = 0.0;
                self.drift = 0.0;
                self.hybrid.set_tangent(angle);
                self.resume();
            }
            TangentOutcome::Reprobe { plan, .. } => {
                self.counters.reprobes += 1;
                self.reprobe = true;
                let plan = self.plan_with_dither(*plan);
                self.probe.start(plan, self.hybrid.frame().tangent_angle);
                self.mode = ServoMode::Probing;
            }
            TangentOutcome::Failed(_) => {
                self.counters.failures += 1;
                self.resume();
            }
        }
    }

    /// Gives up waiting for the estimator (it did not answer): keeps the old tangent, counts a
    /// failure and resumes tracking.
    pub fn give_up_estimate(&mut self) {
        if self.mode == ServoMode::AwaitingEstimate {
            self.counters.failures += 1;
            self.resume();
        }
    }

    fn plan_with_dither(&self, mut plan: ProbePlan) -> ProbePlan {
        plan.dither_hz = if self.dither.amplitude() > 0.0 {
            self.params.dither.frequency_hz
        } else {
            0.0
        };
        plan
    }

    fn resume(&mut self) {
        self.probe.reset();
        self.reprobe = false;
        self.stopped_s = 0.0;
        self.settled_s = 0.0;
        self.mode = ServoMode::Resuming;
    }

    /// While stopped with the force loop on: true once the dither-period mean of the normal force
    /// has stayed within 5 % of the preload for the probe hold time, or after 3 s.
    fn force_settled(&mut self, dt: f64) -> bool {
        self.stopped_s += dt;
        let preload = self.hybrid.params().preload_n;
        if (self.normal_filtered - preload).abs() < 0.05 * preload {
            self.settled_s += dt;
        } else {
            self.settled_s = 0.0;
        }
        self.settled_s >= self.params.tangent.settle_s || self.stopped_s > 3.0
    }

    /// The velocity target the servo tracks at, or goes back to after an estimation or the
    /// safe state (m/s).
    pub fn resume_velocity(&self) -> f64 {
        match (&self.safe, self.mode) {
            (Some(s), _) => s.resume_velocity,
            (None, ServoMode::Track) => self.hybrid.velocity_target(),
            (None, _) => self.resume_velocity,
        }
    }

    /// The Aω the servo dithers at, or goes back to after the safe state (m/s).
    pub fn resume_a_omega(&self) -> f64 {
        match &self.safe {
            Some(s) => s.resume_a_omega,
            None => self
                .resume_a_omega
                .unwrap_or(self.dither.velocity_amplitude()),
        }
    }

    /// True while in the safe state.
    pub fn is_safe(&self) -> bool {
        self.safe.is_some()
    }

    /// Enters, runs or leaves the safe state for this tick's force-data validity.
    fn update_safe(&mut self, valid: bool, dt: f64) {
        let recovery = self.params.safe.recovery_s;
        match self.safe.as_mut() {
            None if !valid => self.enter_safe(),
            None => return,
            Some(s) if valid => {
                s.good_for_s += dt;
                if s.good_for_s >= recovery {
                    self.leave_safe();
                    return;
                }
            }
            Some(s) => s.good_for_s = 0.0,
        }
        let p = self.params.safe;
        let total =
            p.backoff_fraction * self.hybrid.params().preload_n / self.hybrid.hooke_stiffness();
        let a = self.dither.velocity_amplitude();
        let decayed = a * (-dt / p.dither_decay_s).exp();
        self.dither.set_velocity_amplitude(
            if decayed < 1e-6 { 0.0 } else { decayed },
            self.amplitude_bound,
        );
        if let Some(s) = self.safe.as_mut() {
            let step = s.backoff_left.min(total * dt / p.backoff_s);
            s.backoff_left -= step;
            self.hybrid.shift_depth(-step);
        }
    }

    fn enter_safe(&mut self) {
        self.counters.safe_entries += 1;
        let resume_velocity = match self.mode {
            ServoMode::Track => self.hybrid.velocity_target(),
            _ => self.resume_velocity,
        };
        let resume_a_omega = self
            .resume_a_omega
            .unwrap_or(self.dither.velocity_amplitude());
        self.hybrid.set_velocity(0.0);
        if matches!(self.mode, ServoMode::Stopping | ServoMode::Probing) {
            // The strokes cannot be measured without force data: abandon them, keeping the
            // set-point where the stroke had taken it.
            self.counters.aborted += 1;
            if self.mode == ServoMode::Probing {
                self.hybrid.absorb_offset(self.last_stroke.displacement);
            }
            self.probe.reset();
            self.reprobe = false;
        }
        if self.mode != ServoMode::AwaitingEstimate {
            self.mode = ServoMode::Resuming;
        }
        self.last_stroke = SetpointOffset::default();
        self.resume_velocity = resume_velocity;
        let p = self.params.safe;
        self.safe = Some(SafeState {
            resume_velocity,
            resume_a_omega,
            backoff_left: p.backoff_fraction * self.hybrid.params().preload_n
                / self.hybrid.hooke_stiffness(),
            good_for_s: 0.0,
        });
    }

    fn leave_safe(&mut self) {
        let Some(s) = self.safe.take() else {
            return;
        };
        self.resume_velocity = s.resume_velocity;
        self.resume_a_omega = Some(s.resume_a_omega);
        self.stopped_s = 0.0;
        self.settled_s = 0.0;
        if self.mode != ServoMode::AwaitingEstimate {
            self.mode = ServoMode::Resuming;
        }
    }

    fn check_triggers(&mut self, dt: f64, normal: f64) {
        let t = self.params.tracking;
        // Odometer, curvature feedforward and the drift the force loop absorbs.
        let v = self.hybrid.nominal_velocity();
        if self.mode == ServoMode::Track && v != 0.0 {
            let ds = v.abs() * dt;
            self.odometer += ds;
            self.odometer_total += ds;
            if t.curvature_feedforward && self.curvature != 0.0 {
                let angle = self.curve_base + self.curvature * self.odometer * v.signum();
                self.hybrid.set_tangent(angle);
            }
        }
        let preload = self.hybrid.params().preload_n;
        self.normal_window.push(normal);
        let period_mean = self.normal_window.mean();
        if self.mode == ServoMode::Track && v != 0.0 {
            // The set-point rate for the dither-period mean force: free of the dither's ripple.
            let window_s = t.slope_window_m / v.abs();
            let instant = (self.hybrid.depth_rate_for(period_mean) / v).atan();
            self.drift += (dt / window_s.max(dt)).min(1.0) * (instant - self.drift);
        }
        if t.force_filter_s > 0.0 {
            self.normal_filtered +=
                (dt / t.force_filter_s).min(1.0) * (period_mean - self.normal_filtered);
        } else {
            self.normal_filtered = period_mean;
        }
        let deviation = (self.normal_filtered - preload).abs() / preload;
        if deviation < 0.5 * t.force_trigger_fraction {
            self.force_armed = true;
        }
        if !t.enabled || self.mode != ServoMode::Track || self.hybrid.velocity_target() == 0.0 {
            return;
        }
        if self.force_armed
            && deviation > t.force_trigger_fraction
            && self.odometer >= t.min_travel_m
        {
            self.force_armed = false;
            self.begin_estimation(Trigger::Force);
            return;
        }
        let travel = self.odometer;
        if travel < t.min_travel_m.max(t.slope_window_m) {
            return;
        }
        if self.drift.abs() > t.slope_trigger_deg.to_radians() {
            self.begin_estimation(Trigger::Slope);
        } else if t.max_travel_m > 0.0 && travel > t.max_travel_m {
            self.begin_estimation(Trigger::Travel);
        }
    }

    /// One fast-loop tick: returns the joint torques (N·m).
    pub fn step(&mut self, inp: &ServoInput, dt: f64) -> Vector2<f64> {
        let valid = inp.force_valid
            && inp.wrench.force.x.is_finite()
            && inp.wrench.force.y.is_finite()
            && inp.wrench.torque.is_finite();
        let pose = self.arm.pose(inp.q);
        let wrench = Wrench {
            force: inp.wrench.force - self.tare.force,
            torque: inp.wrench.torque - self.tare.torque,
        };
        let force = if valid {
            Self::to_world_at(&pose, wrench)
        } else {
            Vec2::zeros()
        };
        self.update_safe(valid, dt);
        let safe = self.safe.is_some();
        let dither = self.dither.step(dt);
        let mut extra = SetpointOffset::default();
        let mode = if safe { None } else { Some(self.mode) };
        match mode {
            // Probe only once the force loop has brought the normal force back to the preload
            // (it is frozen during the strokes), or after waiting 3 s.
            Some(ServoMode::Stopping)
                if self.hybrid.nominal_velocity() == 0.0 && self.force_settled(dt) =>
            {
                let plan = self.plan_with_dither(self.params.tangent.first_plan());
                self.probe.start(plan, self.hybrid.frame().tangent_angle);
                self.reprobe = false;
                self.mode = ServoMode::Probing;
            }
            Some(ServoMode::Resuming) if self.force_settled(dt) => {
                self.mode = ServoMode::Track;
                self.force_armed = false;
                self.drift = 0.0;
                self.hybrid.set_velocity(self.resume_velocity);
                if let Some(a) = self.resume_a_omega.take() {
                    self.set_a_omega(a);
                }
            }
            Some(ServoMode::Probing) => {
                extra = self.probe.step(dt, force, self.arm.forward_at(&pose));
                self.last_stroke = extra;
                if self.probe.finished() {
                    self.mode = ServoMode::AwaitingEstimate;
                }
            }
            _ => {}
        }
        let probing = self.mode == ServoMode::Probing;
        let force_loop = valid && self.force_control && !probing;
        // Frozen integrators make the stroke response stationary (they would otherwise relax a
        // DC offset picked up in the ramp-in over their ~1 s time constant).
        self.pid.set_integrating(!probing);
        let cmd: HybridCommand = self.hybrid.step(dt, force, dither, extra, force_loop);
        let mut held = false;
        let (q_d, pose_d) = match self.arm.inverse_pose(cmd.position, self.elbow) {
            Ok(x) => x,
            Err(_) => {
                held = true;
                (self.last_q_d, self.arm.pose(self.last_q_d))
            }
        };
        let jinv = if held {
            None
        } else {
            self.arm.jacobian_at(&pose_d).try_inverse()
        };
        let (qd_d, qdd_d) = match jinv {
            Some(ji) => {
                let qd_d = ji * cmd.velocity;
                let qdd_d =
                    ji * (cmd.acceleration - self.arm.jacobian_dot_at(&pose_d, qd_d) * qd_d);
                (qd_d, qdd_d)
            }
            None => (Vector2::zeros(), Vector2::zeros()),
        };
        self.last_q_d = q_d;
        let mut feedforward = if self.params.inertia_feedforward {
            self.arm.inverse_dynamics_at(&pose_d, qd_d, qdd_d)
        } else {
            Vector2::zeros()
        };
        // The preload's feedforward depends on the configuration and the desired force, not on
        // the measurement: it stays on in the safe state (the set-point backs off instead).
        if self.params.preload_feedforward {
            let n_hat = self.hybrid.frame().normal();
            feedforward -=
                self.arm.jacobian_at(&pose).transpose() * (n_hat * self.hybrid.params().preload_n);
        }
        let tau = self.pid.torque(q_d, qd_d, inp.q, inp.qd, feedforward, dt);

        // Tuner: friction resisting the nominal motion, normalised to the model's reference force.
        let t_hat = self.hybrid.frame().tangent();
        let dir = if self.hybrid.velocity_target() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let v_tan = (self.arm.jacobian_at(&pose) * inp.qd).dot(&t_hat);
        let f_ref = self.params.friction_model_reference_n;
        let normal = cmd.normal_force_n;
        let ratio = if normal > 0.2 * f_ref {
            f_ref / normal
        } else {
            1.0
        };
        let friction = -cmd.tangential_force_n * dir * ratio;
        let nominal = self.hybrid.nominal_velocity().abs();
        if valid && !safe {
            self.check_triggers(dt, normal);
        }
        if self.tuning && valid && !safe && nominal > 0.0 && self.mode == ServoMode::Track {
            let input = TunerInput {
                friction_n: friction,
                velocity_m_per_s: v_tan * dir,
                nominal_m_per_s: nominal,
                phase: self.dither.phase(),
                period_end: self.dither.completed_period(),
                normal_n: normal,
            };
            let a = self.tuner.update(&self.ctx, &input);
            self.dither.set_velocity_amplitude(a, self.amplitude_bound);
        }
        self.diag = ServoDiag {
            set_point: cmd.position,
            normal_force_n: normal,
            tangential_force_n: cmd.tangential_force_n,
            friction_normalized_n: friction,
            a_omega_m_per_s: self.dither.velocity_amplitude(),
            dither_amplitude_m: self.dither.amplitude(),
            dither_phase: self.dither.phase(),
            nominal_velocity_m_per_s: self.hybrid.nominal_velocity(),
            tangent_velocity_m_per_s: v_tan,
            torque: tau,
            setpoint_held: held,
            mode: self.mode,
            tangent_angle_rad: self.hybrid.frame().tangent_angle,
            velocity_target_m_per_s: self.hybrid.velocity_target(),
            safe,
        };
        tau
    }
}
