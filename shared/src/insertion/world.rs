//! The world the insertion's peg lives in: afs's [`PegPlant`] or, with the cargo feature
//! `mujoco`, MuJoCo's ([`MujocoPeg`](crate::world::MujocoPeg), docs/insertion-mujoco.md),
//! chosen by the set-up's `[world] kind` (`afs experiment insertion --plant mujoco`).

use super::plant::{Commanded, Flange, PegParams, PegPlant, PegPlantState, PegTruth};
use crate::config::{WorldConfig, WorldKind};
use crate::error::ConfigError;
pub use crate::world::MUJOCO_PEG_STATE_LEN;

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

    /// The length of one of the world's steps when the servo's period is `dt` (s): MuJoCo
    /// steps several times a period; None on the built-in plant, which steps itself.
    pub fn mujoco_step_s(&self, dt: f64) -> Option<f64> {
        match self {
            Self::Builtin(_) => {
                let _ = dt;
                None
            }
            #[cfg(feature = "mujoco")]
            Self::Mujoco(p) => Some(dt / p.substeps() as f64),
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

    /// The built-in plant's whole state, or on MuJoCo's peg its truth alone with MuJoCo's
    /// state beside it ([`PegWorld::mujoco_state`]).
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

    /// MuJoCo's state of its peg (None on the built-in plant).
    pub fn mujoco_state(&self) -> Option<[f64; MUJOCO_PEG_STATE_LEN]> {
        match self {
            Self::Builtin(_) => None,
            #[cfg(feature = "mujoco")]
            Self::Mujoco(p) => Some(p.state()),
        }
    }

    /// Carries on from `s` and, on MuJoCo's peg, MuJoCo's state `mujoco` (both taken from a
    /// world of the same kind and parameters). A state of the other world's kind is refused.
    pub fn restore(
        &mut self,
        s: &PegPlantState,
        mujoco: Option<&[f64; MUJOCO_PEG_STATE_LEN]>,
    ) -> Result<(), ConfigError> {
        match (self, mujoco) {
            (Self::Builtin(p), None) => {
                p.restore(s);
                Ok(())
            }
            #[cfg(feature = "mujoco")]
            (Self::Mujoco(p), Some(m)) => p.restore(m, &s.truth),
            (w, _) => Err(ConfigError::rule(
                "world snapshot",
                format!(
                    "holds the insertion on another world than this servo's ({}); restart \
                     the stack with the set-up the snapshot was taken with",
                    w.kind().name()
                ),
            )),
        }
    }
}
