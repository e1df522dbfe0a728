//! A user's own MJCF arm (`world.mjcf`, `--mjcf FILE`; docs/mujoco.md, *Your own arm*): what
//! afs requires of it, and the arm model the servo reads from it instead of `ArmParams`.
//!
//! Required: exactly two hinge joints (two degrees of freedom) about +z, joint 1 at the world
//! origin, at `qpos = 0` link 1 along +x and link 2 along link 1 (the thesis's joint angles);
//! a site `tool` at the tool tip, on link 2's line; a mocap body `surface` whose frame afs
//! places at the set-up's surface (its x axis the surface's tangent, its y axis the outward
//! normal), holding the face the tool touches. Anything missing is named in the refusal.

use crate::arm::ArmParams;
use crate::error::ConfigError;
use mujoco_rs::prelude::MjtObjBase as Obj;
use mujoco_rs::prelude::{MjData, MjModel, MjtJoint};

fn refuse(path: &str, why: impl std::fmt::Display) -> ConfigError {
    ConfigError::rule(
        "world.mjcf",
        format!("{path}: {why} (docs/mujoco.md, *Your own arm*)"),
    )
}

/// The user's model, checked, with its timestep set to the servo period.
pub(super) fn load(path: &str, dt: f64) -> Result<MjModel, ConfigError> {
    let mut model =
        MjModel::from_xml(path).map_err(|e| refuse(path, format!("not loaded: {e}")))?;
    model.opt_mut().timestep = dt;
    let hinges = model
        .jnt_type()
        .iter()
        .filter(|t| **t == MjtJoint::mjJNT_HINGE)
        .count();
    if model.jnt_type().len() != 2 || hinges != 2 {
        return Err(refuse(
            path,
            format!(
                "has {} joints ({hinges} hinges); afs needs exactly two hinge joints",
                model.jnt_type().len()
            ),
        ));
    }
    for (j, axis) in model.jnt_axis().iter().enumerate() {
        if (axis[2] - 1.0).abs() > 1e-9 {
            return Err(refuse(
                path,
                format!(
                    "joint {} turns about {axis:?}; afs needs +z (a planar arm)",
                    j + 1
                ),
            ));
        }
    }
    if let Some(a) = model.dof_armature().iter().find(|a| **a != 0.0) {
        return Err(refuse(
            path,
            format!(
                "has joint armature {a}; the two-link model cannot hold it (it adds to M's \
                 diagonal only): fold the rotor into the link's inertia"
            ),
        ));
    }
    if model.name_to_id(Obj::mjOBJ_SITE, "tool").is_none() {
        return Err(refuse(path, "has no site named `tool`"));
    }
    match model.name_to_id(Obj::mjOBJ_BODY, "surface") {
        None => return Err(refuse(path, "has no body named `surface`")),
        Some(b) if model.body_mocapid()[b] < 0 => {
            return Err(refuse(
                path,
                "its body `surface` is not a mocap body; add mocap=\"true\"",
            ));
        }
        Some(_) => {}
    }
    Ok(model)
}

/// The arm parameters that reproduce the model's kinematics (link lengths from the joint
/// anchors and the tool site) and its mass matrix M(q) = [[I₁ + m₂ l₁² + I₂ + 2β cos q₂,
/// I₂ + β cos q₂], [·, I₂]] (docs/model.md): I₂ = M₂₂, β = M₁₂(0) − I₂, I₁ from M₁₁(π/2), the
/// mass of link 2 and what it carries from the model, joint damping from the model.
/// `torque_limit_nm` stays the set-up's.
pub(super) fn arm_params(
    path: &str,
    model: &MjModel,
    torque_limit_nm: [f64; 2],
) -> Result<ArmParams, ConfigError> {
    let mut data = MjData::new(model);
    data.forward();
    let anchors = data.xanchor();
    let site = data.site_xpos()[model.name_to_id(Obj::mjOBJ_SITE, "tool").unwrap_or(0)];
    let (a1, a2) = (anchors[0], anchors[1]);
    if a1[0].hypot(a1[1]) > 1e-9 {
        return Err(refuse(
            path,
            format!("joint 1 is at {a1:?}; afs needs it at the origin"),
        ));
    }
    let l1 = (a2[0] - a1[0]).hypot(a2[1] - a1[1]);
    let l2 = (site[0] - a2[0]).hypot(site[1] - a2[1]);
    let bent = |a: &[f64; 3], b: &[f64; 3]| (b[1] - a[1]).abs() > 1e-6 * (1.0 + l1 + l2);
    if bent(&a1, &a2) || bent(&a2, &site) || a2[0] <= a1[0] || site[0] <= a2[0] {
        return Err(refuse(
            path,
            "at qpos = 0 link 1 must lie along +x and link 2 (joint 2 to the site `tool`) along it",
        ));
    }
    let m = |data: &mut MjData<&MjModel>, q2: f64| -> [f64; 4] {
        data.qpos_mut()[0] = 0.0;
        data.qpos_mut()[1] = q2;
        data.forward();
        let mut full = [0.0; 4];
        let _ = data.full_m(&mut full);
        full
    };
    let straight = m(&mut data, 0.0);
    let bent_m = m(&mut data, std::f64::consts::FRAC_PI_2);
    let i2 = straight[3];
    let beta = straight[1] - i2;
    let link2_body = model.jnt_bodyid()[1] as usize;
    let m2 = model.body_subtreemass()[link2_body];
    let i1 = bent_m[0] - i2 - m2 * l1 * l1;
    if !(m2 > 0.0 && beta > 0.0 && i1 > 0.0 && i2 > 0.0) {
        return Err(refuse(
            path,
            format!(
                "its mass matrix gives I1 = {i1}, I2 = {i2}, β = {beta}, m2 = {m2}: link 2 needs mass beyond joint 2"
            ),
        ));
    }
    let c2 = beta / (l1 * m2);
    let damping = model.dof_damping();
    Ok(ArmParams {
        link1_length_m: l1,
        link2_length_m: l2,
        link1_mass_kg: 0.0,
        link1_com_m: 0.0,
        link1_inertia_kg_m2: i1,
        rotor1_inertia_kg_m2: 0.0,
        elbow_mass_kg: 0.0,
        link2_mass_kg: m2,
        link2_com_m: c2,
        link2_inertia_kg_m2: (i2 - m2 * c2 * c2).max(0.0),
        rotor2_inertia_kg_m2: 0.0,
        tip_mass_kg: 0.0,
        joint_damping_nms_per_rad: [damping[0], damping[1]],
        torque_limit_nm,
    })
}
