//! The part's face as the find phase finds it (docs/insertion-frame.md, *The face.s tangent from the corner*): the
//! robot does not know the part's orientation, so it estimates the face's tangent from where
//! the part touches the peg.
//!
//! Pressed on the face, the part touches the peg's tip face: at one corner, at two (flat), or
//! at a corner and the hole's edge. Whichever, the contact force's line of action meets the tip
//! face at the centre of pressure c = tip + s e, e = (cos θ, sin θ) the tip face's direction,
//! and with the moment about the tip M = s (e × F), `s = M / (F_y cos θ − F_x sin θ)`: the same
//! measurement §5.4's friction filter starts from. Every such point lies on the face (to the
//! contacts' µm penetration), so as the walk and the dither move the contact along the face the
//! points trace its line, and the line's direction is the tangent, whatever the friction does
//! (a corner that sticks adds the same point again, never a wrong one). The line is the total
//! least squares fit of the points (the principal axis of their scatter), kept as running sums
//! (no allocation); the wrench is low-passed first (the sensor's noise moves s along the tip
//! face, which is the face's direction only when the peg is already square). Once the line is
//! long enough (its spread along the face) and thin enough (across it), its angle is the
//! estimate; a point farther than `outlier_m` from it (the chamfer, the peg's side) is left out.

use serde::{Deserialize, Serialize};

/// Settings of the face's tangent estimate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FaceParams {
    /// Whether to estimate the face's tangent (the part's orientation unknown); otherwise it
    /// is the robot's belief throughout.
    pub estimate: bool,
    /// Time constant of the wrench's low-pass (s).
    pub filter_s: f64,
    /// The points' spread along the line (standard deviation) before it is believed (m).
    pub least_spread_m: f64,
    /// The largest spread across the line relative to the spread along it.
    pub largest_thickness: f64,
    /// A point farther than this from a believed line is not the face (m).
    pub outlier_m: f64,
    /// Least force along the peg's axis for a point (N).
    pub least_force_n: f64,
    /// A centre of pressure this far out of the half-width, or farther, is at the corner.
    pub corner_fraction: f64,
    /// The largest slope of the centre of pressure's offset from the corner against the
    /// points' x (1 for the hole's edge under the tip face, 0 for a corner).
    pub largest_slip: f64,
    /// The most the face can be turned from the robot's belief (degrees): a line turned more
    /// is another feature's (the chamfer's, 45°).
    pub largest_turn_deg: f64,
    /// The least tilt of the tip face against the line, down towards the touching corner
    /// (degrees): a corner resting on the face has the rest of the tip face above the face's
    /// line; the hole's edge under the tip face traces the peg's own direction instead.
    pub least_tilt_deg: f64,
    /// The most the face may be turned from the robot's belief before its line is believed
    /// (degrees): the part's orientation's uncertainty (0 for a part whose orientation is
    /// known). A peg square to the robot's belief is turned as much against the hole.
    pub prior_error_deg: f64,
}

impl Default for FaceParams {
    fn default() -> Self {
        Self {
            estimate: false,
            filter_s: 5e-3,
            least_spread_m: 0.1e-3,
            largest_thickness: 0.003,
            outlier_m: 30e-6,
            least_force_n: 0.5,
            corner_fraction: 0.8,
            largest_turn_deg: 5.0,
            largest_slip: 0.3,
            least_tilt_deg: 0.15,
            prior_error_deg: 0.0,
        }
    }
}

/// The estimate's running state (what a restarted servo needs).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FaceState {
    /// The face's tangent angle in the robot's frame (rad): the robot's belief until the line
    /// is believed.
    pub angle_rad: f64,
    /// True once the points make a line.
    pub believed: bool,
    /// The low-passed force (N, robot frame) and moment about the tip (N·m).
    pub wrench: [f64; 3],
    /// The points' sums: n, Σx, Σy, Σx², Σxy, Σy² (m, m²), about the first point; then Σs,
    /// Σxs (m, m²) of the centre of pressure's offset s from the corner.
    pub sums: [f64; 8],
    /// The first point (m), the sums' origin.
    pub origin: [f64; 2],
}

/// The face's tangent estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceProbe {
    params: FaceParams,
    state: FaceState,
    prior_rad: f64,
    half_width_m: f64,
}

impl FaceProbe {
    /// An estimate for a peg `width_m` wide, starting from the tangent at `angle_rad` (the
    /// robot's belief).
    pub fn new(params: FaceParams, width_m: f64, angle_rad: f64) -> Self {
        Self {
            params,
            state: FaceState {
                angle_rad,
                ..FaceState::default()
            },
            prior_rad: angle_rad,
            half_width_m: 0.5 * width_m,
        }
    }

    /// The face's estimated tangent angle in the robot's frame (rad).
    pub fn angle(&self) -> f64 {
        self.state.angle_rad
    }

    /// True once the points make a line.
    pub fn believed(&self) -> bool {
        self.state.believed
    }

    /// The state, for a restarted servo.
    pub fn state(&self) -> FaceState {
        self.state
    }

    /// Carries on from `s`.
    pub fn restore(&mut self, s: &FaceState) {
        self.state = *s;
    }

