//! Whitney's quasi-static conditions for a rigid peg in a rigid hole (Whitney 1982), derived in
//! docs/insertion.md, *Whitney's conditions*: the jamming parallelogram and the wedging limit.
//!
//! Conventions (docs/insertion.md): the hole's axis is y, the peg goes in along −y; the peg's
//! tilt θ is counter-clockwise, so θ > 0 leans its top towards −x and puts its bottom-right
//! corner on the +x wall and its left side on the −x edge (two-point contact). The wrench the
//! wrist applies to the peg is `(F_x, −F_z)` with `F_z > 0` pushing in, and a moment `M` about
//! the centre of the peg's tip, counter-clockwise positive. r = d/2, λ = l/(μd) with l the
//! depth of the edge contact along the peg from its tip.

/// The fit: peg width d, clearance ratio c = (D − d)/D, friction coefficient μ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// Peg width d (m).
    pub peg_width_m: f64,
    /// Clearance ratio c = (D − d)/D.
    pub clearance_ratio: f64,
    /// Coulomb friction coefficient μ at every contact.
    pub friction: f64,
}

impl Fit {
    /// Hole width D = d/(1 − c) (m).
    pub fn hole_width_m(&self) -> f64 {
        self.peg_width_m / (1.0 - self.clearance_ratio)
    }

    /// λ = l/(μd) at edge-contact depth `depth_m`.
    pub fn lambda(&self, depth_m: f64) -> f64 {
        depth_m / (self.friction * self.peg_width_m)
    }

    /// The depth l (along the peg, from its tip) at which a peg tilted by `theta` touches both
    /// walls: `d cos θ + l sin θ = D`. None when it never does (θ = 0) or already does at the
    /// mouth (the peg does not fit at that tilt).
    pub fn two_point_depth_m(&self, theta: f64) -> Option<f64> {
        let (s, c) = theta.abs().sin_cos();
        if s <= 0.0 {
            return None;
        }
        let l = (self.hole_width_m() - self.peg_width_m * c) / s;
        (l > 0.0).then_some(l)
    }

    /// The tilt above which two-point contact forms at a depth l < μd, where the contact
    /// forces can hold each other inside their friction cones (wedging): the root of
    /// `d (cos θ + μ sin θ) = D`, θ_w = atan μ − acos(D / (d √(1 + μ²))) (≈ c/μ).
    pub fn wedging_angle_rad(&self) -> f64 {
        let mu = self.friction;
        let ratio = self.hole_width_m() / (self.peg_width_m * (1.0 + mu * mu).sqrt());
        mu.atan() - ratio.min(1.0).acos()
    }

    /// True when a peg entering at `theta` can wedge: two-point contact at l < μd.
    pub fn wedges(&self, theta: f64) -> bool {
        self.two_point_depth_m(theta)
            .is_some_and(|l| l < self.friction * self.peg_width_m)
    }

    /// True when the applied wrench (`fx_over_fz` = F_x/F_z, `m_over_rfz` = M/(r F_z)) lies
    /// inside Whitney's jamming parallelogram at edge-contact depth `depth_m`: the peg slides
    /// in, in one- or two-point contact; outside, friction holds it (jammed).
    pub fn slides(&self, depth_m: f64, fx_over_fz: f64, m_over_rfz: f64) -> bool {
        let (mu, lambda) = (self.friction, self.lambda(depth_m));
        fx_over_fz.abs() < 1.0 / mu
            && (m_over_rfz + mu * (1.0 + lambda) * fx_over_fz).abs() < lambda
    }

