//! The peg and the hole in MuJoCo (docs/insertion-mujoco.md): the built-in plant's peg, wrist
//! and part ([`PegPlant`](crate::insertion::plant::PegPlant)), with MuJoCo's contacts and
//! friction in place of afs's penalty springs and eq. 4.5.
//!
//! The peg moves in the plane on three joints (slide x, slide y, hinge θ about its centre of
//! mass), so its generalised forces are the wrist's force and its moment about the centre of
//! mass. Its contacts are the built-in plant's vertex–edge pairs: each of the peg's four
//! corners is a sphere of radius ρ against the part's solids (left and right of the hole, each
//! a convex prism whose faces sit ρ inside the part's, and the bottom), and each of the part's
//! convex corners a sphere of radius ρ against the peg (a box ρ inside its sides). A sphere's
//! penetration is its vertex's, and each pair is one contact. Stiffness and damping by
//! solref's direct form with the peg's `body_invweight0` (docs/mujoco.md), friction MuJoCo's
//! elliptic cone with μ of the peg's friction law: no presliding, no Stribeck term.
//!
//! The truth's contact state is afs's classification ([`truth_at`]) of the part's features at
//! MuJoCo's pose, with MuJoCo's normal force at each vertex.

use super::MUJOCO_PEG_STATE_LEN;
use super::MujocoParams;
use super::mujoco::{install_log_handler, positive_time};
use super::mujoco_body::{contacts_on, with_contact_stiffness};
use crate::error::ConfigError;
use crate::insertion::geometry::{Contact, Profile, contacts, peg_axes};
use crate::insertion::plant::{
    Flange, PegParams, PegTruth, SLOTS, stiffest_contact_mode, tip_of, truth_at, wrist_wrench,
};
use crate::math::{Vec2, cross};
use mujoco_rs::mujoco_c::mjtState;
use mujoco_rs::prelude::MjtObjBase as mjtObj;
use mujoco_rs::prelude::{MjData, MjModel};
use std::fmt::Write;
use std::sync::Arc;

/// Radius of the vertex spheres (m): above a contact's penetration (3 µm at the 15-N force
/// limit), so that a sphere's centre stays outside the solid it touches and MuJoCo's distance
/// is exact, and small against the clearance: the part's edges are rounded by it under the
/// peg's corners (50 µm dropped pegs into a 100-µm clearance: docs/insertion-mujoco.md).
const VERTEX_RADIUS_M: f64 = 1e-5;
/// Half the thickness of every geom out of the plane (m).
const HALF_THICKNESS_M: f64 = 5e-3;
/// How far the part's solids reach below the hole's bottom (m).
const BELOW_M: f64 = 5e-3;
/// The largest ω·h of the stiffest contact mode in a MuJoCo step (the built-in plant's 0.2).
const OMEGA_H: f64 = 0.2;
/// What a restarted servo needs to resume the peg exactly (`mj_getState`): time, the three
/// joints and their rates, and the constraint solver's warm start.
const STATE_SPEC: u32 = mjtState::mjSTATE_TIME as u32
    | mjtState::mjSTATE_QPOS as u32
    | mjtState::mjSTATE_QVEL as u32
    | mjtState::mjSTATE_WARMSTART as u32;

/// The peg, its wrist and the part, in MuJoCo.
#[derive(Clone)]
pub struct MujocoPeg {
    data: MjData<Arc<MjModel>>,
    params: PegParams,
    profile: Profile,
    body: usize,
    /// Each geom's vertex slot (0–3 the peg's corners, 4.. the part's), None for the solids.
    slot_of_geom: Vec<Option<usize>>,
    /// MuJoCo steps per call of `dt`.
    substeps: usize,
    dt: f64,
    truth: PegTruth,
}

impl std::fmt::Debug for MujocoPeg {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MujocoPeg")
            .field("tip_pose", &self.tip_pose())
            .finish_non_exhaustive()
    }
}

/// The vertices of a convex polygon (counter-clockwise) moved `r` inwards: each edge's line
/// shifted by `r` along its inward normal, the vertex where two shifted lines meet.
fn inset(poly: &[Vec2], r: f64) -> Vec<Vec2> {
    let n = poly.len();
    let inward = |a: Vec2, b: Vec2| {
        let d = (b - a).normalize();
        Vec2::new(-d.y, d.x)
    };
    (0..n)
        .map(|i| {
            let (prev, here, next) = (poly[(i + n - 1) % n], poly[i], poly[(i + 1) % n]);
            let (n1, n2) = (inward(prev, here), inward(here, next));
            here + (n1 + n2) * (r / (1.0 + n1.dot(&n2)))
        })
        .collect()
}

