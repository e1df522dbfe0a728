//! MuJoCo's dynamics of the three-joint arm that carries the insertion's wrist
//! (docs/insertion-mujoco.md, *MuJoCo's arm*): the model [`mjcf::scara`] writes, with the joints'
//! viscous damping, stepped by MuJoCo under the servo's torques and the wrist's reaction.
//!
//! With `--plant mujoco --drive arm` the arm's joints move by MuJoCo's mass matrix, bias
//! forces, damping and integrator, in step with MuJoCo's peg: each of the peg's MuJoCo steps
//! is one of the arm's, of the same length. The two are coupled by the wrist's compliance
//! (afs's wrist model, the same on both plants): its force on the peg goes into the peg's
//! model, its reaction through the flange's Jacobian into the arm's. The arm has no contact
//! geometry, so it is a model of its own; its joints and rates are its whole state (no
//! constraint to warm-start), which the drive's snapshot already carries.

use super::mjcf;
use super::mujoco::{install_log_handler, positive_time};
use super::mujoco_body::load;
use crate::arm::ArmParams;
use crate::error::ConfigError;
use crate::insertion::scara::WristParams;
use mujoco_rs::prelude::{MjData, MjModel};
use std::sync::Arc;

/// The arm in MuJoCo.
#[derive(Clone)]
pub struct MujocoArm {
    data: MjData<Arc<MjModel>>,
    step_s: f64,
}

impl std::fmt::Debug for MujocoArm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MujocoArm")
            .field("q", &self.data.qpos())
            .field("step_s", &self.step_s)
            .finish_non_exhaustive()
    }
}

impl MujocoArm {
    /// Links 1 and 2 of `arm` and the wrist link `wrist`, each joint damped by
    /// `damping_nms_per_rad`, stepped `step_s` seconds at a time; its joints at zero until
    /// [`MujocoArm::set`].
    pub fn new(
        arm: &ArmParams,
        wrist: &WristParams,
        damping_nms_per_rad: [f64; 3],
        step_s: f64,
    ) -> Result<Self, ConfigError> {
        install_log_handler();
        positive_time("MuJoCo arm's step", step_s)?;
        let model = load(&mjcf::scara(arm, wrist, damping_nms_per_rad, step_s))?;
        Ok(Self {
            data: MjData::new(Arc::new(model)),
            step_s,
        })
    }

    /// The length of one step (s).
    pub fn step_s(&self) -> f64 {
        self.step_s
    }

    /// Puts the joints at `q` (rad) moving at `v` (rad/s).
    pub fn set(&mut self, q: [f64; 3], v: [f64; 3]) {
        self.data.qpos_mut().copy_from_slice(&q);
        self.data.qvel_mut().copy_from_slice(&v);
        self.data.forward();
    }

    /// One MuJoCo step under the joint torques `torque` (N·m: the servo's and the wrist's
    /// reaction): the joints and their rates after it.
    pub fn step(&mut self, torque: [f64; 3]) -> ([f64; 3], [f64; 3]) {
        self.data.qfrc_applied_mut().copy_from_slice(&torque);
        self.data.step();
        let (q, v) = (self.data.qpos(), self.data.qvel());
        ([q[0], q[1], q[2]], [v[0], v[1], v[2]])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::insertion::scara::Scara;
    use nalgebra::Vector3;

    /// Damped joints under torques that change with time: MuJoCo's arm and the closed form
    /// (`Scara`'s M, h and the damping, integrated semi-implicitly as MuJoCo's Euler does,
    /// the damping implicitly) stay within 10⁻⁹ rad over 0.2 s, and MuJoCo's tool site is the
    /// closed form's tool point to 10⁻¹². Without the damping in the model they part by
    /// 10⁻³ rad, so the check sees it.
    #[test]
    fn mujocos_damped_arm_moves_as_the_closed_form() {
        let (arm, wrist) = (ArmParams::default(), WristParams::default());
        let damping = [0.05, 0.01, 0.005];
        let h = 1e-4;
        let s = Scara::new(arm, wrist);
        let run = |model_damping: [f64; 3]| {
            let mut mj = MujocoArm::new(&arm, &wrist, model_damping, h).unwrap();
            let (mut q, mut qd) = (Vector3::new(0.3, 1.1, -0.7), Vector3::zeros());
            mj.set(q.into(), [0.0; 3]);
            let d = nalgebra::Matrix3::from_diagonal(&Vector3::from(damping));
            for n in 0..2000 {
                let t = f64::from(n) * h;
                let tau = Vector3::new(2.0 * (5.0 * t).sin(), -1.0, 0.05 * (9.0 * t).cos());
                mj.step(tau.into());
                // MuJoCo's Euler over a step Δt: (M + Δt D) q̈ = τ − h(q, q̇) − D q̇, then q̇,
                // then q.
                let qdd = (s.mass_matrix(q) + d * h)
                    .cholesky()
                    .unwrap()
                    .solve(&(tau - s.coriolis(q, qd) - d * qd));
                qd += qdd * h;
                q += qd * h;
            }
            let end = Vector3::from_column_slice(mj.data.qpos());
            let rate: [f64; 3] = std::array::from_fn(|k| mj.data.qvel()[k]);
            // A step leaves the site where the step began; the kinematics at the end.
            mj.set(end.into(), rate);
            let (site, tool) = (mj.data.site_xpos()[0], s.forward(end));
            assert!((site[0] - tool[0]).hypot(site[1] - tool[1]) < 1e-12);
            (Vector3::from_column_slice(mj.data.qpos()) - q).norm()
        };
        let apart = run(damping);
        assert!(apart < 1e-9, "{apart} rad");
        let undamped = run([0.0; 3]);
        assert!(undamped > 1e-3, "{undamped} rad");
    }

    /// A step that is not a positive time is refused.
    #[test]
    fn a_bad_step_is_refused() {
        let (arm, wrist) = (ArmParams::default(), WristParams::default());
        for h in [0.0, -1e-4, f64::NAN] {
            assert!(MujocoArm::new(&arm, &wrist, [0.0; 3], h).is_err());
        }
    }
}
