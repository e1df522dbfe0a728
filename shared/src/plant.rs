//! The simulated world (thesis ch. 3, fig. 3.2): the two-link arm, its tool in contact with a
//! surface through the normal contact law, friction with a presliding state per contact, and
//! the true wrench the force sensor sees.
//!
//! One [`Plant::step`] integrates the arm by semi-implicit Euler over one servo period: contact
//! and friction forces from the state at the start of the step, then velocities, then positions.
//! The friction state uses an exact exponential update (stable at the servo step) and the
//! contact springs are far below the step's stability limit at 10 kHz (see `docs/model.md`).
//! Allocation-free.

use crate::arm::{Arm, ArmParams, Elbow};
use crate::error::ConfigError;
use crate::friction::{FrictionLaw, Presliding, PreslidingParams, RoughnessMap};
use crate::math::{Vec2, cross};
use crate::sensor::Wrench;
use crate::surface::{ContactLaw, Surface};
use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

/// Physical parameters of the world except the surface geometry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlantParams {
    /// The arm.
    pub arm: ArmParams,
    /// Which inverse-kinematics branch the arm works in.
    pub elbow: Elbow,
    /// Normal contact law.
    pub contact: ContactLaw,
    /// Friction law (eq. 4.5) at `reference_normal_force_n`.
    pub friction: FrictionLaw,
    /// Normal force at which `friction` holds (N); friction scales with F_N / this.
    pub reference_normal_force_n: f64,
    /// Presliding (static friction) parameters.
    pub presliding: PreslidingParams,
    /// Friction coefficient variation along the surface.
    pub roughness: RoughnessMap,
    /// Mass of the tool beyond the sensor (kg); the sensor reads its inertial force too.
    pub tool_mass_kg: f64,
    /// Distance from the sensor origin to the tool tip along link 2 (m).
    pub tool_length_m: f64,
}

impl Default for PlantParams {
    fn default() -> Self {
        Self {
            arm: ArmParams::default(),
            elbow: Elbow::Negative,
            contact: ContactLaw::default(),
            friction: FrictionLaw::THESIS,
            reference_normal_force_n: 2.5,
            presliding: PreslidingParams::default(),
            roughness: RoughnessMap::default(),
            tool_mass_kg: 0.05,
            tool_length_m: 0.05,
        }
    }
}

impl PlantParams {
    /// Checks every parameter; the message names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        Arm::validate(&self.arm)?;
        self.contact.validate()?;
        self.friction.validate()?;
        self.presliding.validate()?;
        let r = self.reference_normal_force_n;
        if !(r.is_finite() && r > 0.0) {
            return Err(ConfigError::setting(
                "plant.reference_normal_force_n",
                r,
                "must be > 0",
            ));
        }
        if !(self.tool_mass_kg.is_finite() && self.tool_mass_kg >= 0.0) {
            return Err(ConfigError::setting(
                "plant.tool_mass_kg",
                self.tool_mass_kg,
                "must be ≥ 0",
            ));
        }
        if self.tool_mass_kg > self.arm.tip_mass_kg {
            return Err(ConfigError::setting(
                "plant.tool_mass_kg",
                self.tool_mass_kg,
                format!(
                    "exceeds arm.tip_mass_kg = {} (the tip mass includes the tool)",
                    self.arm.tip_mass_kg
                ),
            ));
        }
        if !(self.tool_length_m.is_finite() && self.tool_length_m >= 0.0) {
            return Err(ConfigError::setting(
                "plant.tool_length_m",
                self.tool_length_m,
                "must be ≥ 0",
            ));
        }
        for p in &self.roughness.patches {
            if !(p.centre_m.is_finite() && p.half_width_m.is_finite() && p.gain.is_finite()) {
                return Err(ConfigError::rule(
                    "plant.roughness",
                    "has a non-finite patch",
                ));
            }
        }
        Ok(())
    }
}

