//! The fast loop of the plant/servo board: one tick of hybrid control, friction-suppression
//! dither and its tuner, and the drive: inverse kinematics and the PID joint servos of the
//! two-link arm, or the planar impedance of a task-space arm.
//!
//! [`ServoCore::step`] is what the servo process runs at 10 kHz and what the lockstep
//! simulation runs in simulated time; [`ServoCore::step_task`] is its tick on a task-space
//! drive ([`ServoCore::new_task`]). It allocates nothing, takes no lock, does no I/O and
//! never panics on bad numbers: a non-finite force is treated as missing data (force loop and
//! tuner frozen), an unreachable set-point holds the last reachable one.

//!
//! | file | concept |
//! |---|---|
//! | `step` | one tick: the set-point, the drive's command, the triggers, fit and tuner |
//! | `drive` | what the set-point drives: the two-link arm, or a tool's planar force ([`TaskDrive`]) |
//! | `params` | the settings ([`ServoParams`], [`SafeParams`], [`TrackingParams`]) |
//! | `tracking` | modes, triggers, the probe run and the estimator's answer (§5.3.2) |
//! | `safe` | the safe state on untrusted force data |
//! | `state` | [`ServoState`]: everything that crosses a restart, made of named parts |

pub(crate) mod contact;
mod drive;
mod params;
mod safe;
mod state;
mod step;
mod tracking;

pub use contact::{
    ContactReport, ContactState, contact_damping, contact_mode_above_dither, dither_damping_ratio,
};
pub use drive::{TaskCommand, TaskDrive, TaskInput, to_plane};
pub use params::{
    ApproachParams, DriftSource, ProbeForceLoop, SafeParams, ServoParams, TrackingParams,
};
pub use safe::SafeState;
pub use state::{ServoState, ServoStateFlags, TareState};
pub use tracking::{EstimationCounters, ProbeRequest, ServoMode, TrackState, Trigger};

use crate::arm::{Arm, ArmParams, Elbow, JointServo, PidGains, tune_pid_for_bandwidth};
use crate::dither::Dither;
use crate::error::ConfigError;
use crate::hybrid::{HybridController, SetpointOffset, TaskFrame};
use crate::math::Vec2;
use crate::probe::ProbeRunner;
use crate::sensor::Wrench;
use crate::tangent::TangentOutcome;
use crate::tuner::{Tuner, TunerContext, TunerReport};
use nalgebra::{Matrix2, Vector2};
use serde::Serialize;

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
    /// What the set-point drives: the two-link arm's joint servos, or a tool's planar force.
    drive: drive::Drive,
    hybrid: HybridController,
    dither: Dither,
    tuner: Tuner,
    ctx: TunerContext,
    amplitude_bound: f64,
    tuning: bool,
    force_control: bool,
    tare: Wrench,
    diag: ServoDiag,
    mode: ServoMode,
    probe: ProbeRunner,
    reprobe: bool,
    force_armed: bool,
    counters: EstimationCounters,
    last_outcome: Option<TangentOutcome>,
    last_trigger: Option<Trigger>,
    /// The tracker's memory between estimations.
    track: TrackState,
    /// Last accepted estimate: (tangent angle rad, total travel at it m).
    last_estimate: Option<(f64, f64)>,
    /// Normal force over the last dither period (moving average, allocated once).
    normal_window: crate::window::SlidingWindow,
    /// The safe state, while in it.
    safe: Option<SafeState>,
    /// Aω to restore when `Resuming` ends (after the safe state).
    resume_a_omega: Option<f64>,
    /// The probe stroke commanded last tick (to absorb it if the probe is abandoned).
    last_stroke: SetpointOffset,
    /// Consecutive ticks the normal force has been below the contact guard's threshold.
    contact_lost_ticks: u32,
    /// The last estimate turned a corner: estimate once more `corner_confirm_m` on.
    confirm_corner: bool,
    /// Damping added along the normal on the velocity error (N·s/m, [`contact_damping`]).
    normal_damping: f64,
    /// The contact mode's arm side at the start, along the normal: the arm's effective mass
    /// (kg), the servo's own damping (N·s/m) and stiffness (N/m).
    contact_mode: [f64; 3],
    /// The force signal's whole delay from the contact to the torque (s).
    loop_delay: f64,
    /// The contact's normal stiffness, fitted on line (docs/contact.md).
    stiffness: crate::contact::StiffnessEstimator,
    /// The task frame the fit's coordinates are measured in (a new one restarts it).
    stiffness_frame: TaskFrame,
    /// Ticks since the fit's last sample.
    contact_phase: u32,
    /// Times the servo adopted a fitted stiffness.
    adopted: u32,
    /// The guarded approach's speed (m/s, [`ApproachParams::speed`]).
    approach_speed: f64,
    /// The contact-dependent gains are the approach's assumption ([`ContactState::provisional`]).
    provisional: bool,
}

