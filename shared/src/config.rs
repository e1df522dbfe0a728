//! The set-up: everything that defines a simulated run ([`SimConfig`]), the table a stack
//! file has under `[sim]` and `afs experiment --config` reads, and which world it runs in
//! ([`WorldConfig`]). Below the world and the lockstep, which both take it.

use crate::arm::{Arm, Elbow};
use crate::error::ConfigError;
use crate::insertion::options::InsertionOptions;
use crate::math::Vec2;
use crate::plant::PlantParams;
use crate::sensor::SensorParams;
use crate::servo::ServoParams;
use crate::surface::Surface;
use serde::{Deserialize, Serialize};

/// Everything that defines a simulated set-up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// The world.
    pub plant: PlantParams,
    /// The surface.
    pub surface: Surface,
    /// The force sensor.
    pub sensor: SensorParams,
    /// The servo board.
    pub servo: ServoParams,
    /// Where along the surface the tool starts, in pressed contact at the preload (m, u).
    pub start_u_m: f64,
    /// Error of the initial tangent estimate (rad): estimate = true tangent + this.
    pub tangent_error_rad: f64,
    /// How far off the surface the tool starts, along its normal (m): 0 starts it pressed in at
    /// the preload; more starts it free, and the servo approaches (docs/contact.md, *First
    /// touch*).
    pub start_gap_m: f64,
    /// Seed of the sensor noise.
    pub seed: u64,
    /// Which world the servo drives (builtin or MuJoCo).
    pub world: WorldConfig,
    /// The insertion's fit, initial errors, method and limits (`insertion` scenario and
    /// experiment; docs/insertion.md).
    pub insertion: InsertionOptions,
}

impl Default for SimConfig {
    /// The thesis set-up: a flat surface under the arm's decoupled operating point (tip at
    /// (0.4, 0) m, link 2 pointing into the surface), thesis friction, 2.5 N preload.
    fn default() -> Self {
        let plant = PlantParams::default();
        let arm = Arm::new(plant.arm);
        let q = arm
            .decoupled_configuration(0.0, Elbow::Negative)
            .unwrap_or_default();
        let tip = arm.forward(q);
        Self {
            plant,
            surface: Surface::plane(tip, 0.0),
            sensor: SensorParams::default(),
            servo: ServoParams::default(),
            start_u_m: 0.0,
            tangent_error_rad: 0.0,
            start_gap_m: 0.0,
            seed: 1,
            world: WorldConfig::default(),
            insertion: InsertionOptions::default(),
        }
    }
}

impl SimConfig {
    /// Checks the whole set-up.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.plant.validate()?;
        self.surface.validate()?;
        self.sensor.validate()?;
        self.servo.validate()?;
        self.world.validate()?;
        self.insertion.validate()?;
        if !self.start_u_m.is_finite() || !self.tangent_error_rad.is_finite() {
            return Err(ConfigError::rule(
                "start_u_m and tangent_error_rad",
                "must be finite",
            ));
        }
        if !(self.start_gap_m.is_finite() && (0.0..=0.05).contains(&self.start_gap_m)) {
            return Err(ConfigError::setting(
                "start_gap_m",
                self.start_gap_m,
                "must lie in [0, 0.05] m (0: start pressed in at the preload)",
            ));
        }
        if self.tangent_error_rad.abs() > 0.5 {
            return Err(ConfigError::setting(
                "tangent_error_rad",
                self.tangent_error_rad,
                "is beyond ±0.5 rad; the hybrid controller needs a rough estimate",
            ));
        }
        Ok(())
    }

    /// The servo's settings, with the force signal's delay taken from the sensor where the
    /// settings leave it out.
    pub fn servo_params(&self) -> crate::servo::ServoParams {
        let mut p = self.servo;
        if p.hybrid.force_signal_delay_s.is_none() {
            p.hybrid.force_signal_delay_s = Some(self.sensor.signal_delay_s());
        }
        p
    }

    /// The joint angles that put the tool at the start point: pressed in to the preload, or
    /// `start_gap_m` off the surface.
    pub fn start_configuration(&self) -> Result<nalgebra::Vector2<f64>, ConfigError> {
        let arm = Arm::new(self.plant.arm);
        let on_surface = self.surface.point_at(self.start_u_m);
        let angle = self.surface.tangent_angle_at(self.start_u_m);
        let normal = crate::math::perp(crate::math::unit(angle));
        let depth = if self.start_gap_m > 0.0 {
            -self.start_gap_m
        } else {
            self.servo.hybrid.preload_n / self.plant.contact.stiffness()
        };
        let tip: Vec2 = on_surface - normal * depth;
        Ok(arm.inverse(tip, self.plant.elbow)?)
    }
}

