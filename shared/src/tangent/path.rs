//! The tangent from the tip's path ([`tip_path`]): the estimator's answer where the force
//! response is too small to regress, on a contact much stiffer than the servo.

use super::*;
use crate::math::{perp, unit};

/// Range of the slope `b` of the path's direction against the stroke's (see [`tip_path`]) the
/// estimator answers from: the contact holds the tip within 0.5 % of the strokes' normal part,
/// so the path is the surface (a contact of ≳ 4e5 N/m on the default arm: on 1 MN/m at 1 kHz
/// b = −1e-5 … 3e-4; on 100 kN/m at 1 kHz b = 0.02, and there the path's answer at α0 = 15°
/// was 0.64° off, its residual blind to it); a slightly negative slope is a zero one in noise.
pub const TIP_PATH_SLOPES: std::ops::RangeInclusive<f64> = -0.005..=0.005;

/// The tip's path over the probes, fitted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipPath {
    /// α0 = estimated − true tangent angle (rad).
    pub alpha0_rad: f64,
    /// The slope b: how much of the stroke's normal part the tip follows.
    pub slope: f64,
    /// Standard error of α0 from the fit's residual (rad); None with two probes (no residual).
    pub std_error_rad: Option<f64>,
}

/// The tangent from the direction of the tip's in-phase motion. Probe i strokes along δα_i off
/// t̂; the tip moves by (x_i, y_i) along (t̂, n̂), at the angle ψ_i = atan2(y_i, x_i) off t̂.
/// The true tangent lies at −α0 off t̂; the stroke's part along the true normal,
/// `A sin(δα_i + α0)`, becomes a penetration that the contact, the servo and the force loop
/// share out, a fraction of it the same for every probe, while friction shortens the travel
/// x_i alike, so that to first order in the angles
///
///     ψ_i = −α0 + b (δα_i + α0) = a + b δα_i,      α0 = −a/(1 − b),
///
/// with b the penetration's share over the travel's: a straight line in δα, fitted by least
/// squares. On a stiff contact b ≈ 0 and the path is the surface. None when a probe did not
/// move forward along t̂ or b lies outside [`TIP_PATH_SLOPES`] (docs/surface-tracking.md, §4).
pub fn tip_path(stats: &[ProbeStats]) -> Option<TipPath> {
    if stats.len() < 2
        || stats
            .iter()
            .any(|s| s.displacement_m[0].is_nan() || s.displacement_m[0] <= 0.0)
    {
        return None;
    }
    let n = stats.len() as f64;
    let psi = |s: &ProbeStats| s.displacement_m[1].atan2(s.displacement_m[0]);
    let (mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0);
    for s in stats {
        let (d, p) = (s.offset_rad, psi(s));
        sx += d;
        sy += p;
        sxx += d * d;
        sxy += d * p;
    }
    let det = n * sxx - sx * sx;
    if det.is_nan() || det <= 1e-12 {
        return None;
    }
    let b = (n * sxy - sx * sy) / det;
    let a = (sy - b * sx) / n;
    if !TIP_PATH_SLOPES.contains(&b) {
        return None;
    }
    let alpha0_rad = -a / (1.0 - b);
    let std_error_rad = (stats.len() > 2).then(|| {
        let sse: f64 = stats
            .iter()
            .map(|s| (psi(s) - a - b * s.offset_rad).powi(2))
            .sum();
        let var = sse / (n - 2.0);
        let (var_a, var_b, cov) = (var * sxx / det, var * n / det, -var * sx / det);
        let (ga, gb) = (-1.0 / (1.0 - b), -a / (1.0 - b).powi(2));
        (ga * ga * var_a + 2.0 * ga * gb * cov + gb * gb * var_b)
            .max(0.0)
            .sqrt()
    });
    Some(TipPath {
        alpha0_rad,
        slope: b,
        std_error_rad,
    })
}