/// The rate probe samples are recorded at (Hz), whatever the servo's rate (at most it).
pub const PROBE_RECORD_HZ: f64 = 1000.0;

/// Probe samples are recorded every this many servo ticks: 10 at 10 kHz, 1 at 1 kHz and at
/// 500 Hz (a record at [`PROBE_RECORD_HZ`], or every tick below it). A fixed 10 recorded a
/// 1-kHz servo's probes at 100 Hz, with √10 times the noise on every in-phase amplitude.
pub fn probe_decimation(rate_hz: f64) -> usize {
    let n = (rate_hz / PROBE_RECORD_HZ).round();
    if n.is_finite() && n >= 1.0 {
        n as usize
    } else {
        1
    }
}

/// The PID joint servos' Cartesian stiffness along direction `n` at `q`:
/// `1 / (nᵀ J Kp⁻¹ Jᵀ n)` (N/m).
pub fn servo_stiffness_along(arm: &Arm, q: Vector2<f64>, kp: [f64; 2], n: Vec2) -> f64 {
    along(arm, q, Matrix2::new(1.0 / kp[0], 0.0, 0.0, 1.0 / kp[1]), n)
}

/// `1/(nᵀ J G⁻¹ Jᵀ n)`: what a joint-space gain matrix G (stiffness, damping or the mass
/// matrix), given as its inverse `inverse`, amounts to along the Cartesian direction `n` at
/// `q`, the other direction free.
fn along(arm: &Arm, q: Vector2<f64>, inverse: Matrix2<f64>, n: Vec2) -> f64 {
    let j = arm.jacobian(q);
    1.0 / n.dot(&(j * inverse * j.transpose() * n))
}

impl ServoCore {
    /// Whether the force loop stays on during a probe's strokes (`servo.probe_force_loop`).
    pub(super) fn probes_hold_force(&self) -> bool {
        match self.params.probe_force_loop {
            ProbeForceLoop::Frozen => false,
            ProbeForceLoop::On => true,
            ProbeForceLoop::Auto => self.contact_is_stiff(),
        }
    }

    /// True when the contact in use is stiff: its normal mode sits above ω_d/√2
    /// ([`contact_mode_above_dither`]; docs/contact.md, *The force loop during the probes*).
    pub(super) fn contact_is_stiff(&self) -> bool {
        let [mass, _, servo_stiffness] = self.contact_mode;
        contact_mode_above_dither(
            self.params.dither.omega(),
            self.hybrid.params().stiffness_estimate_n_per_m,
            servo_stiffness,
            mass,
        )
    }

