//! Hybrid position/force control in task coordinates (thesis §3.2, fig. 3.4).
//!
//! Task frame at the contact: `x` into the environment along the estimated normal (−n̂),
//! `y` along the estimated tangent t̂. The selection matrix `R = diag(1, 0)` gives x to the
//! force controller and y to the position controller; each produces a position update and the
//! two are combined into one Cartesian set-point, sent through inverse kinematics to the PID
//! joint servos.
//!
//! * Force along x: a Hooke's-law position update, `ẋ_cmd = ω_f (F_d − F_N)/k̂`. The stiffness
//!   k̂ is the estimated interaction stiffness k̂_e in series with the servo's own Cartesian
//!   stiffness along the normal (the PID joints are far softer than a metal contact, so using
//!   k̂_e alone would make the loop ω_f k_servo/k̂_e slow; see `docs/model.md`). With that k̂ the
//!   force loop crosses over near ω_f. An over-estimate of k̂ makes it sluggish, an
//!   under-estimate aggressive (thesis §3.2).
//! * Position along y: the nominal trajectory (a tangential velocity reached with bounded
//!   acceleration) plus the dither `d` of eq. 4.10.
//!
//! A new tangent estimate is fed forward by re-basing the frame at the current set-point.

use crate::error::ConfigError;
use crate::math::{Vec2, perp, unit};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// Settings of the hybrid controller.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HybridParams {
    /// Desired normal force (preload) F_d (N).
    pub preload_n: f64,
    /// Estimated interaction stiffness k̂_e (N/m).
    pub stiffness_estimate_n_per_m: f64,
    /// Force-loop crossover (Hz).
    pub force_bandwidth_hz: f64,
    /// Largest rate of the normal set-point (m/s).
    pub max_normal_rate_m_per_s: f64,
    /// Tangential acceleration limit of the nominal trajectory (m/s²).
    pub tangential_acceleration_m_per_s2: f64,
    /// Delay of the force signal from the contact to the servo, beyond the servo's own tick: the
    /// sensor's filter and sampling (s). Unset: derived from the set-up's sensor
    /// ([`crate::sensor::SensorParams::signal_delay_s`]). It bounds the force loop's rate
    /// feedforward (docs/contact.md).
    pub force_signal_delay_s: Option<f64>,
}

impl Default for HybridParams {
    fn default() -> Self {
        Self {
            preload_n: 2.5,
            stiffness_estimate_n_per_m: 10e3,
            force_bandwidth_hz: 1.5,
            max_normal_rate_m_per_s: 0.02,
            tangential_acceleration_m_per_s2: 0.2,
            force_signal_delay_s: None,
        }
    }
}

impl HybridParams {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let pos = [
            ("preload_n", self.preload_n),
            (
                "stiffness_estimate_n_per_m",
                self.stiffness_estimate_n_per_m,
            ),
            ("force_bandwidth_hz", self.force_bandwidth_hz),
            ("max_normal_rate_m_per_s", self.max_normal_rate_m_per_s),
            (
                "tangential_acceleration_m_per_s2",
                self.tangential_acceleration_m_per_s2,
            ),
        ];
        for (n, v) in pos {
            if !(v.is_finite() && v > 0.0) {
                return Err(ConfigError::setting(
                    format!("hybrid.{n}"),
                    v,
                    "must be > 0",
                ));
            }
        }
        if let Some(d) = self.force_signal_delay_s
            && !(d.is_finite() && (0.0..=0.1).contains(&d))
        {
            return Err(ConfigError::setting(
                "hybrid.force_signal_delay_s",
                d,
                "must lie in [0, 0.1] s (leave it out to derive it from the sensor)",
            ));
        }
        if self.preload_n > 100.0 {
            return Err(ConfigError::setting(
                "hybrid.preload_n",
                self.preload_n,
                "exceeds 100 N; the sensor is rated 130 N",
            ));
        }
        Ok(())
    }
}

/// The task frame: origin and estimated tangent angle (rad, world).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TaskFrame {
    /// Origin (m, world).
    pub origin: Vec2,
    /// Estimated tangent angle from world X (rad).
    pub tangent_angle: f64,
    tangent: Vec2,
}

impl TaskFrame {
    /// A frame at `origin` with tangent at `tangent_angle` (rad).
    pub fn new(origin: Vec2, tangent_angle: f64) -> Self {
        Self {
            origin,
            tangent_angle,
            tangent: unit(tangent_angle),
        }
    }

    /// Unit tangent t̂ (the task y axis).
    pub fn tangent(&self) -> Vec2 {
        self.tangent
    }

