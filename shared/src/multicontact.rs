//! Multiple-point contact (thesis §5.4): a planar box held by the robot and pushed into a
//! corner, its instantaneous centre of rotation P found from rotational dithers, and the
//! friction filter of eqs. 5.11–5.18.
//!
//! * [`BoxPlant`]: the box (x, y, θ) held by a grip of stiffness (k_x, k_y, k_θ) at its centre,
//!   against a floor (y = 0, material below) and a wall (x = 0, material to the left), with
//!   penalty contacts at its vertices and eq. 4.5 friction with presliding at each.
//! * Rotation centre. Rotating the box by dθ about a point C equals rotating it about P plus a
//!   translation `T = dθ J (P − C)` (J: rotation by +90°). The rotation about P is admissible
//!   (the contacts slide along their surfaces); the translation loads the contacts, so the
//!   in-phase force response per radian is `g(C) = −K J (P − C) = (K J) C − K J P`: linear in C,
//!   whatever the 2×2 stiffness K. Three dithers about non-collinear centres give six equations
//!   for the four entries of `A = K J` and the two of `b = −K J P`, and `P = −A⁻¹ b`
//!   ([`rotation_centre`]). Signed (lock-in) responses leave nothing ambiguous.
//! * The thesis works with unsigned RMS values and a diagonal K (eqs. 5.21–5.25): then
//!   `RMS_x(C) ∝ k_x |P_y − C_y|` and `RMS_y(C) ∝ k_y |P_x − C_x|`, and two dithers give each
//!   coordinate of P up to a two-fold ambiguity, the "two roots" of eq. 5.29.
//!   [`thesis_rotation_centre`] takes the four candidates and keeps the one that predicts the
//!   third dither's RMS ratios (the role of the thesis's third dither, eq. 5.30).
//! * [`friction_filter`]: the measured wrench is the normal-force resultant, acting through P,
//!   plus the friction resultant, acting through R (the intersection of the contact tangents).
//!   With moments about R, `M_R = (P − R) × F_N` fixes F_N on a line; friction at a sliding
//!   contact is perpendicular to its normal, so `F_T · F_N = 0` puts F_N on the Thales circle
//!   over F. Two intersections: the physical one has the larger |F_N| (|F_T| < |F_N| when μ < 1).
//!   This is eqs. 5.17–5.18 derived; the printed 5.17 has M² where c² belongs.

use crate::friction::{FrictionLaw, Presliding, PreslidingParams};
use crate::math::{Vec2, cross, perp};
use nalgebra::{Matrix6, Vector6};
use serde::{Deserialize, Serialize};

/// The box and its environment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BoxParams {
    /// Width (along its x) and height (m).
    pub size_m: [f64; 2],
    /// Mass (kg).
    pub mass_kg: f64,
    /// Grip stiffness k_x, k_y (N/m) and k_θ (N·m/rad).
    pub grip_stiffness: [f64; 3],
    /// Grip damping ratio.
    pub grip_damping_ratio: f64,
    /// Contact stiffness of floor and wall (N/m).
    pub contact_stiffness_n_per_m: f64,
    /// Contact damping (N·s/m).
    pub contact_damping_n_s_per_m: f64,
    /// Friction law at each contact at `reference_normal_force_n`.
    pub friction: FrictionLaw,
    /// Normal force at which `friction` holds (N).
    pub reference_normal_force_n: f64,
    /// Presliding.
    pub presliding: PreslidingParams,
}

impl Default for BoxParams {
    fn default() -> Self {
        Self {
            size_m: [0.10, 0.06],
            mass_kg: 0.5,
            grip_stiffness: [5e3, 5e3, 20.0],
            grip_damping_ratio: 0.7,
            contact_stiffness_n_per_m: 1e4,
            contact_damping_n_s_per_m: 20.0,
            friction: FrictionLaw {
                kinetic_n: 0.3,
                viscous_n_s_per_m: 0.0,
                stribeck_n: 0.1,
                stribeck_velocity_m_per_s: 0.01,
            },
            reference_normal_force_n: 1.0,
            presliding: PreslidingParams::default(),
        }
    }
}