/// The part's two solids beside the hole, counter-clockwise, each from its face down its
/// wall to `BELOW_M` under the hole's bottom (the chamfer a cut corner: both stay convex).
fn solids(profile: &Profile) -> [Vec<Vec2>; 2] {
    let v = &profile.vertices[..=profile.segments];
    let floor = v.iter().map(|p| p.y).fold(0.0, f64::min);
    let below = floor - BELOW_M;
    // The left wall's foot; the right wall's is the next vertex.
    let foot = v.iter().position(|p| p.y == floor).unwrap_or(1);
    let last = profile.segments;
    let mut left = vec![Vec2::new(v[0].x, below), Vec2::new(v[foot].x, below)];
    left.extend(v[..foot].iter().rev());
    let mut right = vec![Vec2::new(v[foot + 1].x, below), Vec2::new(v[last].x, below)];
    right.extend(v[foot + 2..=last].iter().rev());
    [left, right]
}

/// The model's XML with the contacts' solver references `solref` (normal, friction; None: a
/// stand-in, compiled once to read the peg's `body_invweight0`), a MuJoCo step of `h` seconds.
fn generate(p: &PegParams, m: &MujocoParams, h: f64, solref: Option<[[f64; 2]; 2]>) -> String {
    let [[n0, n1], [f0, f1]] = solref.unwrap_or([[-1.0, -1.0], [-1.0, -1.0]]);
    let g = &p.geometry;
    let profile = g.profile();
    let (r, z, d) = (VERTEX_RADIUS_M, HALF_THICKNESS_M, m.impedance);
    let mu = p.mu();
    let mut x = String::with_capacity(8 * 1024);
    // Writing to a String cannot fail.
    let _ = writeln!(
        x,
        "<mujoco model=\"afs-peg\">\n  <compiler angle=\"radian\" inertiafromgeom=\"false\"/>\n  \
         <option timestep=\"{h:e}\" gravity=\"0 0 0\" cone=\"{cone}\" impratio=\"{imp}\" \
         noslip_iterations=\"{noslip}\" integrator=\"Euler\"/>\n  <default>\n    \
         <geom contype=\"0\" conaffinity=\"0\"/>\n  </default>\n  <asset>",
        imp = m.impratio,
        cone = if m.pyramidal { "pyramidal" } else { "elliptic" },
        noslip = m.noslip_iterations,
    );
    for (name, solid) in ["left", "right"].iter().zip(solids(&profile)) {
        let mut vertex = String::new();
        for v in inset(&solid, r) {
            let _ = write!(
                vertex,
                "{:e} {:e} {z:e} {:e} {:e} {:e} ",
                v.x, v.y, v.x, v.y, -z
            );
        }
        let _ = writeln!(
            x,
            "    <mesh name=\"{name}\" vertex=\"{}\"/>",
            vertex.trim_end()
        );
    }
    let v = &profile.vertices[..=profile.segments];
    let floor = v.iter().map(|p| p.y).fold(0.0, f64::min);
    let half_hole = 0.5 * g.hole_width_m();
    let _ = writeln!(
        x,
        "  </asset>\n  <worldbody>\n    <geom name=\"left\" type=\"mesh\" mesh=\"left\"/>\n    \
         <geom name=\"right\" type=\"mesh\" mesh=\"right\"/>\n    \
         <geom name=\"bottom\" type=\"box\" size=\"{hx:e} {hy:e} {z:e}\" pos=\"0 {cy:e} 0\"/>",
        hx = half_hole + BELOW_M,
        hy = 0.5 * BELOW_M,
        cy = floor - r - 0.5 * BELOW_M,
    );
    for k in 0..profile.corner_count {
        let c = profile.corners[k];
        let _ = writeln!(
            x,
            "    <geom name=\"k{k}\" type=\"sphere\" size=\"{r:e}\" pos=\"{:e} {:e} 0\"/>",
            c.x, c.y
        );
    }
    // The peg's body: its origin the centre of mass, the tip `com_above_tip_m` below it.
    let (c, half_w, len) = (p.com_above_tip_m, 0.5 * g.peg_width_m, g.peg_length_m);
    let _ = writeln!(
        x,
        "    <body name=\"peg\">\n      <joint name=\"x\" type=\"slide\" axis=\"1 0 0\"/>\n      \
         <joint name=\"y\" type=\"slide\" axis=\"0 1 0\"/>\n      \
         <joint name=\"theta\" type=\"hinge\" axis=\"0 0 1\"/>\n      \
         <inertial pos=\"0 0 0\" mass=\"{mass}\" diaginertia=\"{i} {i} {i}\"/>\n      \
         <geom name=\"body\" type=\"box\" size=\"{bx:e} {by:e} {z:e}\" pos=\"0 {bc:e} 0\"/>",
        mass = p.mass_kg,
        i = p.inertia_kg_m2,
        bx = half_w - r,
        by = 0.5 * len - r,
        bc = 0.5 * len - c,
    );
    for (i, (vx, vy)) in [
        (-half_w, -c),
        (half_w, -c),
        (half_w, len - c),
        (-half_w, len - c),
    ]
    .iter()
    .enumerate()
    {
        let _ = writeln!(
            x,
            "      <geom name=\"c{i}\" type=\"sphere\" size=\"{r:e}\" pos=\"{vx:e} {vy:e} 0\"/>"
        );
    }
    x.push_str("    </body>\n  </worldbody>\n  <contact>\n");
    let pair = |x: &mut String, a: &str, b: &str| {
        let _ = writeln!(
            x,
            "    <pair geom1=\"{a}\" geom2=\"{b}\" condim=\"3\" friction=\"{mu} {mu} 0 0 0\" \
             solref=\"{n0:e} {n1:e}\" solreffriction=\"{f0:e} {f1:e}\" \
             solimp=\"{d} {d} 0.001 0.5 2\"/>"
        );
    };
    for i in 0..4 {
        for solid in ["left", "right", "bottom"] {
            pair(&mut x, &format!("c{i}"), solid);
        }
    }
    for k in 0..profile.corner_count {
        pair(&mut x, &format!("k{k}"), "body");
    }
    x.push_str("  </contact>\n</mujoco>\n");
    x
}