    /// Outward unit normal n̂ (the task x axis is −n̂).
    pub fn normal(&self) -> Vec2 {
        perp(self.tangent)
    }
}

/// An extra set-point motion (world frame), e.g. a tangent-probe stroke.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SetpointOffset {
    /// Displacement (m).
    pub displacement: Vec2,
    /// Velocity (m/s).
    pub velocity: Vec2,
    /// Acceleration (m/s²).
    pub acceleration: Vec2,
}

/// The hybrid controller's output for one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct HybridCommand {
    /// Cartesian set-point (m).
    pub position: Vec2,
    /// Cartesian set-point velocity (m/s).
    pub velocity: Vec2,
    /// Cartesian set-point acceleration (m/s²): nominal and dither, for inertia feedforward.
    pub acceleration: Vec2,
    /// Measured normal force F_N = F·n̂ (N).
    pub normal_force_n: f64,
    /// Measured tangential force F·t̂ (N).
    pub tangential_force_n: f64,
}

wire_struct! {
    /// A [`HybridController`]'s state, for a snapshot.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::HybridState")]
    pub struct HybridState {
        /// Task-frame origin (m, world).
        pub origin_m: [f64; 2],
        /// Estimated tangent angle (rad, world).
        pub tangent_angle_rad: f64,
        /// Tangential position from the origin (m).
        pub s_m: f64,
        /// Nominal tangential velocity (m/s).
        pub s_dot_m_per_s: f64,
        /// Requested nominal tangential velocity (m/s).
        pub velocity_target_m_per_s: f64,
        /// Normal set-point into the surface from the origin (m).
        pub depth_m: f64,
        /// Its rate from the force loop (m/s).
        pub depth_rate_m_per_s: f64,
        /// Desired normal force (N).
        pub preload_n: f64,
        /// Stiffness of the Hooke's-law update (N/m).
        pub hooke_stiffness_n_per_m: f64,
        /// The contact stiffness k̂_e in use (N/m): configured, or adopted from the fit.
        pub stiffness_estimate_n_per_m: f64,
        /// β, the fraction of the set-point rate fed forward.
        pub rate_feedforward: f64,
    }
}

/// Hybrid position/force controller state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HybridController {
    params: HybridParams,
    frame: TaskFrame,
    hooke_stiffness: f64,
    /// Tangential position along t̂ from the origin (m).
    s: f64,
    /// Current nominal tangential velocity (m/s).
    s_dot: f64,
    /// Requested nominal tangential velocity (m/s).
    v_target: f64,
    /// Normal set-point along −n̂ (into the surface) from the origin (m).
    depth: f64,
    depth_rate: f64,
    /// β: the fraction of the force loop's set-point rate fed forward as a velocity
    /// ([`rate_feedforward_fraction`]).
    rate_feedforward: f64,
    /// The normal set-point's rate limit in force (m/s): `max_normal_rate_m_per_s`, or a
    /// guarded approach's speed ([`Self::set_rate_limit`]).
    rate_limit: f64,
}

impl HybridController {
    /// A controller whose set-point starts at the frame origin. `servo_normal_stiffness` is the
    /// PID servo's Cartesian stiffness along the normal (N/m); `loop_delay_s` the force
    /// signal's whole delay from the contact to the torque (s).
    pub fn new(
        params: HybridParams,
        frame: TaskFrame,
        servo_normal_stiffness: f64,
        loop_delay_s: f64,
    ) -> Self {
        let mut c = Self {
            params,
            frame,
            hooke_stiffness: params.stiffness_estimate_n_per_m,
            s: 0.0,
            s_dot: 0.0,
            v_target: 0.0,
            depth: 0.0,
            depth_rate: 0.0,
            rate_feedforward: 1.0,
            rate_limit: params.max_normal_rate_m_per_s,
        };
        c.set_stiffness_estimate(
            params.stiffness_estimate_n_per_m,
            servo_normal_stiffness,
            loop_delay_s,
        );
        c
    }