/// A planar pose (m, m, rad).
pub type Pose = [f64; 3];

/// What is true about the box at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct BoxTruth {
    /// Pose of the box centre.
    pub pose: Pose,
    /// Total contact force on the box (N).
    pub force: Vec2,
    /// Moment of the contact forces about the box centre (N·m).
    pub moment: f64,
    /// Sum of the normal forces (N) and of the friction forces (N) as vectors.
    pub normal_resultant: Vec2,
    /// Friction resultant (N).
    pub friction_resultant: Vec2,
    /// Number of vertex contacts on the floor and on the wall.
    pub contacts: [usize; 2],
    /// The true instantaneous centre of rotation, when one floor and one wall contact exist.
    pub rotation_centre: Option<Vec2>,
}

/// The box in the corner.
#[derive(Debug, Clone)]
pub struct BoxPlant {
    params: BoxParams,
    pose: Pose,
    vel: [f64; 3],
    bristles: [Presliding; 8],
    truth: BoxTruth,
}

/// Vertices of the box in its own frame (bottom-left, bottom-right, top-right, top-left).
fn corners_body(size: [f64; 2]) -> [Vec2; 4] {
    let (a, b) = (0.5 * size[0], 0.5 * size[1]);
    [
        Vec2::new(-a, -b),
        Vec2::new(a, -b),
        Vec2::new(a, b),
        Vec2::new(-a, b),
    ]
}

/// World position of a body-frame point at `pose`.
pub fn to_world(pose: &Pose, p: Vec2) -> Vec2 {
    let (s, c) = pose[2].sin_cos();
    Vec2::new(pose[0] + c * p.x - s * p.y, pose[1] + s * p.x + c * p.y)
}

impl BoxPlant {
    /// The box at `pose`, at rest.
    pub fn new(params: BoxParams, pose: Pose) -> Self {
        let mut b = Self {
            params,
            pose,
            vel: [0.0; 3],
            bristles: [Presliding::default(); 8],
            truth: BoxTruth::default(),
        };
        b.truth = b.contact_state(0.0).0;
        b
    }

    /// The pose at which, tilted by θ ∈ (0, 90°), the bottom-left vertex touches the floor and
    /// the top-left vertex the wall, both with zero penetration.
    pub fn touching_pose(params: &BoxParams, theta: f64) -> Pose {
        let v = corners_body(params.size_m);
        let (s, c) = theta.sin_cos();
        // x of top-left = 0, y of bottom-left = 0.
        let x = -(c * v[3].x - s * v[3].y);
        let y = -(s * v[0].x + c * v[0].y);
        [x, y, theta]
    }

    /// Parameters.
    pub fn params(&self) -> &BoxParams {
        &self.params
    }

    /// Truth of the last step.
    pub fn truth(&self) -> &BoxTruth {
        &self.truth
    }

