//! The contact state as the controller can know it (docs/insertion.md, *The contact-state estimator*): from
//! the wrist's force/torque sensor, the tip's measured depth below the face (whose height the
//! robot knows) and the nominal chamfer, never from the part's true position.
//!
//! * free: the contact force under `free_n` and its moment about the tip under `free_nm`;
//! * face: the point of the tip face the part pushes on (its centre of pressure) at the face
//!   (depth under `face_band_m`): with the part's orientation unknown, at a line through the
//!   robot's origin whose slope is within the bounds the points named face so far leave;
//! * chamfer: that point between the face and the chamfer's depth;
//! * in the hole, Whitney's balance (docs/insertion.md) with the hole's edge at
//!   l = depth − chamfer depth along the peg gives both contacts' normal forces from the
//!   measured lateral force and moment: two-point when, for one of the two tilts, both press
//!   harder than `two_point_n`; jammed or wedged when two-point and the tip has stopped
//!   (l ≥ μd or l < μd); one-point otherwise.

use super::controller::Input;
use super::plant::ContactState;
use crate::math::turn;
use std::f64::consts::FRAC_PI_4;

/// The estimator's state, for a restarted servo.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EstimatorState {
    /// The filtered force (N) and moment (N·m).
    pub filtered: ([f64; 2], f64),
    /// The face's slopes in the robot's frame (lowest, highest).
    pub face_slopes: [f64; 2],
}

/// What the estimator knows and its thresholds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimator {
    /// The face's height (m).
    pub face_y_m: f64,
    /// The chamfer's depth (m).
    pub chamfer_depth_m: f64,
    /// Peg width d (m).
    pub peg_width_m: f64,
    /// Friction coefficient μ (identified).
    pub mu: f64,
    /// The break-away friction coefficient μ_s (the Stribeck peak over μ; identified): the
    /// most axial force one wall contact holds per newton of its normal force.
    pub static_mu: f64,
    /// Contact force below which the peg is free (N).
    pub free_n: f64,
    /// Depth band of the face (m).
    pub face_band_m: f64,
    /// Least normal force of each contact of a two-point state (N).
    pub two_point_n: f64,
    /// Insertion speed below which the peg has stopped (m/s).
    pub stopped_m_per_s: f64,
    /// Moment about the tip below which, with a force under `free_n`, the peg is free (N·m).
    pub free_nm: f64,
    /// Time constant of the low-pass on the sensor's readings (s).
    pub filter_s: f64,
    /// Lateral force beyond the face's friction cone that rules the face out (N).
    pub cone_margin_n: f64,
    /// Least force along the axis for a point to narrow the face's slopes (N): under it the
    /// centre of pressure is the moment's noise over next to nothing.
    pub narrow_least_n: f64,
    /// The filtered force (N) and moment (N·m).
    filtered: ([f64; 2], f64),
    /// The slopes (lowest, highest) of the face's line through the robot's origin, in the
    /// robot's frame, that every point named face so far lies on within `face_band_m`: [0, 0]
    /// for a part whose orientation is known.
    face_slopes: [f64; 2],
}

impl Estimator {
    /// The estimator for a part whose face is at `face_y_m`, with a chamfer `chamfer_depth_m`
    /// deep, a peg `peg_width_m` wide and friction `mu`.
    pub fn new(face_y_m: f64, chamfer_depth_m: f64, peg_width_m: f64, mu: f64) -> Self {
        Self {
            face_y_m,
            chamfer_depth_m,
            peg_width_m,
            mu,
            static_mu: mu,
            free_n: 0.2,
            face_band_m: 20e-6,
            two_point_n: 0.05,
            stopped_m_per_s: 1e-5,
            free_nm: 1e-3,
            filter_s: 2e-3,
            narrow_least_n: 0.5,
            cone_margin_n: 0.05,
            filtered: ([0.0; 2], 0.0),
            face_slopes: [0.0; 2],
        }
    }

    /// For a part whose orientation the robot knows to within `angle_rad` (docs/insertion.md,
    /// *The part's frame*): the face is a line through the robot's origin (the hole's nominal
    /// centre) at depth 0, at most `angle_rad` from the robot's x axis.
    pub fn with_face_turned_up_to(mut self, angle_rad: f64) -> Self {
        let t = angle_rad.abs().min(FRAC_PI_4).tan();
        self.face_slopes = [-t, t];
        self
    }

    /// With the break-away friction coefficient `static_mu` (at least μ).
    pub fn with_static_friction(mut self, static_mu: f64) -> Self {
        self.static_mu = static_mu.max(self.mu);
        self
    }

    /// Its state: the filtered force (N) and moment (N·m), the face's slopes.
    pub fn state(&self) -> EstimatorState {
        EstimatorState {
            filtered: self.filtered,
            face_slopes: self.face_slopes,
        }
    }