    /// One sample while pressed on the part: the contact force on the peg (N) and its moment
    /// about the tip (N·m), the tip's pose (m, m, rad), all in the robot's frame.
    pub fn sample(&mut self, force: [f64; 2], moment_nm: f64, tip: [f64; 3], dt: f64) {
        let p = self.params;
        let a = (dt / p.filter_s.max(dt)).clamp(0.0, 1.0);
        let w = &mut self.state.wrench;
        for (x, v) in w.iter_mut().zip([force[0], force[1], moment_nm]) {
            *x += a * (v - *x);
        }
        let (s_th, c_th) = tip[2].sin_cos();
        let along = w[1] * c_th - w[0] * s_th;
        if along < p.least_force_n {
            return;
        }
        // A corner: the centre of pressure at the tip face's end, where a tilted peg rests.
        // Elsewhere (flat, or on the hole's edge) the point's noise runs along the tip face,
        // which would pull the line towards the peg's own tilt: left out.
        let s = w[2] / along;
        let out = s.abs() / self.half_width_m;
        if out < p.corner_fraction || out > 2.0 - p.corner_fraction {
            return;
        }
        let offset = s - self.half_width_m.copysign(s);
        let s = self.half_width_m.copysign(s);
        let point = [tip[0] + s * c_th, tip[1] + s * s_th];
        if !(point[0].is_finite() && point[1].is_finite()) {
            return;
        }
        if self.state.believed && self.distance(point) > p.outlier_m {
            return;
        }

        let st = &mut self.state;
        if st.sums[0] == 0.0 {
            st.origin = point;
        }
        let (x, y) = (point[0] - st.origin[0], point[1] - st.origin[1]);
        let terms = [1.0, x, y, x * x, x * y, y * y, offset, x * offset];
        for (sum, v) in st.sums.iter_mut().zip(terms) {
            *sum += v;
        }
        self.fit(tip[2], s.signum());
    }

    /// The line through the points, if it is long and thin enough and the tip face, at
    /// `tilt_rad` with its touching corner on the `side` (±1) of the tip, can rest on it at
    /// that corner: its angle becomes the estimate.
    fn fit(&mut self, tilt_rad: f64, side: f64) {
        let p = self.params;
        let [n, sx, sy, sxx, sxy, syy, ss, sxs] = self.state.sums;
        let (mx, my) = (sx / n, sy / n);
        let (cxx, cxy, cyy) = (sxx / n - mx * mx, sxy / n - mx * my, syy / n - my * my);
        // The scatter's eigenvalues: along (λ1) and across (λ2) the principal axis.
        let mean = 0.5 * (cxx + cyy);
        let half = (0.25 * (cxx - cyy).powi(2) + cxy * cxy).sqrt();
        let (along, across) = (mean + half, (mean - half).max(0.0));
        if along.sqrt() < p.least_spread_m {
            return;
        }
        // A corner on the face stays at the tip face's end as the peg moves; the hole's edge
        // under the tip face near its end stays where it is on the part, so its s runs
        // against the peg's motion (slope −1 on x): not a corner.
        let slope = (sxs / n - mx * ss / n) / cxx.max(f64::MIN_POSITIVE);
        if slope.abs() > p.largest_slip {
            self.state.sums = [0.0; 8];
            return;
        }
        if across > p.largest_thickness.powi(2) * along {
            // Not one line (the face and the chamfer, say): start again from here.
            self.state.sums = [0.0; 8];
            return;
        }
        // The principal axis's angle, taken within ±90° of the robot's belief.
        let mut angle = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
        let half_turn = std::f64::consts::PI;
        while angle - self.prior_rad > 0.5 * half_turn {
            angle -= half_turn;
        }
        while angle - self.prior_rad <= -0.5 * half_turn {
            angle += half_turn;
        }
        if (angle - self.prior_rad).abs() > p.largest_turn_deg.to_radians() {
            // Farther from the belief than the part can be turned: the chamfer's line.
            self.state.sums = [0.0; 8];
            return;
        }
        // The other corner is above the line only if the tip face turns down towards the
        // touching one: side · (angle − tilt) > 0. The hole's edge under the tip face near
        // its end, which the slope test can miss over a short walk (the centre of pressure's
        // noise), traces a line along the peg (seed 406 of the default sweep, 2.08° from the
        // face). Not a reason to start again: the line may yet grow into the face's.
        if side * (angle - tilt_rad) < p.least_tilt_deg.to_radians() {
            return;
        }
        self.state.angle_rad = angle;
        self.state.believed = true;
    }