/// Which world the servo drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WorldKind {
    /// afs's own plant (docs/model.md).
    #[default]
    Builtin,
    /// MuJoCo, on a model afs generates from the set-up or on the user's own (docs/mujoco.md).
    Mujoco,
}

impl WorldKind {
    /// Its name in configuration and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            WorldKind::Builtin => "builtin",
            WorldKind::Mujoco => "mujoco",
        }
    }

    /// The kind named `s` (`builtin`, `mujoco`).
    pub fn parse(s: &str) -> Result<Self, ConfigError> {
        match s {
            "builtin" => Ok(WorldKind::Builtin),
            "mujoco" => Ok(WorldKind::Mujoco),
            _ => Err(ConfigError::rule(
                "world.kind",
                format!("is `{s}`; use `builtin` or `mujoco`"),
            )),
        }
    }
}

/// The MuJoCo model's settings (generated models; a user's model keeps its own contact).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MujocoParams {
    /// Radius of the tool's contact sphere (m); the surface geoms sit this far inside the
    /// surface, so the sphere touches when the tool tip reaches it.
    pub tool_radius_m: f64,
    /// Constraint impedance d (solimp's dmin = dmax): with solref's direct form set from it,
    /// the static contact stiffness is the set-up's k_e whatever d (docs/mujoco.md).
    pub impedance: f64,
    /// Ratio of frictional to normal impedance (MuJoCo's `impratio`): the larger, the less the
    /// tool creeps under a tangential force inside the friction cone.
    pub impratio: f64,
    /// The damping of the friction directions (N·s/m, solreffriction's direct form): below the
    /// cone, MuJoCo's friction resists sliding like this damper; the larger, the closer to
    /// stick (docs/mujoco.md).
    pub friction_damping_n_s_per_m: f64,
    /// Iterations of MuJoCo's noslip post-solver (0: off), which removes the friction
    /// directions' slip that the soft model allows.
    pub noslip_iterations: u32,
    /// MuJoCo's pyramidal friction cone instead of the elliptic one.
    pub pyramidal: bool,
    /// Add eq. 4.5's Stribeck and viscous terms as applied forces on the tool, beside MuJoCo's
    /// Coulomb cone (false: MuJoCo's friction alone).
    pub applied_friction: bool,
    /// Half the length of the generated surface along its base tangent (m).
    pub surface_half_length_m: f64,
}

impl Default for MujocoParams {
    fn default() -> Self {
        Self {
            tool_radius_m: 0.5e-3,
            impedance: 0.01,
            impratio: 1e5,
            friction_damping_n_s_per_m: 5.0,
            pyramidal: false,
            noslip_iterations: 0,
            applied_friction: false,
            surface_half_length_m: 0.25,
        }
    }
}

impl MujocoParams {
    /// Checks every setting; the message names it.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let positive = [
            ("world.mujoco.tool_radius_m", self.tool_radius_m),
            ("world.mujoco.impratio", self.impratio),
            (
                "world.mujoco.friction_damping_n_s_per_m",
                self.friction_damping_n_s_per_m,
            ),
            (
                "world.mujoco.surface_half_length_m",
                self.surface_half_length_m,
            ),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(ConfigError::setting(name, v, "must be > 0"));
            }
        }
        if !(self.impedance > 0.0 && self.impedance < 1.0) {
            return Err(ConfigError::setting(
                "world.mujoco.impedance",
                self.impedance,
                "must lie strictly between 0 and 1",
            ));
        }
        Ok(())
    }
}

/// Which world, and how it is built.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WorldConfig {
    /// builtin or mujoco.
    pub kind: WorldKind,
    /// A user's MJCF file (mujoco only): a planar arm with two hinge joints, a site named
    /// `tool` and a body named `surface`. None: afs generates the model from the set-up.
    pub mjcf: Option<String>,
    /// The generated MuJoCo model's settings.
    pub mujoco: MujocoParams,
}

impl WorldConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.mujoco.validate()?;
        if self.mjcf.is_some() && self.kind != WorldKind::Mujoco {
            return Err(ConfigError::rule(
                "world.mjcf",
                "is a MuJoCo model; set world.kind = \"mujoco\" (or --plant mujoco) with it",
            ));
        }
        Ok(())
    }
}
