//! What the MuJoCo worlds share about the one body whose contacts they read (the box, the
//! peg, the arm's tool): its model compiled with the set-up's contact stiffness, and the
//! contact forces on it.

use super::MujocoParams;
use super::mjcf::contact_solrefs;
use crate::error::ConfigError;
use crate::math::Vec2;
use mujoco_rs::prelude::MjtObjBase as mjtObj;
use mujoco_rs::prelude::{MjData, MjModel};
use std::sync::Arc;

/// MuJoCo's model of the MJCF text `xml`, or why it did not load.
pub(super) fn load(xml: &str) -> Result<MjModel, ConfigError> {
    MjModel::from_xml_string(xml)
        .map_err(|e| ConfigError::rule("world (MuJoCo)", format!("the model did not load: {e}")))
}

/// The model `generate` writes, with solver references (normal, friction) that give each
/// contact of the body `name` the stiffness (N/m) and damping (N·s/m) asked for: compiled once
/// with MuJoCo's default references to read the body's `body_invweight0`
/// ([`contact_solrefs`]), then with them. Returns the model and the body's id.
pub(super) fn with_contact_stiffness(
    generate: impl Fn(Option<[[f64; 2]; 2]>) -> String,
    name: &str,
    (stiffness, damping): (f64, f64),
    m: &MujocoParams,
) -> Result<(MjModel, usize), ConfigError> {
    let probe = load(&generate(None))?;
    let body = probe.name_to_id(mjtObj::mjOBJ_BODY, name).ok_or_else(|| {
        ConfigError::rule("world (MuJoCo)", format!("the {name} model has no {name}"))
    })?;
    let solref = contact_solrefs(stiffness, damping, m, probe.body_invweight0()[body][0]);
    Ok((load(&generate(Some(solref)))?, body))
}

/// One of MuJoCo's contacts on a body, in the plane (world x-y).
#[derive(Debug, Clone, Copy)]
pub(super) struct BodyContact {
    /// The contact's two geoms.
    pub geoms: [usize; 2],
    /// Where it is (m).
    pub at: Vec2,
    /// The normal force on the body (N).
    pub normal: Vec2,
    /// The friction force on the body (N).
    pub friction: Vec2,
    /// The normal force's magnitude (N).
    pub normal_n: f64,
    /// The penetration (m; negative apart).
    pub depth_m: f64,
}

/// MuJoCo's contacts on `body` after the last step, each with its force on that body. A
/// contact's force is geom 1's on geom 2 in the contact frame (normal from geom 1 to geom 2),
/// so it changes sign when the body is geom 1's. Allocates nothing.
pub(super) fn contacts_on(
    data: &MjData<Arc<MjModel>>,
    body: usize,
) -> impl Iterator<Item = BodyContact> + '_ {
    let bodies = data.model().geom_bodyid();
    data.contact().iter().enumerate().filter_map(move |(i, c)| {
        let geoms = [c.geom1 as usize, c.geom2 as usize];
        let sign = if bodies[geoms[0]] as usize == body {
            -1.0
        } else if bodies[geoms[1]] as usize == body {
            1.0
        } else {
            return None;
        };
        let f = data.contact_force(i);
        let fr = &c.frame;
        let row = |k: usize| Vec2::new(fr[3 * k], fr[3 * k + 1]) * sign;
        Some(BodyContact {
            geoms,
            at: Vec2::new(c.pos[0], c.pos[1]),
            normal: row(0) * f[0],
            friction: row(1) * f[1] + row(2) * f[2],
            normal_n: f[0],
            depth_m: -c.dist,
        })
    })
}
