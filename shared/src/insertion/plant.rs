//! The peg held by a compliant wrist (docs/insertion.md, *The plant*): a rigid body (x, y, θ)
//! pulled towards the commanded pose by the wrist's stiffness (k_x, k_y, k_θ) acting at its
//! compliance centre on the peg's axis, in contact with the part at every vertex–edge pair
//! ([`super::geometry`]) through a penalty spring and damper and eq. 4.5 friction with
//! presliding at each. Contact stiffness makes the contact far stiffer than the wrist, so the
//! plant sub-steps each call to keep the stiffest contact mode's ω·h below 0.2.

use super::geometry::{
    Contact, Feature, MAX_CORNERS, PegHoleGeometry, Profile, contacts, peg_axes,
};
use crate::friction::{FrictionLaw, Presliding, PreslidingParams};
use crate::math::{Vec2, cross, perp};
use serde::{Deserialize, Serialize};

/// The peg, its wrist and its contacts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PegParams {
    /// Peg and hole.
    pub geometry: PegHoleGeometry,
    /// Mass of the peg and the gripper (kg).
    pub mass_kg: f64,
    /// Their inertia about their centre of mass (kg·m²).
    pub inertia_kg_m2: f64,
    /// Centre of mass above the tip, along the peg (m).
    pub com_above_tip_m: f64,
    /// The wrist's stiffness k_x, k_y (N/m, world) and k_θ (N·m/rad).
    pub wrist_stiffness: [f64; 3],
    /// The wrist's damping ratio.
    pub wrist_damping_ratio: f64,
    /// The wrist's compliance centre above the tip, along the peg (m): 0 is a remote centre
    /// of compliance at the tip (Whitney's RCC), the peg's length a servo wrist at the gripper.
    pub compliance_above_tip_m: f64,
    /// Contact stiffness (N/m) and damping (N·s/m).
    pub contact_stiffness_n_per_m: f64,
    /// Contact damping (N·s/m).
    pub contact_damping_n_s_per_m: f64,
    /// Friction law at every contact at `reference_normal_force_n`; μ = kinetic / reference.
    pub friction: FrictionLaw,
    /// Normal force at which `friction` holds (N).
    pub reference_normal_force_n: f64,
    /// Presliding.
    pub presliding: PreslidingParams,
}

impl Default for PegParams {
    fn default() -> Self {
        Self {
            geometry: PegHoleGeometry::default(),
            mass_kg: 0.2,
            inertia_kg_m2: 2e-4,
            com_above_tip_m: 0.03,
            wrist_stiffness: [2e3, 2e3, 5.0],
            wrist_damping_ratio: 0.7,
            compliance_above_tip_m: 0.03,
            contact_stiffness_n_per_m: 5e6,
            contact_damping_n_s_per_m: 300.0,
            friction: FrictionLaw {
                kinetic_n: 0.3,
                viscous_n_s_per_m: 0.0,
                stribeck_n: 0.05,
                stribeck_velocity_m_per_s: 1e-3,
            },
            reference_normal_force_n: 1.0,
            presliding: PreslidingParams::default(),
        }
    }
}

impl PegParams {
    /// The Coulomb coefficient μ of the kinetic friction.
    pub fn mu(&self) -> f64 {
        self.friction.kinetic_n / self.reference_normal_force_n
    }

    /// The break-away coefficient μ_s: the kinetic friction and the Stribeck excess at rest
    /// over the normal force.
    pub fn static_mu(&self) -> f64 {
        (self.friction.kinetic_n + self.friction.stribeck_n) / self.reference_normal_force_n
    }
}

/// The true contact state (docs/insertion.md, *The plant*).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ContactState {
    /// No contact.
    #[default]
    Free,
    /// On the face beside the hole.
    Face,
    /// On a chamfer (and perhaps the face).
    Chamfer,
    /// In the hole, touching one side.
    OnePoint,
    /// In the hole, touching both sides, sliding in.
    TwoPoint,
    /// Two-point and stuck with the edge contact at l ≥ μd: friction holds the applied wrench.
    Jammed,
    /// Two-point and stuck with l < μd: the contacts hold each other.
    Wedged,
    /// On the hole's bottom.
    Bottom,
}

