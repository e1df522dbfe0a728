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

/// A flange exactly at its commanded pose: an ideal position-controlled arm.
struct Commanded([f64; 3], [f64; 3]);

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
        // The stiffest contact mode: the corner farthest from the centre of mass.
        let g = &params.geometry;
        let reach = (params
            .com_above_tip_m
            .max(g.peg_length_m - params.com_above_tip_m))
        .hypot(0.5 * g.peg_width_m);
        let inv_mass = 1.0 / params.mass_kg + reach * reach / params.inertia_kg_m2;
        let omega = (params.contact_stiffness_n_per_m * inv_mass).sqrt();
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
        let (axis, _) = peg_axes(self.q[2]);
        let tip = Vec2::new(self.q[0], self.q[1]) - axis * self.params.com_above_tip_m;
        [tip.x, tip.y, self.q[2]]
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
            let (wf, pure, wm) = self.wrist_wrench(target, target_vel);
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

    /// The wrist's force at the peg's compliance centre, its pure moment (the rotational
    /// spring and damper) and their moment about the centre of mass, pulling the peg towards
    /// the flange's pose.
    fn wrist_wrench(&self, target: [f64; 3], target_vel: [f64; 3]) -> (Vec2, f64, f64) {
        let p = &self.params;
        let h = p.compliance_above_tip_m;
        let tip = self.tip_pose();
        let at = Vec2::new(tip[0], tip[1]) + peg_axes(tip[2]).0 * h;
        let (axis_d, _) = peg_axes(target[2]);
        let want = Vec2::new(target[0], target[1]) + axis_d * h;
        let com = Vec2::new(self.q[0], self.q[1]);
        let r = at - com;
        let vel = Vec2::new(self.v[0], self.v[1]) + perp(r) * self.v[2];
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
        let m = k[2] * (target[2] - self.q[2]) + c_rot * (target_vel[2] - self.v[2]);
        (f, m, m + cross(r, f))
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
        let tip_pose = self.tip_pose();
        let tip = Vec2::new(tip_pose[0], tip_pose[1]);
        let com = Vec2::new(self.q[0], self.q[1]);
        let r_tip = tip - com;
        let tip_vel = Vec2::new(self.v[0], self.v[1]) + perp(r_tip) * self.v[2];
        let p = &self.params;
        // A wrench (force, moment about the centre of mass) with its moment taken about the tip.
        let about_tip = |(f, m): (Vec2, f64)| (f, m + cross(com - tip, f));
        let (force, moment) = about_tip(self.last_contact);
        let (applied_force, applied_moment) = about_tip(self.last_wrist);
        let (state, edge) = classify(found, &self.normal_n, tip_vel.y, p);
        PegTruth {
            pose: tip_pose,
            velocity: [tip_vel.x, tip_vel.y, self.v[2]],
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
mod tests {
    use super::*;
    use crate::insertion::whitney::Fit;

    fn sharp() -> PegParams {
        let mut p = PegParams::default();
        p.geometry.chamfer_m = 0.0;
        p
    }

    /// Pressed flat on the face beside the hole by the wrist, the peg settles where the wrist's
    /// spring equals its two tip corners' contact springs: depth k_y Δ / (k_y + 2 k_c).
    #[test]
    fn pressed_on_the_face_the_corners_carry_the_wrist() {
        let p = sharp();
        let start = [0.015, 0.0, 0.0];
        let mut plant = PegPlant::new(p, start);
        let push = 2e-3;
        for _ in 0..5000 {
            plant.step([0.015, -push, 0.0], [0.0; 3], 1e-4);
        }
        let (ky, kc) = (p.wrist_stiffness[1], p.contact_stiffness_n_per_m);
        let want = ky * push / (ky + 2.0 * kc);
        let t = plant.truth();
        assert!(
            (t.depth_m - want).abs() < 1e-3 * want,
            "{} vs {want}",
            t.depth_m
        );
        assert_eq!((t.contacts, t.state), (2, ContactState::Face));
        assert!((t.force.y - ky * (push - want)).abs() < 1e-3 * ky * push);
    }

    /// At rest on the face, leaned on by a tilted and offset wrist (its compliance centre 30 mm
    /// above the tip), the wrench the wrist applies balances the contacts': equal and opposite
    /// forces, and moments about the tip (not zero here: the wrist's k_θ Δθ and its force's
    /// lever from the compliance centre).
    #[test]
    fn at_rest_the_applied_wrench_balances_the_contacts() {
        let p = sharp();
        assert!(p.compliance_above_tip_m > 0.0);
        let mut plant = PegPlant::new(p, [0.015, 0.0, 0.0]);
        for _ in 0..10_000 {
            plant.step([0.0153, -2e-3, 0.02], [0.0; 3], 1e-4);
        }
        let t = plant.truth();
        let v = t.velocity;
        assert!(v[0].abs() + v[1].abs() < 1e-6 && v[2].abs() < 1e-4, "{v:?}");
        let scale = t.force.norm();
        assert!(
            scale > 1.0 && t.applied_moment_about_tip.abs() > 0.01,
            "{t:?}"
        );
        assert!((t.applied_force + t.force).norm() < 1e-3 * scale, "{t:?}");
        let dm = t.applied_moment_about_tip + t.moment_about_tip;
        assert!(dm.abs() < 1e-3 * t.applied_moment_about_tip.abs(), "{t:?}");
    }

    /// Dragged along the face at 10 mm/s (far above the Stribeck velocity), the friction on
    /// the peg is μ times the normal force, against the motion.
    #[test]
    fn dragged_on_the_face_friction_is_mu_times_the_normal_force() {
        let p = sharp();
        let mut plant = PegPlant::new(p, [0.010, 0.0, 0.0]);
        let (push, speed, dt) = (2e-3, 0.01, 1e-4);
        let mut ratio = Vec::new();
        for i in 0..6000 {
            let x = 0.010 + speed * i as f64 * dt;
            plant.step([x, -push, 0.0], [speed, 0.0, 0.0], dt);
            let t = plant.truth();
            if i > 3000 {
                ratio.push(-t.force.x / t.force.y);
            }
        }
        let mean = ratio.iter().sum::<f64>() / ratio.len() as f64;
        assert!((mean - p.mu()).abs() < 0.01 * p.mu(), "{mean}");
    }

    /// A peg in two-point contact (tilted 0.3°, sharp edge, RCC at the tip) under a wrench
    /// inside Whitney's parallelogram slides in; outside it (a moment that leans it into the
    /// contacts, or a lateral push beyond 1/μ) it stays: jammed.
    #[test]
    fn two_point_contact_slides_inside_the_parallelogram_and_jams_outside() {
        let mut p = sharp();
        p.compliance_above_tip_m = 0.0;
        p.wrist_stiffness = [200.0, 200.0, 0.05];
        let g = p.geometry;
        let fit = Fit {
            peg_width_m: g.peg_width_m,
            clearance_ratio: g.clearance_ratio,
            friction: p.mu(),
        };
        let theta = 0.3f64.to_radians();
        let l = fit.two_point_depth_m(theta).unwrap();
        let (r, big_d) = (0.5 * g.peg_width_m, g.hole_width_m());
        let tip = [
            -0.5 * big_d + r * theta.cos() + l * theta.sin(),
            r * theta.sin() - l * theta.cos(),
            theta,
        ];
        let lambda = fit.lambda(l);
        let fz = 4.0;
        // Depth gained in the first 0.1 s, in the next 0.2 s, and the state at the end.
        let run = |fx_over_fz: f64, m_over_rfz: f64| -> (f64, f64, ContactState) {
            let mut plant = PegPlant::new(p, tip);
            let k = p.wrist_stiffness;
            let target = [
                tip[0] + fx_over_fz * fz / k[0],
                tip[1] - fz / k[1],
                tip[2] + m_over_rfz * r * fz / k[2],
            ];
            for _ in 0..1000 {
                plant.step(target, [0.0; 3], 1e-4);
            }
            let early = plant.truth().depth_m + tip[1];
            for _ in 0..2000 {
                plant.step(target, [0.0; 3], 1e-4);
            }
            let late = plant.truth().depth_m + tip[1] - early;
            (early, late, plant.truth().state)
        };
        assert!(fit.slides(l, 0.0, 0.0));
        for (fx, m) in [(0.0, 0.0), (0.0, 0.8 * lambda), (-0.5, 0.0)] {
            assert!(fit.slides(l, fx, m));
            let slid = run(fx, m);
            assert!(slid.0 > 1e-3, "inside ({fx}, {m}): {slid:?}");
        }
        for (fx, m) in [
            (0.0, 1.2 * lambda),
            (0.0, 2.0 * lambda),
            (1.2 / fit.friction, 0.0),
        ] {
            assert!(!fit.slides(l, fx, m));
            let held = run(fx, m);
            assert!(held.1.abs() < 1e-5, "outside ({fx}, {m}): {held:?}");
            assert_eq!(held.2, ContactState::Jammed, "({fx}, {m})");
        }
    }
}
