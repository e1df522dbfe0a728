//! §5.4's instantaneous centre of rotation on the peg in the hole (docs/insertion-centre.md):
//! rotational dithers of the wrist about three centres, the wrench response to each, and the
//! centre P where the response vanishes; against where the two contact normals meet.
//!
//! The thesis's box (`crate::multicontact`) fits P from the force response alone: its two
//! contact normals are square, so they cannot hold a couple. The peg's two-point contact can
//! (its normals are θ apart), so here the moment is fitted too: the wrench response to a
//! rotation δ about C is `w(C) = B (C − P) δ` with B 3×2, zero only about P.

use crate::insertion::geometry::{Contact, MAX_CORNERS, PegHoleGeometry, contacts, peg_axes};
use crate::insertion::plant::{ContactState, PegParams, PegPlant};
use crate::math::{Vec2, cross};
use crate::multicontact::rotate_about;
use crate::sensor::{SensorModel, SensorParams, Wrench};
use nalgebra::{Matrix3, Matrix3x2, Vector3};

/// The probe's dithers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeParams {
    /// Rotational dither amplitude (rad).
    pub amplitude_rad: f64,
    /// Its frequency (Hz): well below the wrist's 16-Hz mode, the response quasi-static.
    pub frequency_hz: f64,
    /// Whole periods fitted per centre.
    pub periods: usize,
    /// Ramp in and out (s).
    pub ramp_s: f64,
    /// Axial suppression dither amplitude (m), the insertion's.
    pub axial_m: f64,
    /// Its frequency (Hz).
    pub axial_hz: f64,
    /// The dither centres in the peg's frame at the held pose (across, along the axis from the
    /// tip; m); not collinear.
    pub centres_m: [[f64; 2]; 3],
    /// The moment's weight in the fit: newtons at this arm (m).
    pub moment_arm_m: f64,
}

impl Default for ProbeParams {
    fn default() -> Self {
        Self {
            amplitude_rad: 5e-3,
            frequency_hz: 1.0,
            periods: 8,
            ramp_s: 0.1,
            axial_m: 1e-4,
            axial_hz: 20.0,
            centres_m: [[0.0, 0.0], [0.0, 0.01], [0.005, 0.0]],
            moment_arm_m: 0.005,
        }
    }
}

/// Whitney's two-point pose at tilt `theta` > 0 (rad): the peg's right tip corner on the
/// hole's right wall, its left side on the hole's left edge at l = (D − d cos θ)/sin θ from
/// the tip. `None` when the tilt is not positive.
pub fn two_point_pose(g: &PegHoleGeometry, theta: f64) -> Option<[f64; 3]> {
    if !(theta > 0.0 && theta < std::f64::consts::FRAC_PI_2) {
        return None;
    }
    let (d, big_d) = (g.peg_width_m, g.hole_width_m());
    let l = (big_d - d * theta.cos()) / theta.sin();
    let (axis, side) = peg_axes(theta);
    let tip = Vec2::new(-0.5 * big_d, 0.0) + side * (0.5 * d) - axis * l;
    Some([tip.x, tip.y, theta])
}

/// Where the two normals of the two-point pose meet, in closed form (m): the wall's normal
/// is the horizontal line through the tip corner, the edge's the line through the edge along
/// the peg's side direction s, so P = edge + s t with t = y_corner / sin θ, and P is
/// (l cot θ − d) cos θ ≈ l/θ to the left of the edge.
pub fn two_point_centre(g: &PegHoleGeometry, theta: f64) -> Option<Vec2> {
    let pose = two_point_pose(g, theta)?;
    let (_, side) = peg_axes(theta);
    let corner = Vec2::new(pose[0], pose[1]) + side * (0.5 * g.peg_width_m);
    let edge = Vec2::new(-0.5 * g.hole_width_m(), 0.0);
    Some(edge + side * (corner.y / side.y))
}

/// Where the normals of the peg's contacts at `pose` meet (m), with exactly two contacts
/// whose normals are not parallel: the true instantaneous centre of the two-point contact.
pub fn normals_meet(g: &PegHoleGeometry, pose: [f64; 3]) -> Option<Vec2> {
    let profile = g.profile();
    let mut out = [Contact::default(); 4 + MAX_CORNERS];
    if contacts(g, &profile, pose, &mut out) != 2 {
        return None;
    }
    let (a, b) = (out[0], out[1]);
    let det = cross(a.normal, b.normal);
    if det.abs() < 1e-12 {
        return None;
    }
    // a.point + u a.normal = b.point + v b.normal.
    Some(a.point + a.normal * (cross(b.point - a.point, b.normal) / det))
}