    /// The box's pose.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    fn contact_state(&mut self, dt: f64) -> (BoxTruth, [f64; 3]) {
        let p = self.params;
        let verts = corners_body(p.size_m);
        let (mut f, mut m) = (Vec2::zeros(), 0.0);
        let (mut fn_sum, mut ft_sum) = (Vec2::zeros(), Vec2::zeros());
        let mut counts = [0usize; 2];
        let mut floor_pt = None;
        let mut wall_pt = None;
        let centre = Vec2::new(self.pose[0], self.pose[1]);
        for (i, v) in verts.iter().enumerate() {
            let w = to_world(&self.pose, *v);
            let r = w - centre;
            let vel = Vec2::new(
                self.vel[0] - self.vel[2] * r.y,
                self.vel[1] + self.vel[2] * r.x,
            );
            // Floor (normal +y, tangent +x) and wall (normal +x, tangent −y).
            for (k, (depth, normal)) in [(-w.y, Vec2::new(0.0, 1.0)), (-w.x, Vec2::new(1.0, 0.0))]
                .into_iter()
                .enumerate()
            {
                let slot = 2 * i + k;
                if depth <= 0.0 {
                    self.bristles[slot].reset();
                    continue;
                }
                let rate = -vel.dot(&normal);
                let fnorm = (p.contact_stiffness_n_per_m * depth
                    + p.contact_damping_n_s_per_m * rate)
                    .max(0.0);
                let tangent = -perp(normal);
                let fr = if fnorm > 0.0 && dt > 0.0 {
                    let law = p.friction.scaled(fnorm / p.reference_normal_force_n);
                    self.bristles[slot].step(&law, &p.presliding, vel.dot(&tangent), dt)
                } else {
                    p.presliding.stiffness_n_per_m * self.bristles[slot].deflection_m
                };
                let fc = normal * fnorm - tangent * fr;
                f += fc;
                m += cross(r, fc);
                fn_sum += normal * fnorm;
                ft_sum += -tangent * fr;
                if fnorm > 0.0 {
                    counts[k] += 1;
                    if k == 0 {
                        floor_pt = Some(w);
                    } else {
                        wall_pt = Some(w);
                    }
                }
            }
        }
        let rotation_centre = match (floor_pt, wall_pt) {
            (Some(a), Some(b)) if counts == [1, 1] => Some(Vec2::new(a.x, b.y)),
            _ => None,
        };
        let truth = BoxTruth {
            pose: self.pose,
            force: f,
            moment: m,
            normal_resultant: fn_sum,
            friction_resultant: ft_sum,
            contacts: counts,
            rotation_centre,
        };
        (truth, [f.x, f.y, m])
    }

    /// Advances by `dt` with the grip commanding `target` pose and `target_vel`.
    pub fn step(&mut self, target: Pose, target_vel: [f64; 3], dt: f64) {
        let p = self.params;
        let (truth, contact) = self.contact_state(dt);
        let inertia = p.mass_kg * (p.size_m[0].powi(2) + p.size_m[1].powi(2)) / 12.0;
        let mass = [p.mass_kg, p.mass_kg, inertia];
        for k in 0..3 {
            let kk = p.grip_stiffness[k];
            let c = 2.0 * p.grip_damping_ratio * (kk * mass[k]).sqrt();
            let grip = kk * (target[k] - self.pose[k]) + c * (target_vel[k] - self.vel[k]);
            self.vel[k] += (grip + contact[k]) / mass[k] * dt;
        }
        for k in 0..3 {
            self.pose[k] += self.vel[k] * dt;
        }
        self.truth = truth;
    }
}

/// A commanded pose rotated by `angle` (rad) about `centre` (m).
pub fn rotate_about(pose: Pose, centre: Vec2, angle: f64) -> Pose {
    let (s, c) = angle.sin_cos();
    let d = Vec2::new(pose[0], pose[1]) - centre;
    [
        centre.x + c * d.x - s * d.y,
        centre.y + s * d.x + c * d.y,
        pose[2] + angle,
    ]
}

/// P from the in-phase force responses per radian `g_i` of rotational dithers about centres
/// `c_i` (at least three, not collinear): least squares of `g = A c + b`, then `P = −A⁻¹ b`.
pub fn rotation_centre(centres: &[Vec2], responses: &[Vec2]) -> Option<Vec2> {
    response_fit(centres, responses).map(|f| f.0)
}

/// [`rotation_centre`] with the fitted response matrix `A = ∂g/∂c = K J` (N/m per rad): under
/// the thesis's diagonal stiffness (eqs. 5.19–5.20) its diagonal entries are zero.
pub fn response_fit(
    centres: &[Vec2],
    responses: &[Vec2],
) -> Option<(Vec2, nalgebra::Matrix2<f64>)> {
    let n = centres.len().min(responses.len());
    if n < 3 {
        return None;
    }
    // Unknowns (A11, A12, A21, A22, b1, b2).
    let mut ata = Matrix6::<f64>::zeros();
    let mut atb = Vector6::<f64>::zeros();
    for k in 0..n {
        let c = centres[k];
        let rows = [
            Vector6::new(c.x, c.y, 0.0, 0.0, 1.0, 0.0),
            Vector6::new(0.0, 0.0, c.x, c.y, 0.0, 1.0),
        ];
        for (row, g) in rows.iter().zip([responses[k].x, responses[k].y]) {
            ata += row * row.transpose();
            atb += row * g;
        }
    }
    let x = ata.lu().solve(&atb)?;
    let a = nalgebra::Matrix2::new(x[0], x[1], x[2], x[3]);
    let b = Vec2::new(x[4], x[5]);
    let p = -(a.try_inverse()? * b);
    (p.x.is_finite() && p.y.is_finite()).then_some((p, a))
}