    /// Takes a contact stiffness k̂_e (N/m): the Hooke's-law stiffness k̂ (k̂_e in series with
    /// the servo's `servo_normal_stiffness`, N/m) and β (for the loop's delay `loop_delay_s`,
    /// s) follow. Ignored unless finite and positive.
    pub fn set_stiffness_estimate(
        &mut self,
        stiffness: f64,
        servo_normal_stiffness: f64,
        loop_delay_s: f64,
    ) {
        if !(stiffness.is_finite() && stiffness > 0.0) {
            return;
        }
        let (ke, ks) = (stiffness, servo_normal_stiffness);
        self.params.stiffness_estimate_n_per_m = ke;
        self.hooke_stiffness = if ks > 0.0 && ks.is_finite() {
            ke * ks / (ke + ks)
        } else {
            ke
        };
        let omega = std::f64::consts::TAU * self.params.force_bandwidth_hz;
        self.rate_feedforward =
            rate_feedforward_fraction(self.hooke_stiffness, ke, omega, loop_delay_s);
    }

    /// The settings.
    pub fn params(&self) -> &HybridParams {
        &self.params
    }

    /// Its state: task frame, set-points, force loop.
    pub fn state(&self) -> HybridState {
        HybridState {
            origin_m: [self.frame.origin.x, self.frame.origin.y],
            tangent_angle_rad: self.frame.tangent_angle,
            s_m: self.s,
            s_dot_m_per_s: self.s_dot,
            velocity_target_m_per_s: self.v_target,
            depth_m: self.depth,
            depth_rate_m_per_s: self.depth_rate,
            preload_n: self.params.preload_n,
            hooke_stiffness_n_per_m: self.hooke_stiffness,
            stiffness_estimate_n_per_m: self.params.stiffness_estimate_n_per_m,
            rate_feedforward: self.rate_feedforward,
        }
    }

    /// Restores a state taken by [`HybridController::state`].
    pub fn restore(&mut self, s: &HybridState) {
        self.frame = TaskFrame::new(Vec2::new(s.origin_m[0], s.origin_m[1]), s.tangent_angle_rad);
        self.s = s.s_m;
        self.s_dot = s.s_dot_m_per_s;
        self.v_target = s.velocity_target_m_per_s;
        self.depth = s.depth_m;
        self.depth_rate = s.depth_rate_m_per_s;
        self.params.preload_n = s.preload_n;
        self.hooke_stiffness = s.hooke_stiffness_n_per_m;
        self.params.stiffness_estimate_n_per_m = s.stiffness_estimate_n_per_m;
        self.rate_feedforward = s.rate_feedforward;
    }

    /// Changes the desired normal force (N).
    pub fn set_preload(&mut self, preload_n: f64) {
        if preload_n.is_finite() && preload_n >= 0.0 {
            self.params.preload_n = preload_n;
        }
    }

    /// The stiffness used in the Hooke's-law update (N/m).
    pub fn hooke_stiffness(&self) -> f64 {
        self.hooke_stiffness
    }

    /// The task frame.
    pub fn frame(&self) -> &TaskFrame {
        &self.frame
    }

    /// Requests a nominal tangential velocity (m/s), reached at the acceleration limit.
    pub fn set_velocity(&mut self, v: f64) {
        if v.is_finite() {
            self.v_target = v;
        }
    }

    /// Requested nominal tangential velocity (m/s).
    pub fn velocity_target(&self) -> f64 {
        self.v_target
    }

    /// Current nominal tangential velocity (m/s).
    pub fn nominal_velocity(&self) -> f64 {
        self.s_dot
    }

    /// Stops tangential motion at once (safe state).
    pub fn stop(&mut self) {
        self.v_target = 0.0;
        self.s_dot = 0.0;
    }

    /// The nominal set-point without dither (m).
    pub fn nominal_point(&self) -> Vec2 {
        self.frame.origin + self.frame.tangent() * self.s - self.frame.normal() * self.depth
    }

    /// Feeds forward a new tangent estimate (rad): the frame is re-based at the current
    /// set-point so the command stays continuous.
    pub fn set_tangent(&mut self, tangent_angle: f64) {
        if !tangent_angle.is_finite() {
            return;
        }
        let p = self.nominal_point();
        self.frame = TaskFrame::new(p, tangent_angle);
        self.s = 0.0;
        self.depth = 0.0;
    }

    /// Tangential travel since the frame was last re-based (m).
    pub fn travel(&self) -> f64 {
        self.s
    }

    /// β: the fraction of the force loop's set-point rate fed forward as a velocity.
    pub fn rate_feedforward(&self) -> f64 {
        self.rate_feedforward
    }

    /// Sets β (clamped to [0, 1]), for experiments on the force loop's stability.
    pub fn set_rate_feedforward(&mut self, beta: f64) {
        if beta.is_finite() {
            self.rate_feedforward = beta.clamp(0.0, 1.0);
        }
    }

    /// Rate of the normal set-point from the force loop (m/s, + into the surface).
    pub fn depth_rate(&self) -> f64 {
        self.depth_rate
    }

