//! The world of §5.4's box (fig. 5.9), chosen by the same configuration as the arm's: afs's own
//! [`BoxPlant`] or the same box in MuJoCo ([`MujocoBox`](super::MujocoBox), docs/mujoco.md).

use crate::config::SimConfig;
use crate::error::ConfigError;
use crate::multicontact::{BoxParams, BoxPlant, BoxTruth, Pose};

use super::WorldKind;

/// The box, its grip, the floor and the wall.
#[derive(Debug)]
pub enum BoxWorld {
    /// afs's own box plant, stepped every `dt` seconds.
    Builtin {
        /// The plant.
        plant: Box<BoxPlant>,
        /// Its step (s).
        dt: f64,
    },
    /// MuJoCo.
    #[cfg(feature = "mujoco")]
    Mujoco(Box<super::MujocoBox>),
}

impl BoxWorld {
    /// The box of `params` at rest at `pose` in the world `cfg` names, stepped every `dt`
    /// seconds. A user's MJCF is an arm: the box refuses it.
    pub fn new(
        cfg: &SimConfig,
        params: BoxParams,
        pose: Pose,
        dt: f64,
    ) -> Result<Self, ConfigError> {
        if cfg.world.mjcf.is_some() {
            return Err(ConfigError::rule(
                "world.mjcf",
                "is an arm model; §5.4's box has no arm (run fig5.9 with --plant mujoco instead)",
            ));
        }
        match cfg.world.kind {
            WorldKind::Builtin => Ok(BoxWorld::Builtin {
                plant: Box::new(BoxPlant::new(params, pose)),
                dt,
            }),
            #[cfg(feature = "mujoco")]
            WorldKind::Mujoco => Ok(BoxWorld::Mujoco(Box::new(super::MujocoBox::new(
                params,
                &cfg.world.mujoco,
                dt,
                pose,
            )?))),
            #[cfg(not(feature = "mujoco"))]
            WorldKind::Mujoco => Err(super::without_mujoco()),
        }
    }

    /// Advances one step with the grip commanding `target` pose and `target_vel`.
    pub fn step(&mut self, target: Pose, target_vel: [f64; 3]) {
        match self {
            BoxWorld::Builtin { plant, dt } => plant.step(target, target_vel, *dt),
            #[cfg(feature = "mujoco")]
            BoxWorld::Mujoco(b) => b.step(target, target_vel),
        }
    }

    /// Truth of the last step.
    pub fn truth(&self) -> &BoxTruth {
        match self {
            BoxWorld::Builtin { plant, .. } => plant.truth(),
            #[cfg(feature = "mujoco")]
            BoxWorld::Mujoco(b) => b.truth(),
        }
    }

    /// The box's pose.
    pub fn pose(&self) -> Pose {
        match self {
            BoxWorld::Builtin { plant, .. } => plant.pose(),
            #[cfg(feature = "mujoco")]
            BoxWorld::Mujoco(b) => b.pose(),
        }
    }
}