/// A rotation-centre estimate from raw dither records.
#[derive(Debug, Clone, PartialEq)]
pub struct RotationEstimate {
    /// P from the signed responses (m).
    pub centre: Vec2,
    /// The thesis's unsigned form on the first three dithers, if it found a centre (m).
    pub thesis_centre: Option<Vec2>,
    /// Fitted response matrix A = ∂g/∂c.
    pub response_matrix: nalgebra::Matrix2<f64>,
    /// |diagonal| / |off-diagonal| of A.
    pub coupling: f64,
    /// In-phase force response per radian of each dither (N/rad).
    pub responses: Vec<Vec2>,
}

/// Estimates P from rotational dithers about `centres`: `samples` are (dither index, time s,
/// dither phase rad, measured force N), the commanded rotation about centre i being
/// `amplitude sin φ`. A superposed suppression dither at `suppression_hz` (0: none) is removed
/// by a one-period comb before the lock-in. `None` with fewer than three usable dithers or a
/// singular fit.
pub fn estimate_rotation_centre(
    centres: &[Vec2],
    samples: &[(usize, f64, f64, Vec2)],
    amplitude: f64,
    suppression_hz: f64,
) -> Option<RotationEstimate> {
    if centres.len() < 3 || !(amplitude.is_finite() && amplitude > 0.0) {
        return None;
    }
    let mut responses = Vec::with_capacity(centres.len());
    for k in 0..centres.len() {
        let mine: Vec<&(usize, f64, f64, Vec2)> = samples.iter().filter(|s| s.0 == k).collect();
        let comp = |sel: fn(&Vec2) -> f64| -> Option<f64> {
            let d: Vec<(f64, f64, f64)> = mine.iter().map(|s| (s.1, s.2, sel(&s.3))).collect();
            if d.len() < 16 {
                return None;
            }
            crate::tangent::in_phase_amplitude(&d, suppression_hz)
        };
        let g = Vec2::new(comp(|f| f.x)?, comp(|f| f.y)?) / amplitude;
        if !(g.x.is_finite() && g.y.is_finite()) {
            return None;
        }
        responses.push(g);
    }
    let (centre, a) = response_fit(centres, &responses)?;
    let rms = [0, 1, 2].map(|k| {
        [
            responses[k].x.abs() * amplitude,
            responses[k].y.abs() * amplitude,
        ]
    });
    let thesis_centre = thesis_rotation_centre(centres[0], centres[1], centres[2], rms);
    let coupling = a[(0, 0)].hypot(a[(1, 1)]) / a[(0, 1)].hypot(a[(1, 0)]);
    Some(RotationEstimate {
        centre,
        thesis_centre,
        response_matrix: a,
        coupling,
        responses,
    })
}

