//! One fast-loop tick, in three parts: [`ServoCore::plan`] (the safe state, the dither, the
//! modes and the hybrid controller's set-point, from the tool's position and the contact
//! force), the drive's command ([`super::drive`]), and [`ServoCore::finish`] (triggers, the
//! contact's fit, the tuner and the diagnostics, from the tool's velocity).

use super::drive::{Drive, NormalForces, TaskCommand, TaskInput, force_is_valid, to_plane};
use super::{ServoCore, ServoDiag, ServoInput, ServoMode};
use crate::hybrid::{HybridCommand, SetpointOffset};
use crate::math::Vec2;
use crate::tuner::TunerInput;
use nalgebra::Vector2;

/// What [`ServoCore::plan`] hands to the drive and to [`ServoCore::finish`].
pub(super) struct Planned {
    cmd: HybridCommand,
    extra: SetpointOffset,
    valid: bool,
    safe: bool,
}

impl ServoCore {
    /// One fast-loop tick of the two-link arm: returns the joint torques (N·m). On a servo
    /// built for a task-space drive it returns zero torques (use [`ServoCore::step_task`]).
    pub fn step(&mut self, inp: &ServoInput, dt: f64) -> Vector2<f64> {
        let Drive::TwoLink(two) = &self.drive else {
            return Vector2::zeros();
        };
        let valid = force_is_valid(inp.force_valid, &inp.wrench);
        let pose = two.arm.pose(inp.q);
        let tip = two.arm.forward_at(&pose);
        // The Jacobian at the measured pose: the tip's velocity (the contact mode's damping,
        // the tuner's tangential velocity, the drift trigger) and the normal forces' torques.
        let j = two.arm.jacobian_at(&pose);
        let tip_velocity = j * inp.qd;
        let force = if valid {
            to_plane(pose.s12, pose.c12, inp.wrench.tared(self.tare))
        } else {
            Vec2::zeros()
        };
        let planned = self.plan(valid, force, tip, dt);
        let probing = self.mode == ServoMode::Probing;
        let normal = self.normal_forces(tip_velocity, &planned);
        let inertia_feedforward = self.params.inertia_feedforward;
        let Drive::TwoLink(two) = &mut self.drive else {
            return Vector2::zeros();
        };
        // Frozen integrators make the stroke response stationary (they would otherwise relax a
        // DC offset picked up in the ramp-in over their ~1 s time constant).
        two.pid.set_integrating(!probing);
        let (tau, held) = two.torque(
            &planned.cmd,
            inp.q,
            inp.qd,
            &j,
            &normal,
            inertia_feedforward,
            dt,
        );
        self.finish(&planned, tip, tip_velocity, tau, held, dt);
        tau
    }

    /// One fast-loop tick of a servo on a task-space drive ([`ServoCore::new_task`]): returns
    /// the force and moment the arm is to apply to the tool in the plane (zero on a servo built
    /// for the two-link arm).
    pub fn step_task(&mut self, inp: &TaskInput, dt: f64) -> TaskCommand {
        let Drive::Task(drive) = self.drive else {
            return TaskCommand::default();
        };
        // A pose that is not a number leaves nothing to control: no force, nothing advanced
        // (the robot's guard holds the arm; `robot_guard`).
        if !(inp.position_m.iter().all(|v| v.is_finite())
            && inp.velocity_m_per_s.iter().all(|v| v.is_finite())
            && inp.theta_rad.is_finite()
            && inp.theta_rate_rad_per_s.is_finite())
        {
            return TaskCommand::default();
        }
        let valid = force_is_valid(inp.force_valid, &inp.wrench);
        let force = if valid {
            let (s, c) = inp.theta_rad.sin_cos();
            to_plane(s, c, inp.wrench.tared(self.tare))
        } else {
            Vec2::zeros()
        };
        let planned = self.plan(valid, force, inp.position_m, dt);
        let normal = self.normal_forces(inp.velocity_m_per_s, &planned);
        let out = drive.command(&planned.cmd, inp, &normal, self.params.inertia_feedforward);
        self.finish(
            &planned,
            inp.position_m,
            inp.velocity_m_per_s,
            out.force_n,
            false,
            dt,
        );
        out
    }

    /// The safe state, the dither, the modes and the hybrid controller's set-point, from the
    /// tool's position `tip` (m) and the contact force `force` (N, in the plane; zero unless
    /// `valid`).
    fn plan(&mut self, valid: bool, force: Vec2, tip: Vec2, dt: f64) -> Planned {
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
                extra = self.probe.step(dt, force, tip);
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
        let cmd = self.hybrid.step(dt, force, dither, extra, force_loop);
        Planned {
            cmd,
            extra,
            valid,
            safe,
        }
    }

    /// The normal forces both drives add to the set-point's, at the tool's velocity
    /// `tip_velocity` (m/s).
    fn normal_forces(&self, tip_velocity: Vec2, planned: &Planned) -> NormalForces {
        let n_hat = self.hybrid.frame().normal();
        // The preload's feedforward depends on the configuration and the desired force, not on
        // the measurement: it stays on in the safe state (the set-point backs off instead).
        let preload = self
            .params
            .preload_feedforward
            .then(|| n_hat * self.hybrid.params().preload_n);
        // Damps the contact mode: the normal velocity's error against the set-point's own (the
        // force loop's rate), not against a probe stroke's, which presses into the surface on
        // purpose (docs/contact.md).
        let damping = (self.normal_damping > 0.0).then(|| {
            let error = (tip_velocity - planned.cmd.velocity + planned.extra.velocity).dot(&n_hat);
            n_hat * (self.normal_damping * error)
        });
        NormalForces { preload, damping }
    }

    /// Triggers, the contact's fit, the tuner and the diagnostics, after the drive's command
    /// `drive_out` (joint torques, or the planar force) and whether its set-point was `held`.
    fn finish(
        &mut self,
        planned: &Planned,
        tip: Vec2,
        tip_velocity: Vec2,
        drive_out: Vector2<f64>,
        held: bool,
        dt: f64,
    ) {
        let Planned {
            cmd, valid, safe, ..
        } = *planned;
        let n_hat = self.hybrid.frame().normal();
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
                self.observe_contact(dt, tip, normal);
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
            torque: drive_out,
            setpoint_held: held,
            mode: self.mode,
            tangent_angle_rad: self.hybrid.frame().tangent_angle,
            velocity_target_m_per_s: self.hybrid.velocity_target(),
            safe,
        };
    }
}

#[cfg(test)]
#[path = "step_tests.rs"]
mod tests;