/// What is true at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct PegTruth {
    /// The tip's pose (m, m, rad).
    pub pose: [f64; 3],
    /// The tip's velocity and the rate of θ.
    pub velocity: [f64; 3],
    /// Contact force on the peg (N).
    pub force: Vec2,
    /// Its moment about the tip (N·m).
    pub moment_about_tip: f64,
    /// The force the wrist applies to the peg (N): its spring and damper, the wrench Whitney's
    /// jamming diagram is drawn for.
    pub applied_force: Vec2,
    /// Its moment about the tip (N·m).
    pub applied_moment_about_tip: f64,
    /// Contacts.
    pub contacts: usize,
    /// Contact state.
    pub state: ContactState,
    /// Insertion depth of the tip below the face (m, ≤ 0 above it).
    pub depth_m: f64,
    /// In two-point contact, the hole edge's distance from the tip along the peg (m).
    pub edge_along_peg_m: Option<f64>,
}

/// The plant's whole state ([`PegPlant::state`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PegPlantState {
    /// Centre of mass and θ.
    pub q: [f64; 3],
    /// Their rates.
    pub v: [f64; 3],
    /// Each contact slot's bristle deflection (m).
    pub deflection_m: [f64; SLOTS],
    /// The feature each slot touches.
    pub touching: [Option<(Feature, i8)>; SLOTS],
    /// Each slot's normal force in the last sub-step (N).
    pub normal_n: [f64; SLOTS],
    /// The contact force and its moment about the centre of mass, last sub-step.
    pub last_contact: (Vec2, f64),
    /// The wrist's, last sub-step.
    pub last_wrist: (Vec2, f64),
    /// The truth of the last step.
    pub truth: PegTruth,
}

/// Speed below which a two-point contact counts as stuck (m/s).
const STUCK_M_PER_S: f64 = 1e-5;
/// Slots: the peg's four corners, then the part's corners.
pub const SLOTS: usize = 4 + MAX_CORNERS;

/// The wrist's flange: where the wrist pulls the peg to, and what takes its reaction.
pub trait Flange {
    /// The tip pose the wrist pulls the peg's tip to (m, m, rad), and its rate.
    fn pose(&self) -> ([f64; 3], [f64; 3]);
    /// The wrist's reaction on the flange over a sub-step of `h` (s): a force (N) at the
    /// flange's compliance centre and a pure moment (N·m).
    fn react(&mut self, force: Vec2, moment_nm: f64, h: f64);
}

/// A flange exactly at its commanded pose (the pose, its rate): an ideal position-controlled arm.
pub(crate) struct Commanded(pub(crate) [f64; 3], pub(crate) [f64; 3]);

impl Flange for Commanded {
    fn pose(&self) -> ([f64; 3], [f64; 3]) {
        (self.0, self.1)
    }

    fn react(&mut self, _force: Vec2, _moment_nm: f64, _h: f64) {}
}

/// The peg and the part.
#[derive(Debug, Clone)]
pub struct PegPlant {
    params: PegParams,
    profile: Profile,
    /// Centre of mass and θ, and their rates.
    q: [f64; 3],
    v: [f64; 3],
    bristles: [Presliding; SLOTS],
    /// The feature each slot last touched (a change releases its bristle).
    touching: [Option<(Feature, i8)>; SLOTS],
    truth: PegTruth,
    substep_s: f64,
    /// The contact force and its moment about the centre of mass in the last sub-step.
    last_contact: (Vec2, f64),
    /// The wrist's force and its moment about the centre of mass, last substep.
    last_wrist: (Vec2, f64),
    /// Each slot's normal force in the last sub-step (N).
    normal_n: [f64; SLOTS],
}