/// The estimator's answer from the tip's path: the estimate when the path fits with a
/// residual (three probes or more) and its standard error is within the limit.
pub(super) fn tip_path_outcome(
    samples: &[ProbeSample],
    plan: &ProbePlan,
    base_angle: f64,
    params: &TangentParams,
) -> Option<TangentEstimate> {
    let count = plan.count.min(MAX_PROBES);
    let normal = perp(unit(base_angle));
    let stats: Vec<ProbeStats> = (0..count)
        .map(|k| {
            probe_stats(
                samples,
                k as u8,
                plan.offsets[k],
                base_angle,
                normal,
                plan.periods,
                plan.dither_hz,
            )
        })
        .collect();
    let path = tip_path(&stats)?;
    let se = path.std_error_rad?;
    if !(se <= params.max_std_error_deg.to_radians() && path.alpha0_rad.is_finite()) {
        return None;
    }
    let (sig, noise) = signal_and_noise(&stats);
    Some(TangentEstimate {
        alpha0_rad: path.alpha0_rad,
        tangent_angle_rad: base_angle - path.alpha0_rad,
        method: TangentMethod::TipPath,
        std_error_rad: se,
        residual_n: 0.0,
        noise_n: noise,
        snr: if noise > 0.0 {
            sig / noise
        } else {
            f64::INFINITY
        },
        thesis_alpha0_rad: None,
        thesis_6_1_alpha0_rad: None,
        ratio_alpha0_rad: None,
        stiffness_n_per_m: 0.0,
        probes: count,
        iterations: 1,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats_on_the_line(alpha0: f64, b: f64, offsets: &[f64]) -> Vec<ProbeStats> {
        offsets
            .iter()
            .map(|&d| {
                let psi = -alpha0 + b * (d + alpha0);
                ProbeStats {
                    offset_rad: d,
                    displacement_m: [8e-4 * psi.cos(), 8e-4 * psi.sin()],
                    ..Default::default()
                }
            })
            .collect()
    }

    /// The fit returns α0 = −a/(1 − b) exactly on paths that lie on the model's line, and
    /// refuses a tip that follows 2 % of the strokes (b above the range) or does not move
    /// forward.
    #[test]
    fn the_tip_path_recovers_the_tangent_from_its_line() {
        let offsets = [-16f64, -8.0, 8.0, 16.0].map(f64::to_radians);
        for (alpha0_deg, b) in [(3.0f64, 0.0), (-2.0, 0.004), (7.0, 1e-4), (-0.5, -0.004)] {
            let a0 = alpha0_deg.to_radians();
            let path = tip_path(&stats_on_the_line(a0, b, &offsets)).unwrap();
            assert!((path.alpha0_rad - a0).abs() < 1e-12, "{alpha0_deg}° b {b}");
            assert!((path.slope - b).abs() < 1e-12);
            assert!(path.std_error_rad.unwrap() < 1e-9);
        }
        let two = tip_path(&stats_on_the_line(0.02, 0.001, &offsets[2..])).unwrap();
        assert_eq!(two.std_error_rad, None);
        assert!((two.alpha0_rad - 0.02).abs() < 1e-12);
        assert_eq!(tip_path(&stats_on_the_line(0.02, 0.02, &offsets)), None);
        let mut backwards = stats_on_the_line(0.02, 0.0, &offsets);
        backwards[1].displacement_m[0] = -1e-4;
        assert_eq!(tip_path(&backwards), None);
    }

    /// On a contact that holds the tip on the surface the force response is in the noise, and
    /// the regression alone has no answer; on a re-probe set the tip's path gives the tangent.
    /// The first set (two probes) keeps the regression's answer, and a tip that follows 0.8 of
    /// the strokes on a soft contact gets none from its path (the slope is out of range).
    #[test]
    fn a_stiff_contacts_tangent_comes_from_the_tip_path() {
        let params = TangentParams::default();
        let stiff = ProbeModel {
            alpha0: 2f64.to_radians(),
            base: 0.3,
            k: 1e6,
            noise: 0.02,
            friction: 0.0,
            preload: 2.5,
            travel: 0.8,
            share: 1e-6,
        };
        let (first, second) = (params.first_plan(), params.reprobe_plan());
        let out = estimate(&stiff.record(&first, 3), &first, 0.3, &params, false);
        assert!(
            matches!(out, TangentOutcome::Failed(TangentError::TooNoisy { .. })),
            "{out:?}"
        );
        let record = stiff.record(&second, 4);
        let regression = regression_estimate(&record, &second, 0.3, &params, true);
        assert!(
            matches!(
                regression,
                TangentOutcome::Failed(TangentError::TooNoisy { .. })
            ),
            "{regression:?}"
        );
        match estimate(&record, &second, 0.3, &params, true) {
            TangentOutcome::Estimate(e) => {
                assert_eq!(e.method, TangentMethod::TipPath);
                assert!((e.alpha0_rad.to_degrees() - 2.0).abs() < 0.01, "{e:?}");
            }
            other => panic!("{other:?}"),
        }
        let soft = ProbeModel {
            k: 10.0,
            share: 0.8,
            ..stiff
        };
        let out = estimate(&soft.record(&second, 4), &second, 0.3, &params, true);
        assert!(matches!(out, TangentOutcome::Failed(_)), "{out:?}");
    }

    /// A tip that moved against every stroke (phase-inverted) has no path: fitted as a line
    /// it would read the surface half a turn round.
    #[test]
    fn a_tip_moving_against_the_strokes_has_no_path() {
        let offsets = [-16f64, -8.0, 8.0, 16.0].map(f64::to_radians);
        let mut against = stats_on_the_line(0.02, 0.0, &offsets);
        for s in &mut against {
            s.displacement_m = [-s.displacement_m[0], -s.displacement_m[1]];
        }
        assert_eq!(tip_path(&against), None);
    }

    /// The standard error is ordinary least squares' with the delta method for
    /// α0 = −a/(1 − b), computed here independently with nalgebra's matrices.
    #[test]
    fn the_tip_paths_standard_error_is_least_squares_and_the_delta_method() {
        use nalgebra::{Matrix2, Vector2};
        // Five probes off centre: every term of the covariance counts.
        let offsets = [-16f64, -8.0, 4.0, 8.0, 16.0].map(f64::to_radians);
        let mut stats = stats_on_the_line(0.03, 0.002, &offsets);
        let scatter = [2e-4, -3e-4, 1.5e-4, -1e-4, 2.5e-4];
        for (s, e) in stats.iter_mut().zip(scatter) {
            let psi = s.displacement_m[1].atan2(s.displacement_m[0]) + e;
            s.displacement_m = [8e-4 * psi.cos(), 8e-4 * psi.sin()];
        }
        let path = tip_path(&stats).unwrap();
        let psi: Vec<f64> = stats
            .iter()
            .map(|s| s.displacement_m[1].atan2(s.displacement_m[0]))
            .collect();
        let mut xtx = Matrix2::zeros();
        let mut xty = Vector2::zeros();
        for (d, p) in offsets.iter().zip(&psi) {
            let row = Vector2::new(1.0, *d);
            xtx += row * row.transpose();
            xty += row * *p;
        }
        let inv = xtx.try_inverse().unwrap();
        let coef = inv * xty;
        let (a, b) = (coef[0], coef[1]);
        let sse: f64 = offsets
            .iter()
            .zip(&psi)
            .map(|(d, p)| (p - a - b * d).powi(2))
            .sum();
        let cov = inv * (sse / 3.0);
        let g = Vector2::new(-1.0 / (1.0 - b), -a / (1.0 - b).powi(2));
        let se = (g.transpose() * cov * g)[0].sqrt();
        assert!((path.alpha0_rad + a / (1.0 - b)).abs() < 1e-12);
        assert!((path.slope - b).abs() < 1e-12);
        let got = path.std_error_rad.unwrap();
        assert!(se > 1e-5 && (got - se).abs() < 1e-9 * se, "{got} vs {se}");
    }
}
