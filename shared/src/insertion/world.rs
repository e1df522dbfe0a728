//! The world the insertion's peg lives in: afs's [`PegPlant`] or, with the cargo feature
//! `mujoco`, MuJoCo's ([`MujocoPeg`](crate::world::MujocoPeg), docs/insertion-mujoco.md),
//! chosen by the set-up's `[world] kind` (`afs experiment insertion --plant mujoco`).

use super::plant::{Commanded, Flange, PegParams, PegPlant, PegPlantState, PegTruth};
use crate::error::ConfigError;
use crate::world::{WorldConfig, WorldKind};

/// The peg's world. The built-in plant stays inline (the servo's fast loop steps it); MuJoCo's
/// is boxed, being only a handle and its buffers.
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)]
pub enum PegWorld {
    /// afs's own plant (docs/insertion.md, *The plant*).
    Builtin(PegPlant),
    /// MuJoCo's contacts and friction on the same peg, wrist and part.
    #[cfg(feature = "mujoco")]
    Mujoco(Box<crate::world::MujocoPeg>),
}

impl PegWorld {
    /// The peg of `params` at rest with its tip at `tip_pose` in the world `world` names,
    /// stepped every `dt` seconds.
    pub fn new(
        params: PegParams,
        tip_pose: [f64; 3],
        world: &WorldConfig,
        dt: f64,
    ) -> Result<Self, ConfigError> {
        match (world.kind, &world.mjcf) {
            (WorldKind::Builtin, _) => Ok(Self::Builtin(PegPlant::new(params, tip_pose))),
            (WorldKind::Mujoco, Some(path)) => Err(ConfigError::rule(
                "world.mjcf",
                format!(
                    "is {path}: the insertion runs on afs's generated peg and hole, not on a \
                     model of your own; leave --mjcf out"
                ),
            )),
            #[cfg(feature = "mujoco")]
            (WorldKind::Mujoco, None) => Ok(Self::Mujoco(Box::new(crate::world::MujocoPeg::new(
                params,
                &world.mujoco,
                tip_pose,
                dt,
            )?))),
            #[cfg(not(feature = "mujoco"))]
            (WorldKind::Mujoco, None) => {
                let _ = dt;
                Err(ConfigError::rule(
                    "world.kind",
                    "is `mujoco` but this afs was built without MuJoCo; build it with \
                     `--features mujoco` after `python3 examples/python/mujoco_link.py` (README)",
                ))
            }
        }
    }

    /// Which world this is.
    pub fn kind(&self) -> WorldKind {
        match self {
            Self::Builtin(_) => WorldKind::Builtin,
            #[cfg(feature = "mujoco")]
            Self::Mujoco(_) => WorldKind::Mujoco,
        }
    }

    /// Truth of the last step.
    pub fn truth(&self) -> &PegTruth {
        match self {
            Self::Builtin(p) => p.truth(),
            #[cfg(feature = "mujoco")]
            Self::Mujoco(p) => p.truth(),
        }
    }

    /// Advances by `dt` with the wrist commanding the tip to `target` at `target_vel`.
    pub fn step(&mut self, target: [f64; 3], target_vel: [f64; 3], dt: f64) {
        self.step_with(&mut Commanded(target, target_vel), dt);
    }

    /// Advances by `dt` with the wrist's flange `flange`.
    pub fn step_with<F: Flange>(&mut self, flange: &mut F, dt: f64) {
        match self {
            Self::Builtin(p) => p.step_with(flange, dt),
            #[cfg(feature = "mujoco")]
            Self::Mujoco(p) => p.step_with(flange, dt),
        }
    }

    /// The built-in plant's whole state (a restarted servo resumes it); MuJoCo's peg runs in
    /// the lockstep experiment only, never in a servo that restarts: its truth alone.
    pub fn state(&self) -> PegPlantState {
        match self {
            Self::Builtin(p) => p.state(),
            #[cfg(feature = "mujoco")]
            Self::Mujoco(p) => PegPlantState {
                truth: *p.truth(),
                ..PegPlantState::default()
            },
        }
    }

    /// Carries the built-in plant on from `s`; refused (false) on MuJoCo's peg, whose state
    /// [`PegWorld::state`] does not hold.
    #[must_use]
    pub fn restore(&mut self, s: &PegPlantState) -> bool {
        match self {
            Self::Builtin(p) => {
                p.restore(s);
                true
            }
            #[cfg(feature = "mujoco")]
            Self::Mujoco(_) => false,
        }
    }
}