/// Everything true about the world at one instant (what an ideal observer would see).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct PlantTruth {
    /// Simulated time (s).
    pub time_s: f64,
    /// Joint angles (rad).
    pub q: Vector2<f64>,
    /// Joint rates (rad/s).
    pub qd: Vector2<f64>,
    /// Tool tip position (m, world).
    pub tip: Vec2,
    /// Tool tip velocity (m/s, world).
    pub tip_velocity: Vec2,
    /// Tool tip acceleration (m/s², world).
    pub tip_acceleration: Vec2,
    /// Total contact force on the tool (N, world).
    pub contact_force: Vec2,
    /// Number of contacts (0, 1 or 2).
    pub contact_count: usize,
    /// Sum of normal pushes (N).
    pub normal_force_n: f64,
    /// Friction on the tool along the first contact's tangent (N, signed along the tangent).
    pub friction_force_n: f64,
    /// Sliding velocity along the first contact's tangent (m/s).
    pub sliding_velocity_m_per_s: f64,
    /// Penetration of the deepest contact (m).
    pub depth_m: f64,
    /// Surface coordinate of the first contact (m).
    pub surface_u_m: f64,
    /// World angle of the first contact's tangent (rad).
    pub tangent_angle_rad: f64,
    /// Local friction coefficient multiplier at the first contact.
    pub roughness_factor: f64,
    /// The wrench the sensor feels, in the sensor frame (x along link 2).
    pub sensor_wrench: Wrench,
    /// Joint torques applied during the step (N·m).
    pub torque: Vector2<f64>,
}

/// The world's dynamic state: what must survive a restart of the servo to resume the world.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PlantState {
    /// Simulated time (s).
    pub time_s: f64,
    /// Joint angles (rad).
    pub q: [f64; 2],
    /// Joint rates (rad/s).
    pub qd: [f64; 2],
    /// Friction states of the two contact slots: (face index, bristle deflection m); face
    /// `usize::MAX` marks an empty slot.
    pub friction: [(usize, f64); 2],
}

/// The simulated world.
#[derive(Debug, Clone)]
pub struct Plant {
    arm: Arm,
    params: PlantParams,
    surface: Surface,
    q: Vector2<f64>,
    qd: Vector2<f64>,
    time_s: f64,
    slots: [(usize, Presliding); 2],
    truth: PlantTruth,
}

const EMPTY: usize = usize::MAX;

impl Plant {
    /// A world with the arm at rest at `q`.
    pub fn new(params: PlantParams, surface: Surface, q: Vector2<f64>) -> Self {
        let arm = Arm::new(params.arm);
        let mut p = Self {
            arm,
            params,
            surface,
            q,
            qd: Vector2::zeros(),
            time_s: 0.0,
            slots: [(EMPTY, Presliding::default()); 2],
            truth: PlantTruth::default(),
        };
        p.truth = p.evaluate(Vector2::zeros(), 0.0).0;
        p
    }

    /// The arm model.
    pub fn arm(&self) -> &Arm {
        &self.arm
    }

    /// The parameters.
    pub fn params(&self) -> &PlantParams {
        &self.params
    }

    /// The surface.
    pub fn surface(&self) -> &Surface {
        &self.surface
    }

    /// Moves the surface (a turntable, a part pushed by something else): the next step sees
    /// `surface`. The presliding states are kept, so the move must be small per step.
    pub fn set_surface(&mut self, surface: Surface) {
        self.surface = surface;
    }

    /// Truth at the start of the last step (forces and accelerations from that step).
    pub fn truth(&self) -> &PlantTruth {
        &self.truth
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        self.time_s
    }

    /// Joint angles and rates (what the encoders read).
    pub fn joints(&self) -> (Vector2<f64>, Vector2<f64>) {
        (self.q, self.qd)
    }

    /// Snapshot of the dynamic state.
    pub fn state(&self) -> PlantState {
        PlantState {
            time_s: self.time_s,
            q: [self.q[0], self.q[1]],
            qd: [self.qd[0], self.qd[1]],
            friction: [
                (self.slots[0].0, self.slots[0].1.deflection_m),
                (self.slots[1].0, self.slots[1].1.deflection_m),
            ],
        }
    }

    /// Restores a snapshot taken by [`Plant::state`].
    pub fn restore(&mut self, s: &PlantState) {
        self.time_s = s.time_s;
        self.q = Vector2::new(s.q[0], s.q[1]);
        self.qd = Vector2::new(s.qd[0], s.qd[1]);
        for k in 0..2 {
            self.slots[k] = (
                s.friction[k].0,
                Presliding {
                    deflection_m: s.friction[k].1,
                },
            );
        }
        self.truth = self.evaluate_static();
    }

    fn evaluate_static(&mut self) -> PlantTruth {
        let saved = self.slots;
        let (t, _) = self.evaluate(Vector2::zeros(), 0.0);
        self.slots = saved;
        t
    }