    /// The normal set-point rate the force loop would command for a measured normal force
    /// `normal` (m/s): `ω_f (F_d − F_N)/k̂`, clamped. Linear in F_N, so feeding it an average
    /// force gives the average rate.
    pub fn depth_rate_for(&self, normal: f64) -> f64 {
        let omega = std::f64::consts::TAU * self.params.force_bandwidth_hz;
        let rate = omega * (self.params.preload_n - normal) / self.hooke_stiffness;
        let lim = self.rate_limit;
        rate.clamp(-lim, lim)
    }

    /// Limits the normal set-point's rate to `limit` (m/s), at most `max_normal_rate_m_per_s`:
    /// a guarded approach's speed, or the settings' limit again. Ignored unless finite and
    /// positive.
    pub fn set_rate_limit(&mut self, limit: f64) {
        if limit.is_finite() && limit > 0.0 {
            self.rate_limit = limit.min(self.params.max_normal_rate_m_per_s);
        }
    }

    /// Normal set-point into the surface since the frame was last re-based (m).
    pub fn depth(&self) -> f64 {
        self.depth
    }

    /// Sets the normal set-point (m into the surface from the frame origin), for position
    /// control along the normal while the force loop is off (the preliminary correlation
    /// method of §5.2 drives it this way).
    pub fn set_normal_setpoint(&mut self, depth: f64) {
        if depth.is_finite() {
            self.depth = depth;
        }
    }

    /// Makes a set-point offset (e.g. an interrupted probe stroke) part of the nominal
    /// set-point, so that dropping the offset leaves the command where it was.
    pub fn absorb_offset(&mut self, offset: Vec2) {
        if offset.x.is_finite() && offset.y.is_finite() {
            self.s += offset.dot(&self.frame.tangent());
            self.depth -= offset.dot(&self.frame.normal());
        }
    }

    /// Moves the normal set-point by `delta` (m, + into the surface), e.g. to back off.
    pub fn shift_depth(&mut self, delta: f64) {
        if delta.is_finite() {
            self.depth += delta;
        }
    }

    /// One tick: `force` is the measured force on the tool (N, world), `dither` the dither
    /// displacement, velocity and acceleration along the tangent, `extra` any further set-point
    /// motion (probe strokes); `force_control` false freezes the force loop (while the force
    /// data is not trusted, or during probe strokes).
    pub fn step(
        &mut self,
        dt: f64,
        force: Vec2,
        dither: (f64, f64, f64),
        extra: SetpointOffset,
        force_control: bool,
    ) -> HybridCommand {
        let t = self.frame.tangent();
        let n = self.frame.normal();
        let f_n = force.dot(&n);
        let f_t = force.dot(&t);
        // Nominal trajectory along y.
        let dv = self.v_target - self.s_dot;
        let max_dv = self.params.tangential_acceleration_m_per_s2 * dt;
        let dv = dv.clamp(-max_dv, max_dv);
        let s_ddot = if dt > 0.0 { dv / dt } else { 0.0 };
        self.s_dot += dv;
        self.s += self.s_dot * dt;
        // Hooke's-law force loop along x (selection R = diag(1, 0)).
        self.depth_rate = if force_control {
            self.depth_rate_for(f_n)
        } else {
            0.0
        };
        self.depth += self.depth_rate * dt;
        let position =
            self.frame.origin + t * (self.s + dither.0) - n * self.depth + extra.displacement;
        let velocity = t * (self.s_dot + dither.1) - n * (self.depth_rate * self.rate_feedforward)
            + extra.velocity;
        let acceleration = t * (s_ddot + dither.2) + extra.acceleration;
        HybridCommand {
            position,
            velocity,
            acceleration,
            normal_force_n: f_n,
            tangential_force_n: f_t,
        }
    }
}