/// The thesis's unsigned form (eqs. 5.21–5.30, diagonal stiffness): from the RMS force
/// responses (x, y components) of dithers about `c0`, `c1 = c0 + m u` and `c2`, return the
/// centre among the four sign choices of `(P − c0)_y = m u_y / (1 ∓ r_x)`,
/// `(P − c0)_x = m u_x / (1 ∓ r_y)` whose predicted ratios at `c2` best match the measured ones.
pub fn thesis_rotation_centre(c0: Vec2, c1: Vec2, c2: Vec2, rms: [[f64; 2]; 3]) -> Option<Vec2> {
    let d = c1 - c0;
    let rx = rms[1][0] / rms[0][0];
    let ry = rms[1][1] / rms[0][1];
    if !(rx.is_finite() && ry.is_finite()) {
        return None;
    }
    let mut best: Option<(f64, Vec2)> = None;
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            // |Δy − d_y| = r_x |Δy|  →  Δy = d_y / (1 − s r_x);  likewise for x with r_y.
            let (den_y, den_x) = (1.0 - sx * rx, 1.0 - sy * ry);
            if den_y.abs() < 1e-9 || den_x.abs() < 1e-9 {
                continue;
            }
            let delta = Vec2::new(d.x / den_x, d.y / den_y);
            let p = c0 + delta;
            // Predicted ratios at c2: |P_y − c2_y| / |P_y − c0_y| and the same in x.
            let pred = [
                ((p.y - c2.y) / delta.y).abs(),
                ((p.x - c2.x) / delta.x).abs(),
            ];
            let meas = [rms[2][0] / rms[0][0], rms[2][1] / rms[0][1]];
            let err = (pred[0] - meas[0]).powi(2) + (pred[1] - meas[1]).powi(2);
            if best.is_none_or(|(e, _)| err < e) {
                best = Some((err, p));
            }
        }
    }
    best.map(|b| b.1)
}

/// The friction filter (eqs. 5.11–5.18, derived): splits the measured force `f` with moment
/// `moment_r` about R into the normal resultant through P and the friction resultant through R,
/// assuming friction perpendicular to the normal resultant. `p_rel = P − R`. Returns
/// (F_N, F_T), or `None` when the wrench is inconsistent with a centre at P.
pub fn friction_filter(f: Vec2, moment_r: f64, p_rel: Vec2) -> Option<(Vec2, Vec2)> {
    // F_N on the line p_rel × F_N = M_R: F_N = F0 + s d, d = p_rel / |p_rel|,
    // F0 = M_R J p_rel / |p_rel|² (J p_rel = perp(p_rel)); then F_N · (F − F_N) = 0.
    let l2 = p_rel.norm_squared();
    if l2 <= 0.0 {
        return None;
    }
    let d = p_rel / l2.sqrt();
    let f0 = perp(p_rel) * (moment_r / l2);
    // (f0 + s d)·(f − f0 − s d) = 0 → −s² + s (d·f − 2 d·f0) + f0·(f − f0) = 0.
    let b = d.dot(&f) - 2.0 * d.dot(&f0);
    let c = f0.dot(&(f - f0));
    let disc = b * b + 4.0 * c;
    if disc < 0.0 {
        return None;
    }
    let roots = [0.5 * (b + disc.sqrt()), 0.5 * (b - disc.sqrt())];
    let candidates = roots.map(|s| f0 + d * s);
    let fnorm = if candidates[0].norm() >= candidates[1].norm() {
        candidates[0]
    } else {
        candidates[1]
    };
    Some((fnorm, f - fnorm))
}

/// Eq. 5.29 with tan β where the thesis writes β: the two roots tan θ̄ of
/// `r = tan θ̄ / tan(θ̄ + β)` (eq. 5.28), i.e. of `tan β · T² + (r − 1) T + r tan β = 0`.
/// Their product is r: the second root is `cot(θ̄ + β) = tan(90° − β − θ̄)`, the mirror of the
/// true θ̄ about 45° − β/2, so two dithers cannot tell them apart. `None` when the
/// discriminant is negative (no θ̄ gives this r) or β = 0.
pub fn eq_5_29_roots(r: f64, tan_beta: f64) -> Option<[f64; 2]> {
    let disc = (r - 1.0).powi(2) - 4.0 * tan_beta * tan_beta * r;
    if tan_beta == 0.0 || disc.is_nan() || disc < 0.0 {
        return None;
    }
    let q = disc.sqrt();
    Some([
        ((1.0 - r) + q) / (2.0 * tan_beta),
        ((1.0 - r) - q) / (2.0 * tan_beta),
    ])
}

#[cfg(test)]
#[path = "multicontact_tests.rs"]
mod tests;
