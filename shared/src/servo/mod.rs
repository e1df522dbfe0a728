//! The fast loop of the plant/servo board: one tick of hybrid control, friction-suppression
//! dither and its tuner, inverse kinematics and the PID joint servos.
//!
//! [`ServoCore::step`] is what the servo process runs at 10 kHz and what the lockstep
//! simulation runs in simulated time. It allocates nothing, takes no lock, does no I/O and
//! never panics on bad numbers: a non-finite force is treated as missing data (force loop and
//! tuner frozen), an unreachable set-point holds the last reachable one.

//!
//! | file | concept |
//! |---|---|
//! | `params` | the settings ([`ServoParams`], [`SafeParams`], [`TrackingParams`]) |
//! | `tracking` | modes, triggers, the probe run and the estimator's answer (§5.3.2) |
//! | `safe` | the safe state on untrusted force data |
//! | `state` | [`ServoState`]: everything that crosses a restart, made of named parts |

pub(crate) mod contact;
mod params;
mod safe;
mod state;
mod tracking;

pub use contact::{
    ContactReport, ContactState, contact_damping, contact_mode_above_dither, dither_damping_ratio,
};
pub use params::{
    ApproachParams, DriftSource, ProbeForceLoop, SafeParams, ServoParams, TrackingParams,
};
pub use safe::SafeState;
pub use state::{ServoState, ServoStateFlags, TareState};
pub use tracking::{EstimationCounters, ProbeRequest, ServoMode, TrackState, Trigger};

use crate::arm::{Arm, ArmParams, Elbow, JointServo, PidGains, tune_pid_for_bandwidth};
use crate::dither::Dither;
use crate::error::ConfigError;
use crate::hybrid::{HybridCommand, HybridController, SetpointOffset, TaskFrame};
use crate::math::Vec2;
use crate::probe::ProbeRunner;
use crate::sensor::Wrench;
use crate::tangent::TangentOutcome;
use crate::tuner::{Tuner, TunerContext, TunerInput, TunerReport};
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
            contact_mode: [normal_mass, normal_servo_damping, k_servo],
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
        Ok(servo)
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

    /// One fast-loop tick: returns the joint torques (N·m).
    pub fn step(&mut self, inp: &ServoInput, dt: f64) -> Vector2<f64> {
        let valid = inp.force_valid
            && inp.wrench.force.x.is_finite()
            && inp.wrench.force.y.is_finite()
            && inp.wrench.torque.is_finite();
        let pose = self.arm.pose(inp.q);
        let wrench = inp.wrench.tared(self.tare);
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
                self.track.drift_rad = 0.0;
                self.hybrid.set_velocity(self.track.resume_velocity_m_per_s);
                if let Some(a) = self.resume_a_omega.take() {
                    self.set_a_omega(a);
                }
            }
            Some(ServoMode::Approach) => self.approach(force),
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
        let force_loop = valid && self.force_control && (!probing || self.probes_hold_force());
        self.hybrid
            .set_rate_limit(if self.mode == ServoMode::Approach {
                self.approach_speed
            } else {
                self.hybrid.params().max_normal_rate_m_per_s
            });
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
        // The Jacobian at the measured pose: the preload's feedforward, and the tip's velocity
        // (the contact mode's damping, the tuner's tangential velocity, the drift trigger).
        let j = self.arm.jacobian_at(&pose);
        let tip_velocity = j * inp.qd;
        let n_hat = self.hybrid.frame().normal();
        // The preload's feedforward depends on the configuration and the desired force, not on
        // the measurement: it stays on in the safe state (the set-point backs off instead).
        if self.params.preload_feedforward {
            feedforward -= j.transpose() * (n_hat * self.hybrid.params().preload_n);
        }
        if self.normal_damping > 0.0 {
            // Damps the contact mode: the normal velocity's error against the set-point's own
            // (the force loop's rate), not against a probe stroke's, which presses into the
            // surface on purpose (docs/contact.md).
            let error = (tip_velocity - cmd.velocity + extra.velocity).dot(&n_hat);
            feedforward -= j.transpose() * (n_hat * (self.normal_damping * error));
        }
        let tau = self.pid.torque(q_d, qd_d, inp.q, inp.qd, feedforward, dt);

        // Tuner: friction resisting the nominal motion, normalised to the model's reference force.
        let t_hat = self.hybrid.frame().tangent();
        let dir = if self.hybrid.velocity_target() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let v_tan = tip_velocity.dot(&t_hat);
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
            self.check_triggers(dt, normal, -tip_velocity.dot(&n_hat));
            self.guard_contact(dt, normal);
            if self.observes_contact(normal) {
                self.observe_contact(dt, &pose, normal);
            }
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