/// P from the wrench responses `w` (force N, moment N·m, per rad) to rotational dithers about
/// three `centres`: each component of `w(C) = B C + b` through the three, then the least
/// squares of `B P = −b`, the moment in newtons at `moment_arm_m`. `None` for collinear
/// centres or a response that does not vanish anywhere along a line (B of rank below 2).
pub fn fit_centre(centres: &[Vec2; 3], w: &[[f64; 3]; 3], moment_arm_m: f64) -> Option<Vec2> {
    let c = Matrix3::from_fn(|i, j| match j {
        0 => centres[i].x,
        1 => centres[i].y,
        _ => 1.0,
    });
    let inv = c.try_inverse()?;
    let (mut bm, mut bb) = (Matrix3x2::zeros(), Vector3::zeros());
    for row in 0..3 {
        let scale = if row == 2 { 1.0 / moment_arm_m } else { 1.0 };
        let coef = inv * Vector3::new(w[0][row], w[1][row], w[2][row]) * scale;
        bm[(row, 0)] = coef[0];
        bm[(row, 1)] = coef[1];
        bb[row] = coef[2];
    }
    // A NaN response is no answer (and would panic the SVD's sort).
    if !(bm.iter().chain(bb.iter()).all(|v| v.is_finite())) {
        return None;
    }
    let sv = bm.singular_values();
    if sv.min() <= 1e-6 * sv.max() {
        return None;
    }
    let p = (bm.transpose() * bm).try_inverse()? * (bm.transpose() * -bb);
    (p[0].is_finite() && p[1].is_finite()).then(|| Vec2::new(p[0], p[1]))
}

/// Dithers the wrist's commanded pose about each of `p`'s centres from `hold`, stepping the
/// world every `dt` with `step(target)` (which returns the tared force and moment about the
/// tip), with the axial suppression dither superposed, and fits P.
pub fn probe<S: FnMut([f64; 3]) -> (Vec2, f64)>(
    hold: [f64; 3],
    p: &ProbeParams,
    dt: f64,
    mut step: S,
) -> Option<Vec2> {
    let (axis, side) = peg_axes(hold[2]);
    let tip = Vec2::new(hold[0], hold[1]);
    let centres = p.centres_m.map(|c| tip + side * c[0] + axis * c[1]);
    let omega = std::f64::consts::TAU * p.frequency_hz;
    let total = 2.0 * p.ramp_s + p.periods as f64 / p.frequency_hz;
    let n = (total / dt).round() as usize;
    let mut w = [[0.0; 3]; 3];
    let mut t = 0.0;
    for (k, c) in centres.iter().enumerate() {
        // (time s, phase rad, component) per component.
        let mut rec: [Vec<(f64, f64, f64)>; 3] = Default::default();
        for i in 0..n {
            let tau = i as f64 * dt;
            let ramp = crate::probe::envelope(tau, p.ramp_s, total).0;
            let phase = omega * (tau - p.ramp_s);
            let mut target = rotate_about(hold, *c, ramp * p.amplitude_rad * phase.sin());
            let axial = p.axial_m * (std::f64::consts::TAU * p.axial_hz * t).sin();
            target[0] += axis.x * axial;
            target[1] += axis.y * axial;
            let (f, m) = step(target);
            t += dt;
            if tau >= p.ramp_s && tau <= total - p.ramp_s {
                for (r, v) in rec.iter_mut().zip([f.x, f.y, m]) {
                    r.push((t, phase, v));
                }
            }
        }
        for (wj, r) in w[k].iter_mut().zip(&rec) {
            *wj = crate::tangent::in_phase_amplitude(r, p.axial_hz)? / p.amplitude_rad;
        }
    }
    fit_centre(&centres, &w, p.moment_arm_m)
}

/// One probe of the peg in Whitney's two-point contact at tilt `theta` (rad), held there by
/// the wrist with a moment (20 mN·m by default) towards a larger tilt, sensed by the default sensor at
/// `seed` (σ 0.02 N, 0.5 mN·m, 7 kHz).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoPointProbe {
    /// The true centre, where the contact normals meet after the hold settles (m).
    pub truth: Option<Vec2>,
    /// The probe's estimate (m).
    pub estimate: Option<Vec2>,
    /// The true contact state at the end.
    pub state: ContactState,
}

/// Runs [`TwoPointProbe`] for the peg `params` (its friction law as given),
/// held with `hold_moment_nm` (N·m).
pub fn probe_two_point(
    params: PegParams,
    theta: f64,
    hold_moment_nm: f64,
    seed: u64,
) -> Option<TwoPointProbe> {
    let dt = 1e-4;
    let start = two_point_pose(&params.geometry, theta)?;
    let mut plant = PegPlant::new(params, start);
    let hold = [
        start[0],
        start[1],
        start[2] + hold_moment_nm / params.wrist_stiffness[2],
    ];
    for _ in 0..3000 {
        plant.step(hold, [0.0; 3], dt);
    }
    let truth = normals_meet(&params.geometry, plant.tip_pose());
    let sensor_params = SensorParams::default();
    let mut sensor = SensorModel::new(sensor_params, seed);
    let tare = crate::sim::tare(&mut sensor);
    let (mut next, period, mut time) = (0.0, 1.0 / sensor_params.rate_hz, 0.0);
    let mut reading = Wrench::default();
    let estimate = probe(hold, &ProbeParams::default(), dt, |target| {
        plant.step(target, [0.0; 3], dt);
        time += dt;
        while next <= time {
            let tr = plant.truth();
            let w = Wrench {
                force: tr.force,
                torque: tr.moment_about_tip,
            };
            reading = sensor.sample(w).wrench;
            next += period;
        }
        let tared = reading.tared(tare);
        (tared.force, tared.torque)
    });
    Some(TwoPointProbe {
        truth,
        estimate,
        state: plant.truth().state,
    })
}

#[cfg(test)]
#[path = "centre_tests.rs"]
mod tests;
