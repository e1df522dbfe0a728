//! Set-ups the scenarios and the experiments share: the corner profile and the rigs.

use crate::config::SimConfig;
use serde::{Deserialize, Serialize};

/// The corner profile: faces of 20 mm at 0°, +10°, −5°, +15°, +5° (turns +10°, −15°, +20°,
/// −10°), centred on the arm's operating point.
pub(crate) fn corner_profile() -> Vec<[f64; 2]> {
    let slopes_deg = [0.0f64, 10.0, -5.0, 15.0, 5.0];
    let mut v = vec![[-0.05, 0.0]];
    for s in slopes_deg {
        let [u, h] = *v.last().unwrap_or(&[0.0, 0.0]);
        v.push([u + 0.02, h + 0.02 * s.to_radians().tan()]);
    }
    v
}

/// Puts `cfg` on the level corner profile at its surface origin, starting 2 mm past the first
/// vertex; returns the vertices and where runs end (2 mm before the last vertex).
pub(crate) fn on_corner_profile(cfg: &mut SimConfig) -> (Vec<[f64; 2]>, f64) {
    let vertices = corner_profile();
    cfg.surface = crate::surface::Surface {
        frame: crate::surface::SurfaceFrame {
            origin_m: cfg.surface.frame.origin_m,
            angle_rad: 0.0,
        },
        shape: crate::surface::Shape::Polyline {
            vertices: vertices.clone(),
        },
    };
    cfg.start_u_m = vertices[0][0] + 0.002;
    let end = vertices[vertices.len() - 1][0] - 0.002;
    (vertices, end)
}

/// The rig an experiment runs on.
///
/// `Afs` is the default set-up ([`SimConfig::default`]): the arm at its decoupled operating
/// point with inverse-dynamics and preload feedforward. `Thesis` is the thesis's own rig as far
/// as the thesis describes it: PID joint servos only (§3.3: the set-point goes "through the
/// inverse kinematics and PID controller"), no feedforward of any kind, and the tool at a
/// generic, coupled point of the workspace instead of the decoupled one (docs/model.md,
/// *The thesis's rig*).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Rig {
    /// afs's rig.
    #[default]
    Afs,
    /// The thesis's rig.
    Thesis,
}

/// Distance of the thesis rig's contact point from the base (m): half-way between the
/// decoupled point (0.4 m) and full reach (0.8 m) is 0.6 m; 0.5 m keeps the elbow well bent.
pub const THESIS_RIG_REACH_M: f64 = 0.5;

impl Rig {
    /// Both rigs, afs's first.
    pub const ALL: [Rig; 2] = [Rig::Afs, Rig::Thesis];

    /// The rig's name as the command line spells it.
    pub fn name(self) -> &'static str {
        match self {
            Rig::Afs => "afs",
            Rig::Thesis => "thesis",
        }
    }

    /// Parses a name given on the command line.
    pub fn parse(s: &str) -> Option<Rig> {
        Rig::ALL.into_iter().find(|r| r.name() == s)
    }

    /// Applies the rig to `cfg` (whose surface shape, seed and other settings are kept). The
    /// thesis rig turns both feedforwards and the added contact damping off and moves the surface's origin to the point
    /// [`THESIS_RIG_REACH_M`] from the base on the arm's X axis, turned so that link 2 still
    /// points into the surface along its normal (the thesis's task frame, fig. 3.3); there
    /// `M12 ≠ 0` and a motion along the normal needs both joints.
    pub fn apply(self, cfg: &mut SimConfig) -> Result<(), crate::error::ConfigError> {
        if self == Rig::Afs {
            return Ok(());
        }
        cfg.servo.inertia_feedforward = false;
        cfg.servo.preload_feedforward = false;
        cfg.servo.contact_damping_ratio = 0.0;
        // The thesis bounds the dither by the actuators only and stepped it by 5 mm (fig. 4.7):
        // allow 6 mm, with the contact bound for a tangent known to 1.5° (7.6 mm at the
        // default preload and stiffness).
        cfg.servo.dither.max_amplitude_m = 6e-3;
        cfg.servo.dither.tangent_uncertainty_deg = 1.5;
        let arm = crate::arm::Arm::new(cfg.plant.arm);
        let elbow = cfg.plant.elbow;
        let decoupled = arm.decoupled_configuration(0.0, elbow).ok_or_else(|| {
            crate::error::ConfigError::rule(
                "plant.arm",
                "the thesis rig needs link 1 longer than link 2",
            )
        })?;
        let q = arm
            .inverse(crate::math::Vec2::new(THESIS_RIG_REACH_M, 0.0), elbow)
            .map_err(|e| {
                crate::error::ConfigError::rule("plant.arm", format!("thesis rig point: {e}"))
            })?;
        // The default surface is level under the decoupled point with link 2 along its normal;
        // turn it with link 2.
        let turn = arm.link2_angle(q) - arm.link2_angle(decoupled);
        let tip = arm.forward(q);
        cfg.surface.frame.origin_m = [tip.x, tip.y];
        cfg.surface.frame.angle_rad += turn;
        Ok(())
    }
}