    /// Contact and friction forces at the current state, advancing friction states by `dt`
    /// (0 leaves them). Returns the truth (without accelerations) and the tip force.
    fn evaluate(&mut self, tau: Vector2<f64>, dt: f64) -> (PlantTruth, Vector2<f64>) {
        let p = &self.params;
        let pose = self.arm.pose(self.q);
        let tip = self.arm.forward_at(&pose);
        let jac = self.arm.jacobian_at(&pose);
        let vel = jac * self.qd;
        let contacts = self.surface.contacts(tip);
        let mut force = Vec2::zeros();
        let mut normal_sum = 0.0;
        let mut truth = PlantTruth {
            time_s: self.time_s,
            q: self.q,
            qd: self.qd,
            tip,
            tip_velocity: vel,
            torque: tau,
            ..Default::default()
        };
        let mut new_slots = [(EMPTY, Presliding::default()); 2];
        for (i, c) in contacts.as_slice().iter().enumerate() {
            let depth_rate = -vel.dot(&c.normal);
            let fn_ = p.contact.normal_force(c.depth_m, depth_rate);
            let v_slide = vel.dot(&c.tangent);
            let mut state = self
                .slots
                .iter()
                .find(|s| s.0 == c.feature)
                .map(|s| s.1)
                .unwrap_or_default();
            let rough = p.roughness.factor(c.u_m);
            let fr = if fn_ > 0.0 {
                let law = p.friction.scaled(fn_ / p.reference_normal_force_n * rough);
                if dt > 0.0 {
                    state.step(&law, &p.presliding, v_slide, dt)
                } else {
                    p.presliding.stiffness_n_per_m * state.deflection_m
                        + law.viscous_n_s_per_m * v_slide
                }
            } else {
                state.reset();
                0.0
            };
            new_slots[i] = (c.feature, state);
            force += c.normal * fn_ - c.tangent * fr;
            normal_sum += fn_;
            if i == 0 {
                truth.friction_force_n = -fr;
                truth.sliding_velocity_m_per_s = v_slide;
                truth.surface_u_m = c.u_m;
                truth.tangent_angle_rad = c.tangent.y.atan2(c.tangent.x);
                truth.roughness_factor = rough;
            }
            truth.depth_m = truth.depth_m.max(c.depth_m);
        }
        if dt > 0.0 {
            self.slots = new_slots;
        }
        if contacts.count == 0 {
            let (u, _) = self.surface.to_local(tip);
            truth.surface_u_m = u;
            truth.tangent_angle_rad = self.surface.tangent_angle_at(u);
            truth.roughness_factor = p.roughness.factor(u);
        }
        truth.contact_count = contacts.count;
        truth.normal_force_n = normal_sum;
        truth.contact_force = force;
        let acc = self.arm.acceleration_at(&pose, self.qd, tau, force);
        truth.tip_acceleration = jac * acc + self.arm.jacobian_dot_at(&pose, self.qd) * self.qd;
        truth.sensor_wrench = sensor_wrench(
            (pose.s12, pose.c12),
            self.params.tool_mass_kg,
            self.params.tool_length_m,
            force,
            truth.tip_acceleration,
        );
        (truth, acc)
    }

    /// Advances the world by `dt` (s) under joint torques `tau` (N·m).
    pub fn step(&mut self, tau: Vector2<f64>, dt: f64) {
        let (truth, acc) = self.evaluate(tau, dt);
        self.qd += acc * dt;
        self.q += self.qd * dt;
        self.time_s += dt;
        self.truth = truth;
    }
}

/// The wrench the sensor transmits: contact force minus the tool's inertial force
/// (`tool_mass_kg` × tip acceleration), in the sensor frame (x along link 2, whose angle's
/// sine and cosine are `link2`), with the moment about the sensor origin (`tool_length_m`
/// behind the tip). Every world (built-in, MuJoCo) reports its sensor wrench through this.
pub fn sensor_wrench(
    link2: (f64, f64),
    tool_mass_kg: f64,
    tool_length_m: f64,
    contact_force: Vec2,
    tip_acc: Vec2,
) -> Wrench {
    let (s, c) = link2;
    let xe = Vec2::new(c, s);
    let f = contact_force - tip_acc * tool_mass_kg;
    let moment = cross(xe * tool_length_m, f);
    Wrench {
        force: Vec2::new(c * f.x + s * f.y, -s * f.x + c * f.y),
        torque: moment,
    }
}