impl PegPlant {
    /// The peg at rest with its tip at `tip_pose`.
    pub fn new(params: PegParams, tip_pose: [f64; 3]) -> Self {
        let (axis, _) = peg_axes(tip_pose[2]);
        let com = Vec2::new(tip_pose[0], tip_pose[1]) + axis * params.com_above_tip_m;
        let omega = stiffest_contact_mode(&params);
        let mut p = Self {
            params,
            profile: params.geometry.profile(),
            q: [com.x, com.y, tip_pose[2]],
            v: [0.0; 3],
            bristles: [Presliding::default(); SLOTS],
            touching: [None; SLOTS],
            truth: PegTruth::default(),
            substep_s: 0.2 / omega,
            last_contact: (Vec2::zeros(), 0.0),
            last_wrist: (Vec2::zeros(), 0.0),
            normal_n: [0.0; SLOTS],
        };
        p.truth = p.observe(&[], 0);
        p
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
        tip_of(&self.params, self.q)
    }

    /// The whole state, for a restarted servo to resume ([`PegPlant::restore`]).
    pub fn state(&self) -> PegPlantState {
        PegPlantState {
            q: self.q,
            v: self.v,
            deflection_m: self.bristles.map(|b| b.deflection_m),
            touching: self.touching,
            normal_n: self.normal_n,
            last_contact: self.last_contact,
            last_wrist: self.last_wrist,
            truth: self.truth,
        }
    }

    /// Carries on from `s` (taken by [`PegPlant::state`] of a plant with the same parameters):
    /// the next step is the one that plant would have taken.
    pub fn restore(&mut self, s: &PegPlantState) {
        self.q = s.q;
        self.v = s.v;
        for (b, d) in self.bristles.iter_mut().zip(s.deflection_m) {
            b.deflection_m = d;
        }
        self.touching = s.touching;
        self.normal_n = s.normal_n;
        self.last_contact = s.last_contact;
        self.last_wrist = s.last_wrist;
        self.truth = s.truth;
    }

    /// Advances by `dt` with the wrist commanding the tip to `target` (x, y, θ) at `target_vel`:
    /// a flange that is exactly where it is commanded.
    pub fn step(&mut self, target: [f64; 3], target_vel: [f64; 3], dt: f64) {
        self.step_with(&mut Commanded(target, target_vel), dt);
    }

    /// Advances by `dt` with the wrist's flange `flange`, which takes the wrist's reaction
    /// every sub-step.
    pub fn step_with<F: Flange>(&mut self, flange: &mut F, dt: f64) {
        let n = (dt / self.substep_s).ceil().max(1.0) as usize;
        let h = dt / n as f64;
        let mut found = [Contact::default(); SLOTS];
        let mut count = 0;
        for _ in 0..n {
            count = contacts(
                &self.params.geometry,
                &self.profile,
                self.tip_pose(),
                &mut found,
            );
            let (f, m) = self.contact_wrench(&found[..count], h);
            self.last_contact = (f, m);
            let (target, target_vel) = flange.pose();
            let (wf, pure, wm) = wrist_wrench(&self.params, self.q, self.v, target, target_vel);
            self.last_wrist = (wf, wm);
            let p = &self.params;
            let acc = [
                (f.x + wf.x) / p.mass_kg,
                (f.y + wf.y) / p.mass_kg,
                (m + wm) / p.inertia_kg_m2,
            ];
            for ((v, q), a) in self.v.iter_mut().zip(self.q.iter_mut()).zip(acc) {
                *v += a * h;
                *q += *v * h;
            }
            flange.react(-wf, -pure, h);
        }
        self.truth = self.observe(&found[..count], count);
    }