impl MujocoPeg {
    /// The peg of `params` at rest with its tip at `tip_pose`, stepped `dt` seconds a call
    /// (in MuJoCo steps short enough for the stiffest contact mode), with MuJoCo's contact
    /// settings `m`.
    pub fn new(
        params: PegParams,
        m: &MujocoParams,
        tip_pose: [f64; 3],
        dt: f64,
    ) -> Result<Self, ConfigError> {
        install_log_handler();
        positive_time("servo period (MuJoCo peg)", dt)?;
        let g = &params.geometry;
        let omega = stiffest_contact_mode(&params);
        let substeps = (dt * omega / OMEGA_H).ceil().max(1.0) as usize;
        let h = dt / substeps as f64;
        let (model, body) = with_contact_stiffness(
            |solref| generate(&params, m, h, solref),
            "peg",
            (
                params.contact_stiffness_n_per_m,
                params.contact_damping_n_s_per_m,
            ),
            m,
        )?;
        let profile = g.profile();
        let mut slot_of_geom = vec![None; model.ffi().ngeom as usize];
        let names = (0..4)
            .map(|i| (format!("c{i}"), i))
            .chain((0..profile.corner_count).map(|k| (format!("k{k}"), 4 + k)));
        for (name, slot) in names {
            let id = model.name_to_id(mjtObj::mjOBJ_GEOM, &name).ok_or_else(|| {
                ConfigError::rule("world (MuJoCo)", format!("the peg model has no {name}"))
            })?;
            slot_of_geom[id] = Some(slot);
        }
        let (axis, _) = peg_axes(tip_pose[2]);
        let com = Vec2::new(tip_pose[0], tip_pose[1]) + axis * params.com_above_tip_m;
        let mut peg = Self {
            data: MjData::new(Arc::new(model)),
            params,
            profile,
            body,
            slot_of_geom,
            substeps,
            dt,
            truth: PegTruth::default(),
        };
        peg.data.qpos_mut()[..3].copy_from_slice(&[com.x, com.y, tip_pose[2]]);
        peg.data.forward();
        peg.truth = peg.observe(peg.q(), (Vec2::zeros(), 0.0));
        Ok(peg)
    }

    /// Parameters.
    pub fn params(&self) -> &PegParams {
        &self.params
    }

