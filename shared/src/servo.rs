//! The fast loop of the plant/servo board: one tick of hybrid control, friction-suppression
//! dither and its tuner, inverse kinematics and the PID joint servos.
//!
//! [`ServoCore::step`] is what the servo process runs at 10 kHz and what the lockstep
//! simulation runs in simulated time. It allocates nothing, takes no lock, does no I/O and
//! never panics on bad numbers: a non-finite force is treated as missing data (force loop and
//! tuner frozen), an unreachable set-point holds the last reachable one.

use crate::arm::{Arm, ArmParams, Elbow, JointServo, PidGains, tune_pid_for_bandwidth};
use crate::dither::{Dither, DitherParams};
use crate::friction::FrictionLaw;
use crate::hybrid::{HybridCommand, HybridController, HybridParams, TaskFrame};
use crate::math::Vec2;
use crate::sensor::Wrench;
use crate::tuner::{Tuner, TunerConfig, TunerContext, TunerInput, TunerReport};
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
        }
    }
}

impl ServoParams {
    /// Checks every setting; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.rate_hz.is_finite() && (100.0..=100_000.0).contains(&self.rate_hz)) {
            return Err(format!(
                "servo.rate_hz = {} must lie in [100, 100000]",
                self.rate_hz
            ));
        }
        for (j, b) in self.joint_bandwidth_hz.iter().enumerate() {
            if !(b.is_finite() && *b > 0.0 && *b < self.rate_hz / 20.0) {
                return Err(format!(
                    "servo.joint_bandwidth_hz[{j}] = {b} must be > 0 and below rate_hz/20 = {}",
                    self.rate_hz / 20.0
                ));
            }
        }
        if !(self.joint_damping_ratio.is_finite() && self.joint_damping_ratio > 0.0) {
            return Err(format!(
                "servo.joint_damping_ratio = {} must be > 0",
                self.joint_damping_ratio
            ));
        }
        if !(self.joint_integral_ratio.is_finite()
            && self.joint_integral_ratio >= 0.0
            && self.joint_integral_ratio < 1.0)
        {
            return Err(format!(
                "servo.joint_integral_ratio = {} must lie in [0, 1)",
                self.joint_integral_ratio
            ));
        }
        self.hybrid.validate()?;
        self.dither.validate()?;
        self.tuner.validate()?;
        self.friction_model
            .validate()
            .map_err(|e| format!("servo.friction_model: {e}"))?;
        if !(self.friction_model_reference_n.is_finite() && self.friction_model_reference_n > 0.0) {
            return Err(format!(
                "servo.friction_model_reference_n = {} must be > 0",
                self.friction_model_reference_n
            ));
        }
        if !(self.tool_mass_kg.is_finite() && self.tool_mass_kg >= 0.0) {
            return Err(format!(
                "servo.tool_mass_kg = {} must be ≥ 0",
                self.tool_mass_kg
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
}

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
    ) -> Result<Self, String> {
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
        pid.preset_torque(-(arm.jacobian(q0).transpose() * f0));
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
        let dither = self.dither.step(dt);
        let cmd: HybridCommand = self
            .hybrid
            .step(dt, force, dither, valid && self.force_control);
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
        let feedforward = if self.params.inertia_feedforward {
            self.arm.inverse_dynamics_at(&pose_d, qd_d, qdd_d)
        } else {
            Vector2::zeros()
        };
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
        if self.tuning && valid && nominal > 0.0 {
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
        };
        tau
    }
}
