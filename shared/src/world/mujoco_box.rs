//! §5.4's box in MuJoCo (docs/mujoco.md, *The box of §5.4*): the same box, grip, floor and
//! wall as [`BoxPlant`](crate::multicontact::BoxPlant), with MuJoCo's contacts and friction.
//!
//! The box moves in the plane on three joints (slide x, slide y, hinge θ about its centre), so
//! its generalised forces are the grip's force and its moment about the centre. Its contacts
//! are its four vertices, each a sphere of radius ρ against the floor plane at y = −ρ and the
//! wall plane at x = −ρ: the sphere's penetration is the vertex's, as in the built-in plant,
//! and each vertex is exactly one contact (a 3-D box against a plane would touch at both ends
//! of each edge, two contact springs per vertex). Contact stiffness by solref's direct form
//! ([`super::mjcf::direct_solref`]) with the box body's `body_invweight0`, friction MuJoCo's
//! elliptic cone with μ = F_C / F_ref of the box's friction law (its Stribeck term is not
//! modelled: MuJoCo has none).

use super::MujocoParams;
use super::mujoco::install_log_handler;
use super::mujoco_body::{contacts_on, with_contact_stiffness};
use crate::error::ConfigError;
use crate::math::{Vec2, cross};
use crate::multicontact::{BoxParams, BoxTruth, Pose};
use mujoco_rs::prelude::MjtObjBase as mjtObj;
use mujoco_rs::prelude::{MjData, MjModel};
use std::fmt::Write;
use std::sync::Arc;

/// Radius of the vertex spheres (m).
const VERTEX_RADIUS_M: f64 = 1e-4;

/// The box in MuJoCo.
pub struct MujocoBox {
    data: MjData<Arc<MjModel>>,
    params: BoxParams,
    body: usize,
    floor: usize,
    truth: BoxTruth,
}

impl std::fmt::Debug for MujocoBox {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MujocoBox")
            .field("pose", &self.pose())
            .finish_non_exhaustive()
    }
}

/// The box's MJCF with the contacts' solver references `solref` (normal, friction; None: a
/// stand-in, compiled once to read the box's `body_invweight0`).
fn generate(p: &BoxParams, m: &MujocoParams, dt: f64, solref: Option<[[f64; 2]; 2]>) -> String {
    let [[n0, n1], [f0, f1]] = solref.unwrap_or([[-1.0, -1.0], [-1.0, -1.0]]);
    let (a, b) = (0.5 * p.size_m[0], 0.5 * p.size_m[1]);
    let inertia = p.mass_kg * (p.size_m[0].powi(2) + p.size_m[1].powi(2)) / 12.0;
    let mu = p.friction.kinetic_n / p.reference_normal_force_n;
    let d = m.impedance;
    let r = VERTEX_RADIUS_M;
    let mut x = String::with_capacity(8 * 1024);
    // Writing to a String cannot fail.
    let _ = writeln!(
        x,
        "<mujoco model=\"afs-box\">\n  <compiler angle=\"radian\" inertiafromgeom=\"false\"/>\n  \
         <option timestep=\"{dt:e}\" gravity=\"0 0 0\" cone=\"{cone}\" impratio=\"{imp}\" \
         noslip_iterations=\"{noslip}\" integrator=\"Euler\"/>\n  <default>\n    \
         <geom contype=\"0\" conaffinity=\"0\"/>\n  </default>\n  <worldbody>\n    \
         <geom name=\"floor\" type=\"plane\" pos=\"0 {nr} 0\" zaxis=\"0 1 0\" size=\"0 0 1\"/>\n    \
         <geom name=\"wall\" type=\"plane\" pos=\"{nr} 0 0\" zaxis=\"1 0 0\" size=\"0 0 1\"/>\n    \
         <body name=\"box\">\n      <joint name=\"x\" type=\"slide\" axis=\"1 0 0\"/>\n      \
         <joint name=\"y\" type=\"slide\" axis=\"0 1 0\"/>\n      \
         <joint name=\"theta\" type=\"hinge\" axis=\"0 0 1\"/>\n      \
         <inertial pos=\"0 0 0\" mass=\"{mass}\" diaginertia=\"{inertia} {inertia} {inertia}\"/>",
        imp = m.impratio,
        cone = if m.pyramidal { "pyramidal" } else { "elliptic" },
        noslip = m.noslip_iterations,
        nr = -r,
        mass = p.mass_kg,
    );
    for (i, (vx, vy)) in [(-a, -b), (a, -b), (a, b), (-a, b)].iter().enumerate() {
        let _ = writeln!(
            x,
            "      <geom name=\"v{i}\" type=\"sphere\" size=\"{r}\" pos=\"{vx} {vy} 0\"/>"
        );
    }
    x.push_str("    </body>\n  </worldbody>\n  <contact>\n");
    for i in 0..4 {
        for surface in ["floor", "wall"] {
            let _ = writeln!(
                x,
                "    <pair geom1=\"v{i}\" geom2=\"{surface}\" condim=\"3\" \
                 friction=\"{mu} {mu} 0 0 0\" solref=\"{n0:e} {n1:e}\" \
                 solreffriction=\"{f0:e} {f1:e}\" solimp=\"{d} {d} 0.001 0.5 2\"/>"
            );
        }
    }
    x.push_str("  </contact>\n</mujoco>\n");
    x
}