    /// The contact forces' resultant on the peg and their moment about the centre of mass;
    /// steps each contact's presliding state by `h`.
    fn contact_wrench(&mut self, found: &[Contact], h: f64) -> (Vec2, f64) {
        let p = self.params;
        let com = Vec2::new(self.q[0], self.q[1]);
        let mut seen = [false; SLOTS];
        let (mut f, mut m) = (Vec2::zeros(), 0.0);
        for c in found {
            seen[c.slot] = true;
            if self.touching[c.slot] != Some(c.feature) {
                self.bristles[c.slot].reset();
                self.touching[c.slot] = Some(c.feature);
            }
            let r = c.point - com;
            // The velocity of the peg's material at the contact (the part is still).
            let vel = Vec2::new(self.v[0], self.v[1]) + perp(r) * self.v[2];
            let rate = -vel.dot(&c.normal);
            let fnorm = (p.contact_stiffness_n_per_m * c.depth_m
                + p.contact_damping_n_s_per_m * rate)
                .max(0.0);
            let tangent = -perp(c.normal);
            let fr = if fnorm > 0.0 {
                let law = p.friction.scaled(fnorm / p.reference_normal_force_n);
                self.bristles[c.slot].step(&law, &p.presliding, vel.dot(&tangent), h)
            } else {
                p.presliding.stiffness_n_per_m * self.bristles[c.slot].deflection_m
            };
            self.normal_n[c.slot] = fnorm;
            let fc = c.normal * fnorm - tangent * fr;
            f += fc;
            m += cross(r, fc);
        }
        for ((seen, bristle), touching) in seen
            .iter()
            .zip(self.bristles.iter_mut())
            .zip(self.touching.iter_mut())
        {
            if !seen {
                bristle.reset();
                *touching = None;
            }
        }
        for (seen, f) in seen.iter().zip(self.normal_n.iter_mut()) {
            if !seen {
                *f = 0.0;
            }
        }
        (f, m)
    }

    /// The truth at the present state with the contacts `found`.
    fn observe(&self, found: &[Contact], count: usize) -> PegTruth {
        let motion = (self.q, self.v);
        let wrenches = (self.last_contact, self.last_wrist);
        truth_at(&self.params, motion, wrenches, found, count, &self.normal_n)
    }
}

/// The stiffest contact mode's ω (rad/s): a contact at the corner farthest from the centre of
/// mass, ω = √(k_c (1/m + ρ²/I)).
pub(crate) fn stiffest_contact_mode(p: &PegParams) -> f64 {
    let g = &p.geometry;
    let reach =
        (p.com_above_tip_m.max(g.peg_length_m - p.com_above_tip_m)).hypot(0.5 * g.peg_width_m);
    let inv_mass = 1.0 / p.mass_kg + reach * reach / p.inertia_kg_m2;
    (p.contact_stiffness_n_per_m * inv_mass).sqrt()
}

/// The tip's pose (x, y, θ) of the peg whose centre of mass and tilt are `q`.
pub(crate) fn tip_of(p: &PegParams, q: [f64; 3]) -> [f64; 3] {
    let (axis, _) = peg_axes(q[2]);
    let tip = Vec2::new(q[0], q[1]) - axis * p.com_above_tip_m;
    [tip.x, tip.y, q[2]]
}

/// The wrist's force at the peg's compliance centre, its pure moment (the rotational spring
/// and damper) and their moment about the centre of mass, pulling the peg (centre of mass and
/// tilt `q`, their rates `v`) towards the flange's pose `target` moving at `target_vel`.
pub(crate) fn wrist_wrench(
    p: &PegParams,
    q: [f64; 3],
    v: [f64; 3],
    target: [f64; 3],
    target_vel: [f64; 3],
) -> (Vec2, f64, f64) {
    let h = p.compliance_above_tip_m;
    let tip = tip_of(p, q);
    let at = Vec2::new(tip[0], tip[1]) + peg_axes(tip[2]).0 * h;
    let (axis_d, _) = peg_axes(target[2]);
    let want = Vec2::new(target[0], target[1]) + axis_d * h;
    let com = Vec2::new(q[0], q[1]);
    let r = at - com;
    let vel = Vec2::new(v[0], v[1]) + perp(r) * v[2];
    let want_vel = Vec2::new(target_vel[0], target_vel[1]) + perp(axis_d * h) * target_vel[2];
    let k = p.wrist_stiffness;
    let z = p.wrist_damping_ratio;
    let c_lin = 2.0 * z * (k[0].max(k[1]) * p.mass_kg).sqrt();
    let inertia_at_centre = p.inertia_kg_m2 + p.mass_kg * r.norm_squared();
    let c_rot = 2.0 * z * (k[2] * inertia_at_centre).sqrt();
    let f = Vec2::new(
        k[0] * (want.x - at.x) + c_lin * (want_vel.x - vel.x),
        k[1] * (want.y - at.y) + c_lin * (want_vel.y - vel.y),
    );
    let m = k[2] * (target[2] - q[2]) + c_rot * (target_vel[2] - v[2]);
    (f, m, m + cross(r, f))
}