/// The servo rates of real arms afs is measured at: the thesis's direct-drive rig, Franka's
/// FCI and Universal Robots' e-Series (Hz).
pub const ROBOT_RATES_HZ: [f64; 3] = [10_000.0, 1_000.0, 500.0];

/// Sets the servo rate. The dither (10 Hz), the joint bandwidths (3 and 15 Hz) and the
/// tangent strokes (1 Hz) sit well below the Nyquist frequency of every rate in
/// [`ROBOT_RATES_HZ`], so they stay; [`crate::servo::ServoParams::validate`] refuses a rate
/// they do not fit (docs/mujoco.md, *Rates*).
pub fn set_rate(cfg: &mut SimConfig, rate_hz: f64) -> Result<(), crate::error::ConfigError> {
    cfg.servo.rate_hz = rate_hz;
    cfg.servo.validate()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arm::Arm;
    use crate::math::{perp, unit};

    /// Inertia coupling and the task-frame Jacobian at a rig's contact point, with link 2's
    /// angle to the surface normal.
    fn coupling(rig: Rig) -> (f64, f64, f64) {
        let mut cfg = SimConfig::default();
        rig.apply(&mut cfg).unwrap();
        let arm = Arm::new(cfg.plant.arm);
        let q = cfg.start_configuration().unwrap();
        let m = arm.mass_matrix(q);
        let angle = cfg.surface.tangent_angle_at(cfg.start_u_m);
        let n = perp(unit(angle));
        let j = arm.jacobian(q);
        // Joint 2's share of a normal motion: J⁻¹ n, relative to joint 1's. (A tangential
        // motion is joint 2 alone on both rigs: link 2 is along the normal.)
        let dq = j.try_inverse().unwrap() * nalgebra::Vector2::new(n.x, n.y);
        let link2 = unit(arm.link2_angle(q));
        (
            m[(0, 1)] / m[(1, 1)],
            dq[1].abs() / dq[0].abs(),
            link2.x * n.y - link2.y * n.x,
        )
    }

    /// afs's rig is decoupled (M12 = 0, the normal is joint 1 alone); the thesis's rig is not,
    /// and on both link 2 (the sensor's x axis) points along the surface normal.
    #[test]
    fn thesis_rig_is_coupled_and_keeps_the_task_frame() {
        let (m12, share, cross) = coupling(Rig::Afs);
        assert!(
            m12.abs() < 1e-3 && share < 1e-3 && cross.abs() < 1e-3,
            "{m12} {share} {cross}"
        );
        let (m12, share, cross) = coupling(Rig::Thesis);
        assert!(
            m12.abs() > 0.3 && share > 0.3 && cross.abs() < 1e-3,
            "{m12} {share} {cross}"
        );
        let mut cfg = SimConfig::default();
        Rig::Thesis.apply(&mut cfg).unwrap();
        assert!(!cfg.servo.inertia_feedforward && !cfg.servo.preload_feedforward);
        assert_eq!(Rig::parse("thesis"), Some(Rig::Thesis));
        assert_eq!(Rig::parse("nope"), None);
    }
}
