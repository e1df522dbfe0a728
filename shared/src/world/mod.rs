//! The world the servo drives, chosen by configuration: afs's own [`Plant`] (`builtin`) or
//! MuJoCo (`mujoco`, cargo feature `mujoco`, docs/mujoco.md).
//!
//! The boundary is what a real arm and sensor give a controller: joint torques go in
//! ([`World::step`]); joint angles and rates ([`World::joints`]) and the true contact wrench
//! at the sensor ([`PlantTruth::sensor_wrench`], which the sensor model turns into readings)
//! come out. The rest of [`PlantTruth`] is the ideal observer's view that the checks and plots
//! use; nothing in the controller reads it.

mod boxes;
pub mod mjcf;
#[cfg(feature = "mujoco")]
mod mujoco;
#[cfg(feature = "mujoco")]
mod mujoco_arm;
#[cfg(feature = "mujoco")]
mod mujoco_body;
#[cfg(feature = "mujoco")]
mod mujoco_box;
#[cfg(feature = "mujoco")]
mod mujoco_peg;
#[cfg(feature = "mujoco")]
mod mujoco_wrist;
#[cfg(feature = "mujoco")]
mod user;
pub use boxes::BoxWorld;
#[cfg(feature = "mujoco")]
pub use mujoco::MujocoWorld;
#[cfg(feature = "mujoco")]
pub use mujoco_arm::MujocoArm;
#[cfg(feature = "mujoco")]
pub use mujoco_box::MujocoBox;
#[cfg(feature = "mujoco")]
pub use mujoco_peg::MujocoPeg;

use crate::arm::Arm;
use crate::config::SimConfig;
pub use crate::config::{MujocoParams, WorldConfig, WorldKind};
use crate::error::ConfigError;
use crate::plant::{Plant, PlantParams, PlantState, PlantTruth};
use crate::surface::Surface;
use nalgebra::Vector2;

/// The set-up as its world sees it. With a user's MJCF (`world.mjcf`) the arm is read from
/// the model ([`ArmParams`](crate::arm::ArmParams) replaced, the tool's mass beyond the sensor
/// taken as 0) and a surface left at the default arm's operating point moves to the new arm's;
/// otherwise `cfg` unchanged. Every consumer of the set-up (the lockstep, the servo board)
/// resolves it first, so they all see the same arm.
pub fn resolve(cfg: &SimConfig) -> Result<SimConfig, ConfigError> {
    let Some(path) = &cfg.world.mjcf else {
        return Ok(cfg.clone());
    };
    cfg.world.validate()?;
    #[cfg(feature = "mujoco")]
    {
        let mut out = cfg.clone();
        let model = user::load(path, cfg.servo.dt())?;
        out.plant.arm = user::arm_params(path, &model, cfg.plant.arm.torque_limit_nm)?;
        out.plant.tool_mass_kg = 0.0;
        out.servo.tool_mass_kg = 0.0;
        let default = SimConfig::default();
        if cfg.surface.frame.origin_m == default.surface.frame.origin_m {
            let arm = Arm::new(out.plant.arm);
            let q = arm
                .decoupled_configuration(0.0, out.plant.elbow)
                .ok_or_else(|| {
                    ConfigError::rule(
                        "world.mjcf",
                        format!("{path}: afs's operating point needs link 1 longer than link 2"),
                    )
                })?;
            let tip = arm.forward(q);
            out.surface.frame.origin_m = [tip.x, tip.y];
        }
        Ok(out)
    }
    #[cfg(not(feature = "mujoco"))]
    {
        let _ = path;
        Err(without_mujoco())
    }
}

/// The refusal of a MuJoCo world by an afs built without it.
#[cfg(not(feature = "mujoco"))]
fn without_mujoco() -> ConfigError {
    ConfigError::rule(
        "world.kind",
        "is `mujoco` but this afs was built without MuJoCo; build it with `--features mujoco` \
         after `python3 examples/python/mujoco_link.py` (README)",
    )
}

/// MuJoCo's warnings so far in this process (0 without MuJoCo): counted, never printed from
/// the fast loop nor written to MUJOCO_LOG.TXT; `afs experiment` reports them.
pub fn mujoco_warnings() -> u64 {
    #[cfg(feature = "mujoco")]
    {
        mujoco::warnings()
    }
    #[cfg(not(feature = "mujoco"))]
    {
        0
    }
}

/// The world of one set-up.
#[derive(Debug, Clone)]
pub enum World {
    /// afs's own plant.
    Builtin(Plant),
    /// MuJoCo.
    #[cfg(feature = "mujoco")]
    Mujoco(MujocoWorld),
}

impl World {
    /// The world of `cfg` with the arm at rest at `q`.
    pub fn new(cfg: &SimConfig, q: Vector2<f64>) -> Result<Self, ConfigError> {
        match cfg.world.kind {
            WorldKind::Builtin => Ok(World::Builtin(Plant::new(
                cfg.plant.clone(),
                cfg.surface.clone(),
                q,
            ))),
            #[cfg(feature = "mujoco")]
            WorldKind::Mujoco => Ok(World::Mujoco(MujocoWorld::new(cfg, q)?)),
            #[cfg(not(feature = "mujoco"))]
            WorldKind::Mujoco => Err(without_mujoco()),
        }
    }