    /// Carries on from `s` ([`Estimator::state`]).
    pub fn restore(&mut self, s: &EstimatorState) {
        self.filtered = s.filtered;
        self.face_slopes = s.face_slopes;
    }

    /// Low-passes one reading (the sensor's moment noise is σ = 0.5 mN·m, a tenth of a newton
    /// at the peg's half-width) and classifies the filtered one. The time constant is
    /// `filter_s`, and at least four ticks: at a real robot's 1 kHz or 500 Hz a 2-ms filter
    /// would pass each reading through whole. `inp` is in the part's frame as the controller
    /// estimates it, the robot's turned by `frame_rad`.
    pub fn update(
        &mut self,
        inp: &Input,
        frame_rad: f64,
        speed_m_per_s: f64,
        dt: f64,
    ) -> ContactState {
        let a = (dt / self.filter_s.max(4.0 * dt)).min(1.0);
        let (f, m) = &mut self.filtered;
        for (f, x) in f.iter_mut().zip(inp.force) {
            *f += a * (x - *f);
        }
        *m += a * (inp.moment_nm - *m);
        let filtered = Input {
            force: *f,
            moment_nm: *m,
            tip: inp.tip,
        };
        self.classify(&filtered, frame_rad, speed_m_per_s)
    }

    /// The state from one sensor reading and pose in the part's frame as estimated (the
    /// robot's turned by `frame_rad`), the tip's insertion speed `speed_m_per_s` (positive
    /// going in). A point named face narrows the face's slopes.
    pub fn classify(&mut self, inp: &Input, frame_rad: f64, speed_m_per_s: f64) -> ContactState {
        let [fx, fy] = inp.force;
        let r = 0.5 * self.peg_width_m;
        // Opposite wall contacts cancel in the force but not in the moment.
        if fx.hypot(fy) < self.free_n && inp.moment_nm.abs() < self.free_nm {
            return ContactState::Free;
        }
        let depth = self.face_y_m - inp.tip[1];
        // Where on the tip face the part pushes (the centre of pressure x_c = M/F_y, within
        // the face) and how deep that point is: a tilted peg on the face's edge has its tip's
        // centre below the face, the point it rests on at the face.
        let x_c = if fy > 0.0 {
            (inp.moment_nm / fy).clamp(-r, r)
        } else {
            0.0
        };
        let (s, c) = inp.tip[2].sin_cos();
        // The point in the robot's frame, where the face's line is known to pass through the
        // origin: its x and its depth below the robot's x axis.
        let p = turn([inp.tip[0] + x_c * c, inp.tip[1] + x_c * s], frame_rad);
        let (x, contact_depth) = (p[0], self.face_y_m - p[1]);
        let [lo, hi] = self.face_slopes;
        // The face's normal is within the frame's error of the robot's y axis, so the force it
        // puts on the peg is within μ (and that error) of it: a force farther out is the
        // chamfer's (45°: (1 − μ)/(1 + μ) sliding down it).
        let frame_bound = hi.abs().max(lo.abs()).atan();
        let cone = (self.mu.atan() + frame_bound).tan();
        let on_face_cone = fx.abs() <= cone * fy + self.cone_margin_n;
        if on_face_cone && contact_depth - (lo * x).max(hi * x) < self.face_band_m {
            if fy >= self.narrow_least_n {
                self.narrow_face(x, contact_depth);
            }
            return ContactState::Face;
        }
        if contact_depth - 0.5 * (lo + hi) * x <= self.chamfer_depth_m + self.face_band_m {
            return ContactState::Chamfer;
        }
        let l = (depth - self.chamfer_depth_m).max(1e-6);
        let (mu, m) = (self.mu, inp.moment_nm);
        // Whitney's balance with the wrist's wrench (−F, −M), for each tilt (the mirror flips
        // the lateral force and the moment).
        let pressed = |fx: f64, m: f64| {
            let f1 = (-m - mu * r * fx) / l;
            let f2 = -fx + f1;
            f1 > self.two_point_n && f2 > self.two_point_n
        };
        // One contact on a wall (the tip's corner on it, or the hole's edge on the peg's side)
        // holds along the axis at most μ_s times its normal force, and its normal is within
        // the frame's bound and the peg's tilt of the x axis: a force farther from the x axis
        // needs a second contact pressing the other way. Their squeeze is internal to the peg
        // (a wedge can hold with no lateral force and no moment), so Whitney's balance, which
        // reads the normal forces from the lateral force and the moment, does not see it.
        let wall_cone = (self.static_mu.atan() + frame_bound + inp.tip[2].abs()).tan();
        let squeezed = fy > wall_cone * fx.abs() + self.cone_margin_n;
        if squeezed || pressed(fx, m) || pressed(-fx, -m) {
            if speed_m_per_s.abs() < self.stopped_m_per_s {
                return if l < mu * self.peg_width_m {
                    ContactState::Wedged
                } else {
                    ContactState::Jammed
                };
            }
            return ContactState::TwoPoint;
        }
        ContactState::OnePoint
    }