    /// The parallelogram's vertices in the (F_x/F_z, M/(r F_z)) plane at depth `depth_m`,
    /// counter-clockwise from (−1/μ, ·): its sides are F_x/F_z = ±1/μ (one-point contact, the
    /// peg slides along a wall) and M/(r F_z) = ±λ − μ(1 + λ) F_x/F_z (two-point contact).
    pub fn parallelogram(&self, depth_m: f64) -> [[f64; 2]; 4] {
        let (mu, lambda) = (self.friction, self.lambda(depth_m));
        let m = |fx: f64, side: f64| side * lambda - mu * (1.0 + lambda) * fx;
        let x = 1.0 / mu;
        [
            [-x, m(-x, -1.0)],
            [x, m(x, -1.0)],
            [x, m(x, 1.0)],
            [-x, m(-x, 1.0)],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, Vector3};

    fn fit() -> Fit {
        Fit {
            peg_width_m: 0.01,
            clearance_ratio: 0.002,
            friction: 0.3,
        }
    }

    /// The exact quasi-static balance of a peg tilted by θ in two-point contact (θ > 0:
    /// bottom-right corner on the +x wall, left side on the −x edge at depth l along the peg),
    /// both contacts sliding in: the insertion force F_z at which friction just holds the
    /// applied (F_x, M). Unknowns: the edge's normal force f₁ (normal to the peg's side,
    /// friction along it), the corner's f₂ (normal to the wall, friction along it), F_z.
    fn exact_holding_force(f: &Fit, theta: f64, fx: f64, m: f64) -> (f64, f64, f64) {
        let (s, c) = theta.sin_cos();
        let (d, mu) = (f.peg_width_m, f.friction);
        let l = f.two_point_depth_m(theta).unwrap();
        // Peg frame: axis a = (−s, c), side normal n = (c, s); tip centre at the origin.
        let (axis, n) = ([-s, c], [c, s]);
        let edge = [-0.5 * d * n[0] + l * axis[0], -0.5 * d * n[1] + l * axis[1]];
        let corner = [0.5 * d * n[0], 0.5 * d * n[1]];
        // Force on the peg at the edge: f₁ (n + μ a) (normal into the peg, friction up the
        // peg against the insertion); at the corner: f₂ ((−1, 0) + μ (0, 1)).
        let g1 = [n[0] + mu * axis[0], n[1] + mu * axis[1]];
        let g2 = [-1.0, mu];
        let moment = |p: [f64; 2], g: [f64; 2]| p[0] * g[1] - p[1] * g[0];
        // x: F_x + f₁ g1x + f₂ g2x = 0; y: −F_z + f₁ g1y + f₂ g2y = 0; M + Σ moments = 0.
        let a = Matrix3::new(
            g1[0],
            g2[0],
            0.0,
            g1[1],
            g2[1],
            -1.0,
            moment(edge, g1),
            moment(corner, g2),
            0.0,
        );
        let x = a.lu().solve(&Vector3::new(-fx, 0.0, -m)).unwrap();
        (x[0], x[1], x[2])
    }

    /// The parallelogram's two-point sides are the exact balance's small-angle limit: at a
    /// tilt of 0.2° the holding force of the exact geometry is on the side to 1 %, for
    /// lateral forces and moments across the parallelogram with both contacts pressed.
    #[test]
    fn the_two_point_side_is_the_exact_balance() {
        let f = fit();
        let theta = 0.2f64.to_radians();
        let l = f.two_point_depth_m(theta).unwrap();
        let (mu, lambda, r) = (f.friction, f.lambda(l), 0.5 * f.peg_width_m);
        let mut checked = 0;
        for fx in [-1.0, -0.3, 0.0, 0.5, 2.0] {
            for m in [0.0, 0.002, 0.01, 0.05] {
                let (f1, f2, fz) = exact_holding_force(&f, theta, fx, m);
                if f1 <= 0.0 || f2 <= 0.0 {
                    continue;
                }
                // The side: M/r + μ(1 + λ) F_x = λ F_z.
                let side = (m / r + mu * (1.0 + lambda) * fx) / lambda;
                assert!(
                    (fz - side).abs() < 0.01 * fz.abs(),
                    "fx {fx} m {m}: {fz} vs {side}"
                );
                // Just above the holding force the peg slides; just below it jams.
                assert!(f.slides(l, fx / (1.01 * fz), m / (r * 1.01 * fz)) || fx.abs() * mu >= fz);
                assert!(!f.slides(l, fx / (0.99 * fz), m / (r * 0.99 * fz)));
                checked += 1;
            }
        }
        assert!(checked >= 10, "{checked}");
    }

    /// Two-point contact depth and the wedging angle are exact for the geometry: at θ_w the
    /// two-point depth is μd, and θ_w → c/μ as the clearance closes.
    #[test]
    fn wedging_angle_closes_two_point_contact_at_mu_d() {
        let f = fit();
        let w = f.wedging_angle_rad();
        let l = f.two_point_depth_m(w).unwrap();
        assert!((l - f.friction * f.peg_width_m).abs() < 1e-9, "{l}");
        assert!(f.wedges(1.01 * w) && !f.wedges(0.99 * w));
        let tight = Fit {
            clearance_ratio: 1e-5,
            ..f
        };
        let small = tight.wedging_angle_rad() / (1e-5 / 0.3);
        assert!((small - 1.0).abs() < 1e-3, "{small}");
        assert_eq!(f.two_point_depth_m(0.0), None);
    }

    /// The parallelogram's vertices lie on its sides: F_x/F_z = ±1/μ and the two-point lines.
    #[test]
    fn parallelogram_vertices_are_on_its_sides() {
        let f = fit();
        let l = 0.006;
        let (mu, lambda) = (f.friction, f.lambda(l));
        for (i, v) in f.parallelogram(l).iter().enumerate() {
            assert!((v[0].abs() - 1.0 / mu).abs() < 1e-12);
            let side = v[1] + mu * (1.0 + lambda) * v[0];
            assert!((side.abs() - lambda).abs() < 1e-9, "{i}: {side}");
        }
        // Inside: the centre; outside: beyond a two-point side or a one-point side.
        assert!(f.slides(l, 0.0, 0.0));
        assert!(!f.slides(l, 0.0, 1.01 * lambda));
        assert!(!f.slides(l, 1.01 / mu, -mu * (1.0 + lambda) * 1.01 / mu));
    }
}