    /// Truth of the last step.
    pub fn truth(&self) -> &PegTruth {
        &self.truth
    }

    /// The tip's pose.
    pub fn tip_pose(&self) -> [f64; 3] {
        tip_of(&self.params, self.q())
    }

    /// MuJoCo steps per call.
    pub fn substeps(&self) -> usize {
        self.substeps
    }

    fn q(&self) -> [f64; 3] {
        let q = self.data.qpos();
        [q[0], q[1], q[2]]
    }

    fn v(&self) -> [f64; 3] {
        let v = self.data.qvel();
        [v[0], v[1], v[2]]
    }

    /// Advances by the period it was built for with the wrist's flange `flange`, which takes
    /// the wrist's reaction every MuJoCo step. `dt` must be that period.
    pub fn step_with<F: Flange>(&mut self, flange: &mut F, dt: f64) {
        debug_assert!(
            (dt - self.dt).abs() <= 1e-9 * self.dt,
            "period {dt} vs {}",
            self.dt
        );
        let h = self.dt / self.substeps as f64;
        let (mut started, mut wrist) = (self.q(), (Vec2::zeros(), 0.0));
        for _ in 0..self.substeps {
            started = self.q();
            let (target, target_vel) = flange.pose();
            let (wf, pure, wm) = wrist_wrench(&self.params, started, self.v(), target, target_vel);
            wrist = (wf, wm);
            self.data
                .qfrc_applied_mut()
                .copy_from_slice(&[wf.x, wf.y, wm]);
            self.data.step();
            flange.react(-wf, -pure, h);
        }
        self.truth = self.observe(started, wrist);
    }

    /// MuJoCo's state (`mj_getState`: time, joints, rates, warm start).
    pub fn state(&self) -> [f64; MUJOCO_PEG_STATE_LEN] {
        let mut values = [0.0; MUJOCO_PEG_STATE_LEN];
        let len = self.data.read_state_into(STATE_SPEC, &mut values);
        debug_assert_eq!(len, MUJOCO_PEG_STATE_LEN, "the peg has three joints");
        values
    }

    /// Carries on from `state` (taken by [`MujocoPeg::state`] of a peg built alike) with the
    /// truth `truth` of the step that led there: the next step is the one that peg would have
    /// taken.
    pub fn restore(
        &mut self,
        state: &[f64; MUJOCO_PEG_STATE_LEN],
        truth: &PegTruth,
    ) -> Result<(), ConfigError> {
        let need = self.data.model().state_size(STATE_SPEC);
        if need != MUJOCO_PEG_STATE_LEN {
            return Err(ConfigError::rule(
                "world snapshot",
                format!("holds {MUJOCO_PEG_STATE_LEN} MuJoCo state values, this peg needs {need}"),
            ));
        }
        self.data
            .set_state(state, STATE_SPEC)
            .map_err(|e| ConfigError::rule("world snapshot", e.to_string()))?;
        self.data.forward();
        self.truth = *truth;
        Ok(())
    }

    /// The truth after a step that started at `started` with the wrist's wrench `wrist`
    /// (force, moment about the centre of mass): MuJoCo's contact forces of that step, the
    /// part's features at the pose it started from.
    fn observe(&self, started: [f64; 3], wrist: (Vec2, f64)) -> PegTruth {
        let q = self.q();
        let com = Vec2::new(started[0], started[1]);
        let (mut force, mut moment) = (Vec2::zeros(), 0.0);
        let mut normal_n = [0.0; SLOTS];
        for c in contacts_on(&self.data, self.body) {
            let on_peg = c.normal + c.friction;
            force += on_peg;
            moment += cross(c.at - com, on_peg);
            if let Some(slot) = self.slot_of_geom[c.geoms[0]].or(self.slot_of_geom[c.geoms[1]]) {
                normal_n[slot] += c.normal_n;
            }
        }
        let mut found = [Contact::default(); SLOTS];
        let g = &self.params.geometry;
        let count = contacts(g, &self.profile, tip_of(&self.params, started), &mut found);
        // The moment about the centre of mass where the step ended, as the built-in truth's.
        let moment = moment + cross(com - Vec2::new(q[0], q[1]), force);
        truth_at(
            &self.params,
            (q, self.v()),
            ((force, moment), wrist),
            &found[..count],
            count,
            &normal_n,
        )
    }
}

#[cfg(test)]
#[path = "mujoco_peg_tests.rs"]
mod tests;