    /// Keeps the face's slopes that put the point `x` (m) at `depth` (m) within the band: if
    /// none of them does (the point above the face, by noise), they stay as they were.
    fn narrow_face(&mut self, x: f64, depth: f64) {
        if x.abs() < 1e-4 {
            return;
        }
        let b = self.face_band_m;
        let (a, z) = ((depth - b) / x, (depth + b) / x);
        let [lo, hi] = self.face_slopes;
        let (lo, hi) = (lo.max(a.min(z)), hi.min(a.max(z)));
        if lo <= hi {
            self.face_slopes = [lo, hi];
        }
    }
}

/// The classes the accuracy compares: two-point, jammed and wedged are one (the estimator
/// tells them apart by the tip's speed, which the truth also uses).
pub fn class(s: ContactState) -> ContactState {
    match s {
        ContactState::Jammed | ContactState::Wedged => ContactState::TwoPoint,
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::insertion::plant::{PegParams, PegPlant};

    fn reading(plant: &PegPlant) -> Input {
        let t = plant.truth();
        Input {
            force: [t.force.x, t.force.y],
            moment_nm: t.moment_about_tip,
            tip: t.pose,
        }
    }

    /// Held by the wrist in each state of the plant, the estimator names it: on the face, on
    /// the chamfer, in one-point contact with a wall, wedged in two-point contact.
    #[test]
    fn the_estimate_is_the_plants_state_when_held() {
        let p = PegParams::default();
        let g = p.geometry;
        let h = g.chamfer_m / g.chamfer_angle_deg.to_radians().tan();
        let mut est = Estimator::new(0.0, h, g.peg_width_m, p.mu());
        let half = 0.5 * g.hole_width_m();
        let r = 0.5 * g.peg_width_m;
        let theta = 1f64.to_radians();
        let l = (half * 2.0 - g.peg_width_m * theta.cos()) / theta.sin();
        let two_point_tip = [
            -half + r * theta.cos() + (l + h) * theta.sin(),
            r * theta.sin() - (l + h) * theta.cos(),
            theta,
        ];
        for (start, push, want) in [
            ([0.012, 0.0, 0.0], [0.0, -1e-3, 0.0], ContactState::Face),
            (
                [half + 0.25e-3 - r, -0.25e-3, 0.0],
                [1e-3, -1e-3, 0.0],
                ContactState::Chamfer,
            ),
            (
                [half - r - 5e-6, -0.004, 0.0],
                [0.25e-3, 0.0, 0.0],
                ContactState::OnePoint,
            ),
            (two_point_tip, [0.0, -1e-3, 0.1], ContactState::Wedged),
        ] {
            let mut plant = PegPlant::new(p, start);
            let target = [start[0] + push[0], start[1] + push[1], start[2] + push[2]];
            for _ in 0..3000 {
                plant.step(target, [0.0; 3], 1e-4);
            }
            let truth = plant.truth();
            assert_eq!(
                class(truth.state),
                class(want),
                "truth at {start:?}: {truth:?}"
            );
            let got = est.classify(&reading(&plant), 0.0, -truth.velocity[1]);
            assert_eq!(got, truth.state, "estimate at {start:?}");
        }
        let free = Input::default();
        assert_eq!(est.classify(&free, 0.0, 0.0), ContactState::Free);
    }

    /// At 500 Hz the filter still averages: a force alternating ±1 N tick by tick comes out
    /// within ±0.2 N (the filter's steady swing is a/(2 − a) = 1/7 with a = 1/4), where a 2-ms
    /// time constant alone would pass it whole.
    #[test]
    fn the_filter_spans_four_ticks_at_a_robots_rate() {
        let mut est = Estimator::new(0.0, 0.0, 0.01, 0.3);
        let mut last = 0.0;
        for k in 0..200 {
            let f = if k % 2 == 0 { 1.0 } else { -1.0 };
            let inp = Input {
                force: [f, 0.0],
                ..Input::default()
            };
            est.update(&inp, 0.0, 0.0, 2e-3);
            last = est.state().filtered.0[0];
        }
        assert!(last.abs() < 0.2, "{last}");
        assert!(last.abs() > 0.1, "{last}");
    }

    /// The peg's left corner on a face turned `angle_deg` (its depth below the robot's x axis
    /// x tan(angle)), `below_m` deeper, the tip square to the robot's frame, pressed with
    /// `force`.
    fn corner_at(x: f64, angle_deg: f64, below_m: f64, force: [f64; 2]) -> Input {
        let r = 0.005;
        Input {
            force,
            moment_nm: -r * force[1],
            tip: [x + r, -(x * angle_deg.to_radians().tan() + below_m), 0.0],
        }
    }

    /// With the part turned 1.5° and its orientation unknown (to 2°), a corner on the face
    /// 10 mm from the hole's nominal centre, 0.26 mm below the robot's x axis, is the face (a
    /// known frame calls it the chamfer); walked along the face to 6 mm, the points narrow the
    /// face's line until a corner 60 µm under it is the chamfer, which the prior's 2° alone
    /// allows (it would call it the face).
    #[test]
    fn a_turned_face_is_told_from_the_chamfer_by_its_line() {
        let est =
            || Estimator::new(0.0, 0.5e-3, 0.01, 0.3).with_face_turned_up_to(2f64.to_radians());
        let far = corner_at(0.010, 1.5, 0.0, [0.0, 1.0]);
        assert_eq!(est().classify(&far, 0.0, 0.0), ContactState::Face);
        let mut known = Estimator::new(0.0, 0.5e-3, 0.01, 0.3);
        assert_eq!(known.classify(&far, 0.0, 0.0), ContactState::Chamfer);

        let below = corner_at(0.0058, 1.5, 60e-6, [0.0, 1.0]);
        assert_eq!(est().classify(&below, 0.0, 0.0), ContactState::Face);
        let mut walked = est();
        for k in 0..=600 {
            let x = 0.012 - 1e-5 * f64::from(k);
            let inp = corner_at(x, 1.5, 0.0, [0.2, 1.0]);
            assert_eq!(
                walked.classify(&inp, 0.0, 0.0),
                ContactState::Face,
                "at {x}"
            );
        }
        assert_eq!(walked.classify(&below, 0.0, 0.0), ContactState::Chamfer);
        // The same in the frame the controller has turned to the face (by its angle, −1.5°),
        // where the corner is 60 µm under the x axis.
        let a = -1.5f64.to_radians();
        let turned = Input {
            force: turn(below.force, -a),
            moment_nm: below.moment_nm,
            tip: {
                let p = turn([below.tip[0], below.tip[1]], -a);
                [p[0], p[1], -a]
            },
        };
        assert_eq!(walked.classify(&turned, a, 0.0), ContactState::Chamfer);
    }

    /// A first touch on the chamfer's upper part, 0.1 mm down it at 5.4 mm (the face turned
    /// 0.5°), is as deep as the face turned 2° could be there; the force on the peg sliding
    /// down the chamfer, (1 − μ)/(1 + μ) = 0.54 across the axis, is outside the face's friction
    /// cone: the chamfer. Pushed straight down it would be taken for the face.
    #[test]
    fn a_force_outside_the_faces_friction_cone_is_not_the_face() {
        let est =
            || Estimator::new(0.0, 0.5e-3, 0.01, 0.3).with_face_turned_up_to(2f64.to_radians());
        let sliding = corner_at(0.0054, 0.5, 0.1e-3, [-0.54, 1.0]);
        assert_eq!(est().classify(&sliding, 0.0, 0.0), ContactState::Chamfer);
        let straight = corner_at(0.0054, 0.5, 0.1e-3, [0.0, 1.0]);
        assert_eq!(est().classify(&straight, 0.0, 0.0), ContactState::Face);
    }

    /// In the bore, 0.72 mm past the chamfer (l < μd), square: a peg squeezed between the
    /// walls holds 1 N along the axis with no lateral force and no moment, which no single
    /// wall contact can (it would need 1/μ_s N across), so it is two-point, and wedged when
    /// stopped; Whitney's balance alone reads no normal force and calls it one-point. One
    /// contact on the left wall at the break-away limit (2 N across, 0.7 N along, the moment
    /// of the friction at the tip's corner) stays one-point.
    #[test]
    fn a_squeeze_the_wrench_cannot_show_is_two_point() {
        let h = 0.5e-3;
        let est = || Estimator::new(0.0, h, 0.01, 0.3).with_static_friction(0.35);
        let tip = [0.0, -(h + 0.72e-3), 0.0];
        let squeezed = Input {
            force: [0.0, 1.0],
            moment_nm: 0.0,
            tip,
        };
        assert_eq!(est().classify(&squeezed, 0.0, 0.0), ContactState::Wedged);
        assert_eq!(est().classify(&squeezed, 0.0, 0.01), ContactState::TwoPoint);
        let (normal, r) = (2.0, 0.005);
        let one = Input {
            force: [normal, 0.35 * normal],
            moment_nm: -r * 0.35 * normal,
            tip,
        };
        assert_eq!(est().classify(&one, 0.0, 0.0), ContactState::OnePoint);
        // Without the break-away friction the same contact is beyond μ's cone.
        let mut kinetic = Estimator::new(0.0, h, 0.01, 0.3);
        assert_ne!(kinetic.classify(&one, 0.0, 0.0), ContactState::OnePoint);
    }
}
