//! The contact state as the controller can know it (docs/insertion.md, *Contact states*): from
//! the wrist's force/torque sensor, the tip's measured depth below the face (whose height the
//! robot knows) and the nominal chamfer, never from the part's true position.
//!
//! * free: the contact force under `free_n` and its moment about the tip under `free_nm`;
//! * face: the point of the tip face the part pushes on (its centre of pressure) at the face
//!   (depth under `face_band_m`);
//! * chamfer: that point between the face and the chamfer's depth;
//! * in the hole, Whitney's balance (docs/insertion.md) with the hole's edge at
//!   l = depth − chamfer depth along the peg gives both contacts' normal forces from the
//!   measured lateral force and moment: two-point when, for one of the two tilts, both press
//!   harder than `two_point_n`; jammed or wedged when two-point and the tip has stopped
//!   (l ≥ μd or l < μd); one-point otherwise.

use super::controller::Input;
use super::plant::ContactState;

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
    /// The filtered force (N) and moment (N·m).
    filtered: ([f64; 2], f64),
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
            free_n: 0.2,
            face_band_m: 20e-6,
            two_point_n: 0.05,
            stopped_m_per_s: 1e-5,
            free_nm: 1e-3,
            filter_s: 2e-3,
            filtered: ([0.0; 2], 0.0),
        }
    }

    /// The filtered force (N) and moment (N·m): its state.
    pub fn filtered(&self) -> ([f64; 2], f64) {
        self.filtered
    }

    /// Carries on from a filtered force and moment ([`Estimator::filtered`]).
    pub fn restore(&mut self, filtered: ([f64; 2], f64)) {
        self.filtered = filtered;
    }

    /// Low-passes one reading (the sensor's moment noise is σ = 0.5 mN·m, a tenth of a newton
    /// at the peg's half-width) and classifies the filtered one. The time constant is
    /// `filter_s`, and at least four ticks: at a real robot's 1 kHz or 500 Hz a 2-ms filter
    /// would pass each reading through whole.
    pub fn update(&mut self, inp: &Input, speed_m_per_s: f64, dt: f64) -> ContactState {
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
        self.classify(&filtered, speed_m_per_s)
    }

    /// The state from one sensor reading and pose, the tip's insertion speed `speed_m_per_s`
    /// (positive going in).
    pub fn classify(&self, inp: &Input, speed_m_per_s: f64) -> ContactState {
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
        let contact_depth = depth - x_c * inp.tip[2].sin();
        if contact_depth < self.face_band_m {
            return ContactState::Face;
        }
        if contact_depth <= self.chamfer_depth_m + self.face_band_m {
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
        if pressed(fx, m) || pressed(-fx, -m) {
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
        let est = Estimator::new(0.0, h, g.peg_width_m, p.mu());
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
            let got = est.classify(&reading(&plant), -truth.velocity[1]);
            assert_eq!(got, truth.state, "estimate at {start:?}");
        }
        let free = Input::default();
        assert_eq!(est.classify(&free, 0.0), ContactState::Free);
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
            est.update(&inp, 0.0, 2e-3);
            last = est.filtered().0[0];
        }
        assert!(last.abs() < 0.2, "{last}");
        assert!(last.abs() > 0.1, "{last}");
    }
}
