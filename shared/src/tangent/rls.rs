//! The recursive form of eq. 5.10: recursive least squares with forgetting on absolute probe
//! directions, for slowly varying slopes ([`TangentRls`]).

use super::*;
use crate::math::{Vec2, perp, unit};
use serde::Serialize;

/// Eq. 5.10's recursive form, as recursive least squares with forgetting on the same model as
/// [`estimate`]: each probe's in-phase normal force f and in-phase tip displacement Δp (world)
/// satisfy `f = −k n·Δp`, linear in the vector `k n` (world frame). The filter tracks `k n`,
/// the tangent is perpendicular to it, and old probes fade with factor λ, so a slowly turning
/// surface is followed without knowing k (stiffness) or any fixed frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TangentRls {
    theta: [f64; 2],
    p: [[f64; 2]; 2],
    p_max: f64,
    forgetting: f64,
    /// Random walk of the tangent angle per update (rad) over the force noise (N), for the
    /// drift form; 0 for exponential forgetting only.
    drift: f64,
    updates: usize,
}

impl TangentRls {
    /// A filter with forgetting factor `forgetting` ∈ [0.5, 1] and initial covariance `p0`,
    /// starting from the normal of `tangent_angle` with stiffness guess `k0` (N/m).
    pub fn new(forgetting: f64, p0: f64, tangent_angle: f64, k0: f64) -> Self {
        let n = perp(unit(tangent_angle)) * k0;
        Self {
            theta: [n.x, n.y],
            p: [[p0, 0.0], [0.0, p0]],
            p_max: 2.0 * p0,
            forgetting: forgetting.clamp(0.5, 1.0),
            drift: 0.0,
            updates: 0,
        }
    }

    /// The drift form: no exponential forgetting; instead, before each update the angle of
    /// `k n` may have moved by a random walk of `angle_drift_rad` (standard deviation per
    /// update), against force noise `force_noise_n` (standard deviation of an in-phase force).
    /// This is a Kalman filter whose process noise lies only along the angle (`q = (k σ_a/σ_f)²`
    /// on the direction perpendicular to `k n`), so the stiffness k keeps its whole history while
    /// the angle follows a turning surface. Exponential forgetting fades k as well, and because
    /// the probes excite the normal direction only weakly (the measured normal motion is a few
    /// percent of the stroke), a forgotten k drags the angle (docs/surface-tracking.md §5).
    pub fn with_drift(
        p0: f64,
        tangent_angle: f64,
        k0: f64,
        angle_drift_rad: f64,
        force_noise_n: f64,
    ) -> Self {
        let mut f = Self::new(1.0, p0, tangent_angle, k0);
        if angle_drift_rad.is_finite() && force_noise_n.is_finite() && force_noise_n > 0.0 {
            f.drift = angle_drift_rad.abs() / force_noise_n;
        }
        f
    }

    /// Adds one probe: in-phase tip displacement (world, m) and in-phase normal force (N).
    pub fn update(&mut self, displacement: Vec2, force_in_phase: f64) {
        if !(displacement.x.is_finite() && displacement.y.is_finite() && force_in_phase.is_finite())
        {
            return;
        }
        if self.drift > 0.0 {
            // Process noise along the angle: the direction perpendicular to k n.
            let k = self.theta[0].hypot(self.theta[1]);
            if k > 0.0 {
                let u = [-self.theta[1] / k, self.theta[0] / k];
                let q = (k * self.drift).powi(2);
                for i in 0..2 {
                    for j in 0..2 {
                        self.p[i][j] += q * u[i] * u[j];
                    }
                }
            }
        }
        let phi = [-displacement.x, -displacement.y];
        let p = self.p;
        let pphi = [
            p[0][0] * phi[0] + p[0][1] * phi[1],
            p[1][0] * phi[0] + p[1][1] * phi[1],
        ];
        let denom = self.forgetting + phi[0] * pphi[0] + phi[1] * pphi[1];
        let gain = [pphi[0] / denom, pphi[1] / denom];
        let err = force_in_phase - (self.theta[0] * phi[0] + self.theta[1] * phi[1]);
        self.theta[0] += gain[0] * err;
        self.theta[1] += gain[1] * err;
        for i in 0..2 {
            for j in 0..2 {
                self.p[i][j] = (p[i][j] - gain[i] * pphi[j]) / self.forgetting;
            }
        }
        // Keep P symmetric (rounding otherwise breaks it and the filter diverges) and bounded
        // (with forgetting, directions the probes do not excite would grow without limit).
        let off = 0.5 * (self.p[0][1] + self.p[1][0]);
        self.p[0][1] = off;
        self.p[1][0] = off;
        let trace = self.p[0][0] + self.p[1][1];
        if trace > self.p_max {
            let k = self.p_max / trace;
            self.p.iter_mut().flatten().for_each(|x| *x *= k);
        }
        self.updates += 1;
    }

    /// Feeds every probe of a record (stats on the estimate's final normal) into the filter.
    pub fn update_from(&mut self, stats: &[ProbeStats], base_angle: f64) {
        let (t, n) = (unit(base_angle), perp(unit(base_angle)));
        for s in stats {
            self.update(
                t * s.displacement_m[0] + n * s.displacement_m[1],
                s.force_in_phase_n,
            );
        }
    }

    /// The tangent angle (rad, world).
    pub fn tangent_angle(&self) -> f64 {
        self.theta[1].atan2(self.theta[0]) - std::f64::consts::FRAC_PI_2
    }

    /// The contact stiffness the filter sees, |k n| (N/m).
    pub fn stiffness(&self) -> f64 {
        self.theta[0].hypot(self.theta[1])
    }

    /// Number of updates.
    pub fn updates(&self) -> usize {
        self.updates
    }
}