impl MujocoBox {
    /// The box of `params` at rest at `pose`, stepped every `dt` seconds, with MuJoCo's
    /// contact settings `m`.
    pub fn new(
        params: BoxParams,
        m: &MujocoParams,
        dt: f64,
        pose: Pose,
    ) -> Result<Self, ConfigError> {
        install_log_handler();
        let (model, body) = with_contact_stiffness(
            |solref| generate(&params, m, dt, solref),
            "box",
            (
                params.contact_stiffness_n_per_m,
                params.contact_damping_n_s_per_m,
            ),
            m,
        )?;
        let floor = model
            .name_to_id(mjtObj::mjOBJ_GEOM, "floor")
            .ok_or_else(|| ConfigError::rule("world (MuJoCo)", "the box model has no floor"))?;
        let mut b = Self {
            data: MjData::new(Arc::new(model)),
            params,
            body,
            floor,
            truth: BoxTruth::default(),
        };
        b.data.qpos_mut()[..3].copy_from_slice(&pose);
        b.data.forward();
        b.truth = b.observe(pose);
        Ok(b)
    }

    /// Parameters.
    pub fn params(&self) -> &BoxParams {
        &self.params
    }

    /// Truth at the start of the last step.
    pub fn truth(&self) -> &BoxTruth {
        &self.truth
    }

    /// The box's pose.
    pub fn pose(&self) -> Pose {
        let q = self.data.qpos();
        [q[0], q[1], q[2]]
    }

    /// One `mj_step` with the grip (stiffness and damping of [`BoxParams`], as the built-in
    /// plant's) commanding `target` pose and `target_vel`.
    pub fn step(&mut self, target: Pose, target_vel: [f64; 3]) {
        let p = self.params;
        let pose = self.pose();
        let vel = {
            let v = self.data.qvel();
            [v[0], v[1], v[2]]
        };
        let inertia = p.mass_kg * (p.size_m[0].powi(2) + p.size_m[1].powi(2)) / 12.0;
        let mass = [p.mass_kg, p.mass_kg, inertia];
        for k in 0..3 {
            let kk = p.grip_stiffness[k];
            let c = 2.0 * p.grip_damping_ratio * (kk * mass[k]).sqrt();
            self.data.qfrc_applied_mut()[k] =
                kk * (target[k] - pose[k]) + c * (target_vel[k] - vel[k]);
        }
        self.data.step();
        self.truth = self.observe(pose);
    }