    /// The contact mode's damping ratio for a contact of `stiffness` (N/m): the configured
    /// ζ_c, raised to what keeps the mode from amplifying the dither ([`dither_damping_ratio`]);
    /// 0 (no damping added) when ζ_c is 0.
    fn contact_damping_ratio_for(
        params: &ServoParams,
        stiffness: f64,
        servo_stiffness: f64,
        mass: f64,
    ) -> f64 {
        let zeta = params.contact_damping_ratio;
        if zeta > 0.0 {
            zeta.max(dither_damping_ratio(
                params.dither.omega(),
                stiffness,
                servo_stiffness,
                mass,
            ))
        } else {
            0.0
        }
    }

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
        let m_inv = m.try_inverse().unwrap_or_else(Matrix2::zeros);
        let normal_mass = along(&arm, q0, m_inv, frame.normal());
        let kd_inv = Matrix2::new(1.0 / gains[0].kd, 0.0, 0.0, 1.0 / gains[1].kd);
        let normal_servo_damping = along(&arm, q0, kd_inv, frame.normal());
        let drive = drive::Drive::TwoLink(drive::TwoLink {
            arm,
            elbow,
            pid,
            last_q_d: q0,
        });
        Ok(Self::with_drive(
            params,
            drive,
            frame,
            f0,
            [normal_mass, normal_servo_damping, k_servo],
        ))
    }

    /// A servo on a task-space drive ([`TaskDrive`]: an arm whose torques are `Jᵀ W`, such as
    /// the FR3 through [`crate::task_plane`]), the tool at `position_m` (m, in the plane) with
    /// the measured sensor-frame wrench `wrench0` at its angle `drive.theta_rad` (the angle it
    /// holds), and an estimated tangent `tangent_angle` (rad, in the plane). Its ticks are
    /// [`ServoCore::step_task`].
    ///
    /// # Errors
    /// [`ConfigError`] for settings that do not validate, or an inertia or a gain that is not
    /// finite and positive.
    pub fn new_task(
        params: ServoParams,
        drive: TaskDrive,
        position_m: Vec2,
        wrench0: Wrench,
        tangent_angle: f64,
    ) -> Result<Self, ConfigError> {
        params.validate()?;
        if !drive.is_valid() {
            return Err(ConfigError::setting(
                "task drive's inertia and gains",
                drive
                    .inertia
                    .min()
                    .min(drive.gains.stiffness.min())
                    .min(drive.gains.damping.min()),
                "must be finite and > 0 (task_plane::planar_inertia and planar_gains give them)",
            ));
        }
        if !(position_m.iter().all(|v| v.is_finite()) && tangent_angle.is_finite()) {
            return Err(ConfigError::setting(
                "task drive's start",
                position_m.x + position_m.y + tangent_angle,
                "the tool's position and the tangent must be finite",
            ));
        }
        let (s, c) = drive.theta_rad.sin_cos();
        let f0 = drive::to_plane(s, c, wrench0);
        let frame = TaskFrame::new(position_m, tangent_angle);
        let mode = drive.along(frame.normal());
        Ok(Self::with_drive(
            params,
            drive::Drive::Task(drive),
            frame,
            f0,
            mode,
        ))
    }

    /// What both constructors share: the servo on `drive`, its task frame `frame`, the contact
    /// force at the start `f0` (N, in the plane) and the contact mode's arm side along the
    /// normal `contact_mode` (mass kg, damping N·s/m, stiffness N/m).
    fn with_drive(
        params: ServoParams,
        drive: drive::Drive,
        frame: TaskFrame,
        f0: Vec2,
        contact_mode: [f64; 3],
    ) -> Self {
        let [normal_mass, _, k_servo] = contact_mode;
        let tangent_angle = frame.tangent_angle;
        let signal_delay = params
            .hybrid
            .force_signal_delay_s
            .unwrap_or_else(|| crate::sensor::SensorParams::default().signal_delay_s());
        // The reading waits up to a tick for the servo, whose torque then holds for a tick.
        let loop_delay = signal_delay + 1.5 * params.dt();
        let hybrid = HybridController::new(params.hybrid, frame, k_servo, loop_delay);
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
        // Off the surface (less than the touch's force along the normal): a guarded approach.
        let mode =
            if f0.dot(&frame.normal()) < params.approach.touch_fraction * params.hybrid.preload_n {
                ServoMode::Approach
            } else {
                ServoMode::Track
            };
        let probe_capacity = [params.tangent.first_plan(), params.tangent.reprobe_plan()]
            .iter()
            .map(|p| {
                ProbeRunner::samples_needed(p, params.rate_hz, probe_decimation(params.rate_hz))
            })
            .max()
            .unwrap_or(0);
        let mut servo = Self {
            params,
            drive,
            hybrid,
            dither: Dither::new(params.dither.frequency_hz),
            tuner,
            ctx,
            amplitude_bound,
            tuning: false,
            force_control: true,
            tare: Wrench::default(),
            diag: ServoDiag::default(),
            mode,
            probe: ProbeRunner::new(probe_capacity, probe_decimation(params.rate_hz)),
            reprobe: false,
            force_armed: true,
            counters: EstimationCounters::default(),
            last_outcome: None,
            last_trigger: None,
            track: TrackState {
                normal_filtered_n: params.hybrid.preload_n,
                curve_base_rad: tangent_angle,
                ..TrackState::default()
            },
            last_estimate: None,
            normal_window: crate::window::SlidingWindow::new(
                (params.rate_hz / params.dither.frequency_hz)
                    .round()
                    .max(1.0) as usize,
            ),
            safe: None,
            resume_a_omega: None,
            last_stroke: SetpointOffset::default(),
            contact_lost_ticks: 0,
            confirm_corner: false,
            // Derived below with the other contact-dependent gains.
            normal_damping: 0.0,
            contact_mode,
            loop_delay,
            stiffness: crate::contact::StiffnessEstimator::new(Default::default()),
            stiffness_frame: frame,
            contact_phase: 0,
            adopted: 0,
            approach_speed: params.approach.speed(params.hybrid.preload_n, normal_mass),
            provisional: false,
        };
        if mode == ServoMode::Approach {
            servo.assume_stiffest_contact();
        } else {
            servo.use_stiffness(params.hybrid.stiffness_estimate_n_per_m);
        }
        servo
    }

    /// Sensor-frame force to world: rotation by the link-2 angle q1+q2.
    fn to_world(arm: &Arm, q: Vector2<f64>, w: Wrench) -> Vec2 {
        let p = arm.pose(q);
        drive::to_plane(p.s12, p.c12, w)
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

    /// Joint PID gains of the two-link arm (`None` on a task-space drive).
    pub fn gains(&self) -> Option<[PidGains; 2]> {
        match &self.drive {
            drive::Drive::TwoLink(two) => Some(two.pid.gains),
            drive::Drive::Task(_) => None,
        }
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

    /// The damping added along the normal (N·s/m).
    pub fn normal_damping(&self) -> f64 {
        self.normal_damping
    }

    /// The contact mode's arm side at the start, along the normal: the arm's effective mass
    /// (kg), the servo's own damping (N·s/m) and stiffness (N/m).
    pub fn contact_mode(&self) -> [f64; 3] {
        self.contact_mode
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
}