    /// The distance of `point` from the believed line (m).
    fn distance(&self, point: [f64; 2]) -> f64 {
        let [n, sx, sy, ..] = self.state.sums;
        let centre = [self.state.origin[0] + sx / n, self.state.origin[1] + sy / n];
        let (s, c) = self.state.angle_rad.sin_cos();
        (-s * (point[0] - centre[0]) + c * (point[1] - centre[1])).abs()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const WIDTH: f64 = 0.01;

    /// A probe estimating, the robot's belief 0.
    fn probe() -> FaceProbe {
        FaceProbe::new(
            FaceParams {
                estimate: true,
                ..FaceParams::default()
            },
            WIDTH,
            0.0,
        )
    }

    /// Feeds the estimate a peg tilted by `tilt` against a face at `face_angle` (robot frame)
    /// while its tip moves 1 mm: the part touches the tip face at `contact(u)` (on the face, m,
    /// u the distance moved), at `s(u)` from the tip along the tip face, with 1 N along the
    /// face's normal and `friction` N along it, and deterministic noise of ±0.02 N on the force
    /// and ±0.5 mN·m at 20 Hz on the moment (the sensor's noise as the dither moves it).
    fn fed(
        face_angle: f64,
        tilt: f64,
        contact: impl Fn(f64) -> f64,
        s: impl Fn(f64) -> f64,
        friction: f64,
    ) -> FaceProbe {
        let mut f = probe();
        let (t, n) = (
            [face_angle.cos(), face_angle.sin()],
            [-face_angle.sin(), face_angle.cos()],
        );
        let e = [(face_angle + tilt).cos(), (face_angle + tilt).sin()];
        let dt = 1e-4;
        for k in 0..20_000 {
            let u = 1e-3 * f64::from(k) / 20_000.0;
            let noise = (f64::from(k) * 0.7).sin();
            let true_force = [n[0] + friction * t[0], n[1] + friction * t[1]];
            let (c, s) = (contact(u), s(u));
            let tip = [c * t[0] - s * e[0], c * t[1] - s * e[1], face_angle + tilt];
            let moment = s * (e[0] * true_force[1] - e[1] * true_force[0]);
            let force = [true_force[0] + 0.02 * noise, true_force[1] - 0.02 * noise];
            f.sample(force, moment + 5e-4 * (f64::from(k) * 0.013).cos(), tip, dt);
        }
        f
    }

    /// A corner sliding on a face turned 1.5° from the robot's belief: the line it traces is
    /// the face, to a thousandth of a degree, whatever the friction along it.
    #[test]
    fn a_corner_sliding_on_the_face_traces_its_tangent() {
        let alpha = 1.5f64.to_radians();
        for (tilt_deg, friction) in [(-1.0f64, 0.3), (1.0, -0.3), (-2.0, 0.0)] {
            let corner = -(0.5 * WIDTH).copysign(tilt_deg);
            let f = fed(alpha, tilt_deg.to_radians(), |u| u, |_| corner, friction);
            assert!(f.believed(), "{tilt_deg}");
            let err = (f.angle() - alpha).to_degrees();
            assert!(err.abs() < 1e-3, "{tilt_deg}°: {err}°");
        }
    }

    /// The hole's edge under the tip face near its end stays where it is as the peg slides:
    /// the centre of pressure runs along the tip face, not with it, and the line the corner
    /// would trace (the peg's own direction) is not believed.
    #[test]
    fn the_holes_edge_near_the_corner_is_not_a_corner() {
        let alpha = 1.5f64.to_radians();
        // The contact fixed on the part; the tip moves u away from it: s = 4.5 mm + u.
        let f = fed(alpha, 1f64.to_radians(), |_| 0.0, |u| 4.5e-3 + u, 0.3);
        assert!(!f.believed(), "{}°", f.angle().to_degrees());
    }

    /// The hole's edge under the tip face, its centre of pressure's slope hidden by noise
    /// (here it stays 0.4 mm inside the corner, as a slope of 0 would have it): the snapped
    /// corner moves with the peg, along the tip face, and the line it traces is the peg's
    /// direction, on which the rest of the tip face cannot rest. Not believed (without the
    /// tilt test: believed at the peg's angle, 1° from the face).
    #[test]
    fn a_line_along_the_peg_is_not_the_face() {
        let (alpha, tilt) = (0.5f64.to_radians(), -1f64.to_radians());
        let mut f = probe();
        let theta = alpha + tilt;
        let (e, n) = ([theta.cos(), theta.sin()], [-alpha.sin(), alpha.cos()]);
        let s = 0.5 * WIDTH - 0.4e-3;
        for k in 0..20_000 {
            let u = 1e-3 * f64::from(k) / 20_000.0;
            let tip = [-u * e[0], -u * e[1], theta];
            let moment = s * (e[0] * n[1] - e[1] * n[0]);
            f.sample(n, moment, tip, 1e-4);
        }
        assert!(!f.believed(), "{}°", f.angle().to_degrees());
    }

    /// A line turned more than the part can be (the chamfer's 45°) and a peg flat on the face
    /// (the centre of pressure mid-face) give no estimate.
    #[test]
    fn the_chamfer_and_a_flat_peg_give_no_estimate() {
        let chamfer = fed(
            -45f64.to_radians(),
            -1f64.to_radians(),
            |u| u,
            |_| 0.5 * WIDTH,
            0.3,
        );
        assert!(!chamfer.believed());
        assert_eq!(chamfer.angle(), 0.0);
        let flat = fed(0.5f64.to_radians(), 0.0, |u| u, |_| 1e-3, 0.3);
        assert!(!flat.believed());
    }
}