/// The joint torques that hold the arm at rest against a tip force `f_tip` (world, on the tool):
/// `τ = −Jᵀ f`.
pub fn holding_torque(arm: &Arm, q: Vector2<f64>, f_tip: Vec2) -> Vector2<f64> {
    -(arm.jacobian(q).transpose() * f_tip)
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::math::unit;

    fn world() -> (Plant, Vector2<f64>) {
        let params = PlantParams::default();
        let arm = Arm::new(params.arm);
        let q0 = arm.decoupled_configuration(0.0, Elbow::Negative).unwrap();
        let tip = arm.forward(q0);
        let surface = Surface::plane(tip, 0.0);
        let depth = 2.5 / params.contact.stiffness();
        let q = arm
            .inverse(tip - Vec2::new(0.0, depth), Elbow::Negative)
            .unwrap();
        (Plant::new(params, surface, q), q)
    }

    /// Pressed into a plane and held by exactly the static torque, the arm stays put and the
    /// sensor reads the preload along its x axis (link 2 points into the surface).
    #[test]
    fn static_contact_equilibrium() {
        let (mut plant, q) = world();
        let f = plant.truth().contact_force;
        assert!((f - Vec2::new(0.0, 2.5)).norm() < 1e-9, "{f:?}");
        let tau = holding_torque(plant.arm(), q, f);
        for _ in 0..1000 {
            plant.step(tau, 1e-4);
        }
        let t = plant.truth();
        assert!((t.q - q).norm() < 1e-9, "drifted {:?}", t.q - q);
        // The sensor frame is link 2's: F = R(−φ)·(0, 2.5).
        let (sn, cs) = plant.arm().link2_angle(t.q).sin_cos();
        let expected = Vec2::new(sn * 2.5, cs * 2.5);
        assert!(
            (t.sensor_wrench.force - expected).norm() < 1e-6,
            "{:?}",
            t.sensor_wrench
        );
        assert!((expected.x + 2.5).abs() < 1e-5);
        // Moment about the sensor origin: r × F with r along the tool axis.
        let m = cross(unit(plant.arm().link2_angle(t.q)) * 0.05, t.contact_force);
        assert!((t.sensor_wrench.torque - m).abs() < 1e-12);
    }

    /// Sliding at constant speed, the friction on the tool equals eq. 4.5 at the actual normal force.
    #[test]
    fn sliding_friction_follows_the_law() {
        let (mut plant, q) = world();
        // Drive the tip along +X at 20 mm/s with a stiff joint-space PD around a moving target.
        let arm = *plant.arm();
        let start = arm.forward(q);
        let mut fr = 0.0;
        let mut fnn = 0.0;
        let mut v = 0.0;
        for k in 0..5000 {
            let t = k as f64 * 1e-4;
            let target = start + Vec2::new(0.02 * t, 0.0);
            let qd_target = arm.inverse(target, Elbow::Negative).unwrap();
            let (qq, qqd) = plant.joints();
            let jinv = arm.jacobian(qq).try_inverse().unwrap();
            let qd_des = jinv * Vec2::new(0.02, 0.0);
            let tau = (qd_target - qq) * 4000.0
                + (qd_des - qqd) * 60.0
                + holding_torque(&arm, qq, Vec2::new(0.0, 2.5));
            plant.step(tau, 1e-4);
            let tr = plant.truth();
            fr = tr.friction_force_n;
            fnn = tr.normal_force_n;
            v = tr.sliding_velocity_m_per_s;
        }
        let law = plant.params().friction.scaled(fnn / 2.5);
        assert!((v - 0.02).abs() < 1e-4, "v = {v}");
        assert!(
            (fr + law.resistance(v)).abs() < 2e-3,
            "friction {fr} vs law {}",
            -law.resistance(v)
        );
    }

    #[test]
    fn state_round_trip() {
        let (mut plant, q) = world();
        let tau =
            holding_torque(plant.arm(), q, plant.truth().contact_force) + Vector2::new(0.0, 0.3);
        for _ in 0..200 {
            plant.step(tau, 1e-4);
        }
        let s = plant.state();
        let mut copy = plant.clone();
        for _ in 0..100 {
            plant.step(tau, 1e-4);
        }
        copy.restore(&s);
        for _ in 0..100 {
            copy.step(tau, 1e-4);
        }
        assert_eq!(copy.state(), plant.state());
    }
}