    /// The contact forces on the box at `pose` (the state the last step started from).
    fn observe(&self, pose: Pose) -> BoxTruth {
        let centre = Vec2::new(pose[0], pose[1]);
        let mut t = BoxTruth {
            pose,
            ..BoxTruth::default()
        };
        let (mut floor_pt, mut wall_pt) = (None, None);
        for c in contacts_on(&self.data, self.body) {
            t.force += c.normal + c.friction;
            t.moment += cross(c.at - centre, c.normal + c.friction);
            t.normal_resultant += c.normal;
            t.friction_resultant += c.friction;
            if c.normal_n > 0.0 {
                if c.geoms.contains(&self.floor) {
                    t.contacts[0] += 1;
                    floor_pt = Some(c.at);
                } else {
                    t.contacts[1] += 1;
                    wall_pt = Some(c.at);
                }
            }
        }
        t.rotation_centre = match (floor_pt, wall_pt) {
            (Some(a), Some(b)) if t.contacts == [1, 1] => Some(Vec2::new(a.x, b.y)),
            _ => None,
        };
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::multicontact::BoxPlant;

    /// Flat on the floor and pushed down by the grip, the box settles where the grip's force
    /// equals both bottom vertices' springs: solref's direct form gives each vertex the
    /// set-up's contact stiffness k_e (depth to 0.1 %), and the contact force is the grip's.
    #[test]
    fn each_vertex_is_a_contact_of_the_set_ups_stiffness() {
        let p = BoxParams::default();
        let b0 = 0.5 * p.size_m[1];
        let mut b = MujocoBox::new(p, &MujocoParams::default(), 1e-4, [0.2, b0, 0.0]).unwrap();
        let (kg, ke, push) = (p.grip_stiffness[1], p.contact_stiffness_n_per_m, 1e-3);
        for _ in 0..5000 {
            b.step([0.2, b0 - push, 0.0], [0.0; 3]);
        }
        let depth = b0 - b.pose()[1];
        let want = kg * push / (kg + 2.0 * ke);
        assert!(
            (depth - want).abs() < 1e-3 * want,
            "depth {depth} vs {want}"
        );
        let t = b.truth();
        assert_eq!(t.contacts, [2, 0]);
        let force = 2.0 * ke * want;
        assert!(
            (t.force.y - force).abs() < 1e-3 * force,
            "{:?} vs {force}",
            t.force
        );
        assert!(t.force.x.abs() < 1e-6 * force && t.moment.abs() < 1e-6 * force);
    }

    /// Tilted 20° and pushed into the corner, the box touches the floor with its bottom-left
    /// vertex and the wall with its top-left one, as the built-in plant: the same contacts,
    /// the true rotation centre where they are, and the grip's push carried by the contacts.
    #[test]
    fn in_the_corner_it_has_the_built_in_plants_contacts_and_centre() {
        let p = BoxParams::default();
        let theta = 20f64.to_radians();
        let touch = BoxPlant::touching_pose(&p, theta);
        let target = [touch[0] - 4e-4, touch[1] - 4e-4, theta];
        let mut b = MujocoBox::new(p, &MujocoParams::default(), 1e-4, touch).unwrap();
        let mut builtin = BoxPlant::new(p, touch);
        for _ in 0..5000 {
            b.step(target, [0.0; 3]);
            builtin.step(target, [0.0; 3], 1e-4);
        }
        let (tm, tb) = (b.truth(), builtin.truth());
        assert_eq!(tm.contacts, [1, 1]);
        let (m, r) = (tm.rotation_centre.unwrap(), tb.rotation_centre.unwrap());
        assert!((m - r).norm() < 2e-5, "{m:?} vs {r:?}");
        let grip = Vec2::new(
            p.grip_stiffness[0] * (b.pose()[0] - target[0]),
            p.grip_stiffness[1] * (b.pose()[1] - target[1]),
        );
        assert!(
            (tm.force - grip).norm() < 1e-3 * grip.norm(),
            "{:?} vs {grip:?}",
            tm.force
        );
        assert!(
            (tm.force - tb.force).norm() < 0.1 * tb.force.norm(),
            "{:?} vs {:?}",
            tm.force,
            tb.force
        );
    }
}