    /// Which world this is.
    pub fn kind(&self) -> WorldKind {
        match self {
            World::Builtin(_) => WorldKind::Builtin,
            #[cfg(feature = "mujoco")]
            World::Mujoco(_) => WorldKind::Mujoco,
        }
    }

    /// The arm model (for a user's MJCF, the one read from it).
    pub fn arm(&self) -> &Arm {
        match self {
            World::Builtin(p) => p.arm(),
            #[cfg(feature = "mujoco")]
            World::Mujoco(m) => m.arm(),
        }
    }

    /// The physical parameters of the set-up.
    pub fn params(&self) -> &PlantParams {
        match self {
            World::Builtin(p) => p.params(),
            #[cfg(feature = "mujoco")]
            World::Mujoco(m) => m.params(),
        }
    }

    /// The surface.
    pub fn surface(&self) -> &Surface {
        match self {
            World::Builtin(p) => p.surface(),
            #[cfg(feature = "mujoco")]
            World::Mujoco(m) => m.surface(),
        }
    }

    /// Moves the surface (its frame; the shape stays): the next step sees it.
    pub fn set_surface(&mut self, surface: Surface) {
        match self {
            World::Builtin(p) => p.set_surface(surface),
            #[cfg(feature = "mujoco")]
            World::Mujoco(m) => m.set_surface(surface),
        }
    }

    /// Truth at the start of the last step.
    pub fn truth(&self) -> &PlantTruth {
        match self {
            World::Builtin(p) => p.truth(),
            #[cfg(feature = "mujoco")]
            World::Mujoco(m) => m.truth(),
        }
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        match self {
            World::Builtin(p) => p.time(),
            #[cfg(feature = "mujoco")]
            World::Mujoco(m) => m.time(),
        }
    }

    /// Joint angles and rates (what the encoders read).
    pub fn joints(&self) -> (Vector2<f64>, Vector2<f64>) {
        match self {
            World::Builtin(p) => p.joints(),
            #[cfg(feature = "mujoco")]
            World::Mujoco(m) => m.joints(),
        }
    }

    /// Advances the world by `dt` (s) under joint torques `tau` (N·m).
    pub fn step(&mut self, tau: Vector2<f64>, dt: f64) {
        match self {
            World::Builtin(p) => p.step(tau, dt),
            #[cfg(feature = "mujoco")]
            World::Mujoco(m) => m.step(tau),
        }
    }

    /// Snapshot of the dynamic state (what a restarted servo resumes).
    pub fn state(&self) -> WorldStateAny {
        match self {
            World::Builtin(p) => WorldStateAny::Builtin(p.state()),
            #[cfg(feature = "mujoco")]
            World::Mujoco(m) => WorldStateAny::Mujoco(m.state()),
        }
    }

    /// Restores a snapshot taken by [`World::state`] of the same kind of world.
    pub fn restore(&mut self, s: &WorldStateAny) -> Result<(), ConfigError> {
        match (self, s) {
            (World::Builtin(p), WorldStateAny::Builtin(st)) => {
                p.restore(st);
                Ok(())
            }
            #[cfg(feature = "mujoco")]
            (World::Mujoco(m), WorldStateAny::Mujoco(st)) => m.restore(st),
            (w, _) => Err(ConfigError::rule(
                "world snapshot",
                format!(
                    "was taken of another kind of world than this {} one; the world starts afresh",
                    w.kind().name()
                ),
            )),
        }
    }
}

/// A world's dynamic state, of either kind.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WorldStateAny {
    /// The built-in plant's state.
    Builtin(PlantState),
    /// MuJoCo's integration state (time, joints, warm start, mocap), `len` values used.
    Mujoco(MujocoState),
}

/// The length of MuJoCo's peg state (`mj_getState`: time, three joints, their rates, the
/// solver's warm start of three).
pub const MUJOCO_PEG_STATE_LEN: usize = 10;

/// The most values a MuJoCo state may have here (a planar arm: two joints, one mocap body).
pub const MUJOCO_STATE_LEN: usize = 32;

/// MuJoCo's state as `mj_getState` gives it (time, qpos, qvel, act, warm start, mocap pose).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MujocoState {
    /// How many of `values` are used.
    pub len: usize,
    /// The values.
    pub values: [f64; MUJOCO_STATE_LEN],
}

/// The friction law the world of `cfg` applies, at the plant's reference normal force: the
/// built-in plant's eq. 4.5; on MuJoCo its Coulomb cone alone (μ F_N, no Stribeck or viscous
/// term) unless `applied_friction` adds them. The experiments compare with this law.
pub fn friction_law(cfg: &SimConfig) -> crate::friction::FrictionLaw {
    let law = cfg.plant.friction;
    match cfg.world.kind {
        WorldKind::Mujoco if !cfg.world.mujoco.applied_friction => crate::friction::FrictionLaw {
            viscous_n_s_per_m: 0.0,
            stribeck_n: 0.0,
            ..law
        },
        _ => law,
    }
}