/// The truth of the peg at centre of mass and tilt `q` moving at `v` (the `motion`), with the
/// last sub-step's contact and wrist wrenches (force, moment about the centre of mass), the
/// contacts `found` at the pose that sub-step started from and each slot's normal force.
pub(crate) fn truth_at(
    p: &PegParams,
    motion: ([f64; 3], [f64; 3]),
    wrenches: ((Vec2, f64), (Vec2, f64)),
    found: &[Contact],
    count: usize,
    normal_n: &[f64; SLOTS],
) -> PegTruth {
    let (q, v) = motion;
    let tip_pose = tip_of(p, q);
    let tip = Vec2::new(tip_pose[0], tip_pose[1]);
    let com = Vec2::new(q[0], q[1]);
    let r_tip = tip - com;
    let tip_vel = Vec2::new(v[0], v[1]) + perp(r_tip) * v[2];
    // A wrench (force, moment about the centre of mass) with its moment taken about the tip.
    let about_tip = |(f, m): (Vec2, f64)| (f, m + cross(com - tip, f));
    let (force, moment) = about_tip(wrenches.0);
    let (applied_force, applied_moment) = about_tip(wrenches.1);
    let (state, edge) = classify(found, normal_n, tip_vel.y, p);
    PegTruth {
        pose: tip_pose,
        velocity: [tip_vel.x, tip_vel.y, v[2]],
        force,
        moment_about_tip: moment,
        applied_force,
        applied_moment_about_tip: applied_moment,
        contacts: count,
        state,
        depth_m: -tip.y,
        edge_along_peg_m: edge,
    }
}

/// A contact carrying less than this is not counted in the contact state (N): ten times the
/// force sensor's noise; a lighter touch (the peg brushing a wall under the dither) is free.
pub const LEAST_CONTACT_N: f64 = 0.2;

/// The contact state from the contacts and the tip's insertion speed (docs/insertion.md).
fn classify(
    found: &[Contact],
    normal_n: &[f64; SLOTS],
    tip_vy: f64,
    p: &PegParams,
) -> (ContactState, Option<f64>) {
    let mut kept = [Contact::default(); SLOTS];
    let mut n = 0;
    for c in found.iter().filter(|c| normal_n[c.slot] >= LEAST_CONTACT_N) {
        kept[n] = *c;
        n += 1;
    }
    let found = &kept[..n];
    if found.is_empty() {
        return (ContactState::Free, None);
    }
    let has = |f: Feature| found.iter().any(|c| c.counted_as == f);
    if has(Feature::Bottom) {
        return (ContactState::Bottom, None);
    }
    let in_hole = |c: &&Contact| c.counted_as == Feature::Wall;
    let left = found.iter().filter(in_hole).any(|c| c.feature.1 < 0);
    let right = found.iter().filter(in_hole).any(|c| c.feature.1 > 0);
    if left && right {
        let edge = found
            .iter()
            .filter_map(|c| c.along_peg_m)
            .fold(None, |a: Option<f64>, l| Some(a.map_or(l, |a| a.max(l))));
        if tip_vy.abs() < STUCK_M_PER_S {
            let wedged = edge.is_some_and(|l| l < p.mu() * p.geometry.peg_width_m);
            let state = if wedged {
                ContactState::Wedged
            } else {
                ContactState::Jammed
            };
            return (state, edge);
        }
        return (ContactState::TwoPoint, edge);
    }
    if left || right {
        return (ContactState::OnePoint, None);
    }
    if has(Feature::Chamfer) {
        return (ContactState::Chamfer, None);
    }
    (ContactState::Face, None)
}

#[cfg(test)]
#[path = "plant_tests.rs"]
mod tests;