/// β, the fraction of the force loop's set-point rate `ẋ_d = ω_f (F_d − F_N)/k̂` that is fed
/// forward as a set-point velocity (docs/contact.md, *The rate feedforward*).
///
/// Through the joints' damping c the feedforward is a proportional force feedback: it acts on
/// the tool as a spring `κ = β c ω_f k_e/k̂` against the penetration. Seen through a delay τ, a
/// spring κ is a damper `−κ τ`; it must leave the servo's own damping at least half of c, so
/// `β ≤ k̂/(2 ω_f k_e τ)` (c cancels). Full feedforward (β = 1) where that allows it: soft
/// contacts, where it makes the loop follow ω_f; a fraction on stiff ones. `hooke` is k̂ (N/m),
/// `stiffness` k_e (N/m), `omega` ω_f (rad/s), `delay` τ (s).
pub fn rate_feedforward_fraction(hooke: f64, stiffness: f64, omega: f64, delay: f64) -> f64 {
    let bound = hooke / (2.0 * omega * stiffness * delay);
    if bound.is_finite() {
        bound.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against a pure spring of stiffness k̂ (a rigid servo), the force loop is first order with
    /// time constant 1/ω_f: after one time constant the error has fallen to 1/e.
    #[test]
    fn force_loop_is_first_order_against_its_model_stiffness() {
        let params = HybridParams {
            max_normal_rate_m_per_s: 1.0,
            ..Default::default()
        };
        let frame = TaskFrame::new(Vec2::zeros(), 0.0);
        let mut c = HybridController::new(params, frame, f64::INFINITY, 1e-3);
        let k = c.hooke_stiffness();
        assert_eq!(k, 10e3);
        let dt = 1e-4;
        let tau = 1.0 / (std::f64::consts::TAU * params.force_bandwidth_hz);
        let steps = (tau / dt).round() as usize;
        let mut cmd = HybridCommand::default();
        for _ in 0..steps {
            // Environment: surface at y = 0, material below; push = k · depth.
            let depth = (-cmd.position.y).max(0.0);
            cmd = c.step(
                dt,
                Vec2::new(0.0, k * depth),
                (0.0, 0.0, 0.0),
                SetpointOffset::default(),
                true,
            );
        }
        let f = k * (-cmd.position.y);
        let err = (2.5 - f) / 2.5;
        assert!((err - (-1.0f64).exp()).abs() < 2e-3, "error fraction {err}");
    }

    /// β is whole on soft contacts and, on stiff ones, where the delayed feedforward's damper
    /// κτ = β c ω_f k_e τ/k̂ takes half the servo's damping c.
    #[test]
    fn rate_feedforward_stops_at_half_the_damping() {
        let omega = std::f64::consts::TAU * 1.5;
        let (ks, tau) = (1520.0, 0.7e-3);
        let hooke = |ke: f64| ke * ks / (ke + ks);
        assert_eq!(rate_feedforward_fraction(hooke(1e4), 1e4, omega, tau), 1.0);
        for ke in [1e6, 1e7] {
            let beta = rate_feedforward_fraction(hooke(ke), ke, omega, tau);
            let share = beta * omega * ke * tau / hooke(ke);
            assert!((share - 0.5).abs() < 1e-12, "k_e {ke}: κτ/c = {share}");
        }
        assert_eq!(rate_feedforward_fraction(hooke(1e6), 1e6, omega, 0.0), 1.0);
    }

    #[test]
    fn tangent_feed_forward_keeps_setpoint_continuous() {
        let frame = TaskFrame::new(Vec2::new(0.4, 0.0), 0.0);
        let mut c = HybridController::new(HybridParams::default(), frame, 1000.0, 1e-3);
        c.set_velocity(0.02);
        let mut last = Vec2::zeros();
        for _ in 0..5000 {
            last = c
                .step(
                    1e-4,
                    Vec2::new(0.0, 2.0),
                    (0.0, 0.0, 0.0),
                    SetpointOffset::default(),
                    true,
                )
                .position;
        }
        c.set_tangent(0.2);
        let next = c
            .step(
                1e-4,
                Vec2::new(0.0, 2.0),
                (0.0, 0.0, 0.0),
                SetpointOffset::default(),
                true,
            )
            .position;
        assert!((next - last).norm() < 1e-5, "jump {:?}", next - last);
        assert!((c.frame().tangent_angle - 0.2).abs() < 1e-15);
    }

    #[test]
    fn nominal_velocity_respects_acceleration_limit() {
        let frame = TaskFrame::new(Vec2::zeros(), 0.0);
        let mut c = HybridController::new(HybridParams::default(), frame, 1000.0, 1e-3);
        c.set_velocity(0.02);
        c.step(
            1e-4,
            Vec2::zeros(),
            (0.0, 0.0, 0.0),
            SetpointOffset::default(),
            false,
        );
        assert!((c.nominal_velocity() - 0.2 * 1e-4).abs() < 1e-15);
        for _ in 0..2000 {
            c.step(
                1e-4,
                Vec2::zeros(),
                (0.0, 0.0, 0.0),
                SetpointOffset::default(),
                false,
            );
        }
        assert!((c.nominal_velocity() - 0.02).abs() < 1e-15);
    }
}
