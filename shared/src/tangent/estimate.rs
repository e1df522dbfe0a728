//! The estimator: from a probe run's record to an estimate, a re-probe plan or an error
//! ([`estimate`], [`TangentOutcome`]).

use super::*;
use crate::math::{Vec2, perp, unit};
use serde::Serialize;

/// A probe whose in-phase tip travel along the estimated tangent is below this fraction of
/// its commanded stroke's tangential part (`A cos δα`) is stuck ([`TangentError::Stuck`]).
/// Probes that slide travel 0.55–0.97 of it across the built-in plant and MuJoCo at 1e3–1e6 N/m
/// and 10 kHz, 1 kHz and 500 Hz; a tip that friction holds, 0.01 (docs/surface-tracking.md, §4).
pub const MIN_TRAVEL_FRACTION: f64 = 0.25;

/// Which rule produced an estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TangentMethod {
    /// Regression of the in-phase normal force on the measured tip motion (see [`estimate`]).
    MotionRegression,
    /// Ratio of the responses to the commanded strokes (exact eq. 5.8, or least squares over
    /// more probes); used when the tip motion is not recorded.
    CommandedRatio,
    /// The direction of the tip's own path over the probes (see [`tip_path`]), where the force
    /// response is too small for the regression: a contact much stiffer than the servo.
    TipPath,
}

/// Why the estimator wants another probe set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ReprobeReason {
    /// The true tangent lies between the probes: the RMS form (eq. 5.8) would fold.
    Fold,
    /// R1 ≈ R2: both probes far from the tangent, α0 ill-conditioned.
    EqualResponses,
    /// No probe's sign is significant and the hypotheses disagree.
    Ambiguous,
    /// The contact is softer than the stroke was sized for: the re-probe runs a longer stroke
    /// ([`TangentParams::soft_contact_stroke`]).
    SoftContact,
}

/// Why an estimate cannot be trusted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, thiserror::Error)]
#[serde(rename_all = "snake_case", tag = "error")]
pub enum TangentError {
    /// The normal force dropped below the contact-loss limit during a stroke.
    #[error(
        "contact lost during probe {probe}: normal force fell to {min_n:.3} N; reduce the stroke amplitude or raise the preload"
    )]
    ContactLost {
        /// Probe index.
        probe: usize,
        /// Smallest normal force (N).
        min_n: f64,
    },
    /// Too few samples for a probe.
    #[error("probe {probe} has {samples} samples; the record is incomplete")]
    MissingData {
        /// Probe index.
        probe: usize,
        /// Samples found.
        samples: usize,
    },
    /// Friction held the tip: a probe's measured travel along the tangent is a small fraction
    /// of its commanded stroke, so the force does not follow a penetration (the regression's
    /// premise) but the stick's presliding.
    #[error(
        "the tip travelled {travel_fraction:.3} of probe {probe}'s stroke: friction holds it; raise the friction-suppression dither or the stroke (tangent.amplitude_m)"
    )]
    Stuck {
        /// Probe index.
        probe: usize,
        /// In-phase tip travel along t̂ over the commanded stroke's tangential part.
        travel_fraction: f64,
    },
    /// The response is buried in noise.
    #[error(
        "the force response ({signal_n:.4} N) is below the noise ({noise_n:.4} N); use a larger stroke or more periods"
    )]
    TooNoisy {
        /// Largest |R| (N).
        signal_n: f64,
        /// Its standard error (N).
        noise_n: f64,
    },
    /// The estimate's uncertainty exceeds the limit.
    #[error("the estimate's standard error {std_error_deg:.3}° exceeds {limit_deg:.3}°")]
    Uncertain {
        /// Standard error (deg).
        std_error_deg: f64,
        /// Limit (deg).
        limit_deg: f64,
    },
    /// Re-probing did not resolve the ambiguity.
    #[error("re-probing did not resolve the tangent ({0:?})")]
    Unresolved(ReprobeReason),
}

/// An accepted estimate with its quality.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TangentEstimate {
    /// α0 = estimated − true tangent angle (rad).
    pub alpha0_rad: f64,
    /// Corrected tangent angle θ̂ − α0 (rad, world).
    pub tangent_angle_rad: f64,
    /// Rule used.
    pub method: TangentMethod,
    /// Standard error of α0 (rad).
    pub std_error_rad: f64,
    /// Residual RMS of the probe model (N).
    pub residual_n: f64,
    /// Noise level of the in-phase responses (N).
    pub noise_n: f64,
    /// Signal-to-noise ratio: largest |R| over its standard error.
    pub snr: f64,
    /// The thesis's eq. 5.8 on broadband RMS (first two probes), for comparison (rad).
    pub thesis_alpha0_rad: Option<f64>,
    /// Eq. 6.1 on broadband RMS with the measured strokes (first two probes) (rad).
    pub thesis_6_1_alpha0_rad: Option<f64>,
    /// The signed commanded-stroke ratio (exact eq. 5.8 / least squares) (rad).
    pub ratio_alpha0_rad: Option<f64>,
    /// Effective contact stiffness the regression found (N/m).
    pub stiffness_n_per_m: f64,
    /// Probes used.
    pub probes: usize,
    /// Re-projection iterations for the friction leakage.
    pub iterations: usize,
}

/// What the estimator answers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "outcome")]
pub enum TangentOutcome {
    /// A trusted estimate.
    Estimate(TangentEstimate),
    /// Run this plan and call again with all probes.
    Reprobe {
        /// Why.
        reason: ReprobeReason,
        /// The plan to run.
        plan: ProbePlan,
    },
    /// No trustworthy estimate.
    Failed(TangentError),
}

/// Estimates α0 from a probe record. `base_angle` is the estimated tangent angle θ̂ (rad) the
/// offsets are relative to; `plan` lists the probes in `samples`; `reprobed` is true when this
/// record already contains a re-probe set.
///
/// The answer is the regression of each probe's in-phase normal force on its in-phase measured
/// tip displacement (x along t̂, y along n̂): the force follows the penetration,
/// `f = −k (x sin α0 + y cos α0)`, linear in (k sin α0, k cos α0). Using the measured motion
/// (thesis §6.2.2: "relies only on the measured force values and the motion of the robot")
/// removes the servo's compliance from the problem, and the tangential travel times the contact
/// stiffness makes α0 far better determined than the ratio of two small force responses.
/// Before answering, the signed responses decide whether the thesis's form would fold (probes
/// on both sides of the tangent) or be ill-conditioned (R1 ≈ R2): then the estimator asks for
/// a re-probe on both sides with wider angles.
///
/// Where the regression has no answer (a force response in the noise, no significant sign, an
/// uncertain fit), the tip's own path may have one: on a contact much stiffer than the servo
/// the tip slides along the surface whatever direction it is stroked in ([`tip_path`]).
pub fn estimate(
    samples: &[ProbeSample],
    plan: &ProbePlan,
    base_angle: f64,
    params: &TangentParams,
    reprobed: bool,
) -> TangentOutcome {
    let outcome = regression_estimate(samples, plan, base_angle, params, reprobed);
    // Only a re-probe set the regression could not resolve: its four probes give the path a
    // residual to be judged by, and every answer the regression gives stays its own.
    let unresolved = matches!(
        outcome,
        TangentOutcome::Failed(
            TangentError::TooNoisy { .. }
                | TangentError::Uncertain { .. }
                | TangentError::Unresolved(_)
        )
    );
    if !(reprobed && unresolved) {
        return outcome;
    }
    tip_path_outcome(samples, plan, base_angle, params).map_or(outcome, TangentOutcome::Estimate)
}

/// The motion regression alone (see [`estimate`]).
pub(super) fn regression_estimate(
    samples: &[ProbeSample],
    plan: &ProbePlan,
    base_angle: f64,
    params: &TangentParams,
    reprobed: bool,
) -> TangentOutcome {
    let count = plan.count.min(MAX_PROBES);
    if count < 2 {
        return TangentOutcome::Failed(TangentError::MissingData {
            probe: count,
            samples: 0,
        });
    }
    let n_hat = perp(unit(base_angle));
    // The preload during the hold before probing: the reference for contact loss.
    let (hold_sum, hold_count) = samples
        .iter()
        .filter(|s| s.probe == HOLD)
        .fold((0.0, 0usize), |(a, n), s| {
            (a + Vec2::new(s.force[0], s.force[1]).dot(&n_hat), n + 1)
        });
    let hold_mean = if hold_count == 0 {
        f64::NAN
    } else {
        hold_sum / hold_count as f64
    };
    let offsets = &plan.offsets[..count];
    let mut alpha = 0.0;
    let mut stats = [ProbeStats::default(); MAX_PROBES];
    let mut iterations = 0;
    let mut fit = None;
    // The force is projected on the current normal estimate; re-project until α0 settles
    // (removes the tangential force leaking into the projection when n̂ is off by α0).
    for it in 0..4 {
        iterations = it + 1;
        let normal = perp(unit(base_angle - alpha));
        for k in 0..count {
            stats[k] = probe_stats(
                samples,
                k as u8,
                offsets[k],
                base_angle,
                normal,
                plan.periods,
                plan.dither_hz,
            );
        }
        if it == 0 {
            for (k, s) in stats.iter().enumerate().take(count) {
                if s.samples < 8 {
                    return TangentOutcome::Failed(TangentError::MissingData {
                        probe: k,
                        samples: s.samples,
                    });
                }
                let reference = if hold_mean.is_finite() {
                    hold_mean
                } else {
                    s.normal_mean_n
                };
                if s.normal_min_n < params.contact_loss_fraction * reference {
                    return TangentOutcome::Failed(TangentError::ContactLost {
                        probe: k,
                        min_n: s.normal_min_n,
                    });
                }
            }
            if let Some(stuck) = stuck_probe(&stats[..count], plan.amplitude_m) {
                return TangentOutcome::Failed(stuck);
            }
            let (sig, noise) = signal_and_noise(&stats[..count]);
            if sig < 3.0 * noise {
                return TangentOutcome::Failed(TangentError::TooNoisy {
                    signal_n: sig,
                    noise_n: noise,
                });
            }
        }
        let Some(step) = regress(&stats[..count]) else {
            return TangentOutcome::Failed(TangentError::Unresolved(ReprobeReason::Ambiguous));
        };
        let converged = (step.0 - alpha).abs() < 1e-7;
        alpha = step.0;
        fit = Some(step);
        if converged {
            break;
        }
    }
    let Some((alpha, stiffness, resid, se)) = fit else {
        return TangentOutcome::Failed(TangentError::Unresolved(ReprobeReason::Ambiguous));
    };
    let fitted = (alpha, stiffness, se);
    if !reprobed
        && let Some(again) = soft_contact_reprobe(&stats[..count], plan, params, hold_mean, fitted)
    {
        return again;
    }
    // The thesis's two-probe form: would it fold, or is it ill-conditioned? Judged on the
    // corrected normal: on the uncorrected one the tangential (friction) force leaking into
    // the projection can flip a small response's sign.
    if count == 2 {
        let sig_k = |k: usize| stats[k].r_signed_n.abs() > params.sign_threshold * stats[k].r_std_n;
        let (r1, r2) = (stats[0].r_signed_n, stats[1].r_signed_n);
        if sig_k(0) && sig_k(1) && r1.signum() != r2.signum() {
            return reprobe_or_fail(ReprobeReason::Fold, params, reprobed);
        }
        let diff_std = (stats[0].r_std_n.powi(2) + stats[1].r_std_n.powi(2)).sqrt();
        if sig_k(0) && sig_k(1) && (r1 - r2).abs() < params.equal_threshold * diff_std {
            return reprobe_or_fail(ReprobeReason::EqualResponses, params, reprobed);
        }
    }
    let limit = params.max_std_error_deg.to_radians();
    if se > limit || !alpha.is_finite() {
        return TangentOutcome::Failed(TangentError::Uncertain {
            std_error_deg: se.to_degrees(),
            limit_deg: params.max_std_error_deg,
        });
    }
    let (sig, noise) = signal_and_noise(&stats[..count]);
    // Cross-checks: the thesis's forms and the commanded-stroke ratio.
    let thesis = eq_5_8(stats[0].rms_n, stats[1].rms_n, offsets[0], offsets[1]);
    let sides = |s: &ProbeStats| 0.5 * (s.stroke_sides_m[0] + s.stroke_sides_m[1]);
    let thesis_61 = eq_6_1(
        stats[0].rms_n,
        stats[1].rms_n,
        sides(&stats[0]),
        sides(&stats[1]),
        offsets[0],
        offsets[1],
    );
    let rho: Vec<f64> = stats.iter().take(count).map(|s| s.r_signed_n).collect();
    let rho_std: Vec<f64> = stats.iter().take(count).map(|s| s.r_std_n).collect();
    let ratio = if count == 2 {
        alpha0_exact(rho[0], rho[1], offsets[0], offsets[1])
    } else {
        alpha0_least_squares(&rho, offsets, &rho_std).map(|r| r.0)
    };
    TangentOutcome::Estimate(TangentEstimate {
        alpha0_rad: alpha,
        tangent_angle_rad: base_angle - alpha,
        method: TangentMethod::MotionRegression,
        std_error_rad: se,
        residual_n: resid,
        noise_n: noise,
        snr: if noise > 0.0 {
            sig / noise
        } else {
            f64::INFINITY
        },
        thesis_alpha0_rad: thesis,
        thesis_6_1_alpha0_rad: thesis_61,
        ratio_alpha0_rad: ratio,
        stiffness_n_per_m: stiffness,
        probes: count,
        iterations,
    })
}

/// The largest signed response |R| over the probes and the largest of their standard errors
/// (N): the signal and the noise the estimator's gates compare.
pub(super) fn signal_and_noise(stats: &[ProbeStats]) -> (f64, f64) {
    stats.iter().fold((0.0f64, 0.0f64), |(a, b), s| {
        (a.max(s.r_signed_n.abs()), b.max(s.r_std_n))
    })
}

/// A first set on a soft contact: the response is small against the noise whatever the answer,
/// so a re-probe (four probes close to the corrected tangent, on both sides) runs a stroke
/// scaled to the stiffness the regression just read (`fit`: α0 in rad, k_e in N/m and α0's
/// standard error in rad), bounded by the swing it costs at the hold's mean normal force
/// `hold_mean_n` (the first probe's where the hold gave none); None where the contact is not
/// soft.
fn soft_contact_reprobe(
    stats: &[ProbeStats],
    plan: &ProbePlan,
    params: &TangentParams,
    hold_mean_n: f64,
    (alpha, stiffness, se): (f64, f64, f64),
) -> Option<TangentOutcome> {
    let preload_n = if hold_mean_n.is_finite() {
        hold_mean_n
    } else {
        stats.first()?.normal_mean_n
    };
    let response = commanded_stiffness(stats, plan.amplitude_m, alpha);
    let stroke = params.soft_contact_stroke(stiffness, response, preload_n, 3.0 * se)?;
    Some(TangentOutcome::Reprobe {
        reason: ReprobeReason::SoftContact,
        plan: params.soft_contact_plan(stroke, alpha),
    })
}

/// The normal force's in-phase response per metre of the commanded stroke's part along the
/// normal, `k_c` in `f_i = −k_c A sin(δα_i + α0)` by least squares over the probes (N/m): the
/// contact in series with the servo and less what the force loop takes out at the stroke's
/// frequency. It is what a stroke's force response scales with; 0 where no stroke has a part
/// along the normal.
fn commanded_stiffness(stats: &[ProbeStats], amplitude_m: f64, alpha0: f64) -> f64 {
    let (num, den) = stats.iter().fold((0.0, 0.0), |(n, d), s| {
        let normal = amplitude_m * (s.offset_rad + alpha0).sin();
        (n - s.force_in_phase_n * normal, d + normal * normal)
    });
    if den > 0.0 { num / den } else { 0.0 }
}

/// The first probe whose in-phase travel along t̂ is below [`MIN_TRAVEL_FRACTION`] of the
/// commanded stroke's tangential part, as [`TangentError::Stuck`].
fn stuck_probe(stats: &[ProbeStats], amplitude_m: f64) -> Option<TangentError> {
    stats.iter().enumerate().find_map(|(probe, s)| {
        let commanded = amplitude_m * s.offset_rad.cos();
        let travel_fraction = s.displacement_m[0].abs() / commanded;
        (commanded > 0.0 && travel_fraction < MIN_TRAVEL_FRACTION).then_some(TangentError::Stuck {
            probe,
            travel_fraction,
        })
    })
}

/// Least squares of `f_i = −(u x_i + w y_i)` over the probes (in-phase force on in-phase
/// displacement along t̂, n̂): α0 = atan2(u, w), k = |(u, w)|. Returns (α0, k, residual RMS,
/// standard error of α0).
pub(super) fn regress(stats: &[ProbeStats]) -> Option<(f64, f64, f64, f64)> {
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for s in stats {
        let (x, y, f) = (
            s.displacement_m[0],
            s.displacement_m[1],
            -s.force_in_phase_n,
        );
        a11 += x * x;
        a12 += x * y;
        a22 += y * y;
        b1 += x * f;
        b2 += y * f;
    }
    let det = a11 * a22 - a12 * a12;
    if det.is_nan() || det.abs() <= 1e-30 {
        return None;
    }
    let u = (a22 * b1 - a12 * b2) / det;
    let w = (a11 * b2 - a12 * b1) / det;
    if w.is_nan() || w <= 0.0 {
        return None;
    }
    let k = (u * u + w * w).sqrt();
    let alpha = u.atan2(w);
    let n = stats.len() as f64;
    let sse: f64 = stats
        .iter()
        .map(|s| (-s.force_in_phase_n - u * s.displacement_m[0] - w * s.displacement_m[1]).powi(2))
        .sum();
    // Error of an in-phase amplitude: √2 × the standard error of R.
    let sigma2 = stats
        .iter()
        .map(|s| 2.0 * s.r_std_n * s.r_std_n)
        .sum::<f64>()
        / n;
    let (ci11, ci12, ci22) = (a22 / det, -a12 / det, a11 / det);
    let (gu, gw) = (w / (k * k), -u / (k * k));
    let var_a = sigma2 * (gu * gu * ci11 + 2.0 * gu * gw * ci12 + gw * gw * ci22);
    Some((alpha, k, (sse / n).sqrt(), var_a.max(0.0).sqrt()))
}

pub(super) fn reprobe_or_fail(
    reason: ReprobeReason,
    params: &TangentParams,
    reprobed: bool,
) -> TangentOutcome {
    if reprobed {
        TangentOutcome::Failed(TangentError::Unresolved(reason))
    } else {
        TangentOutcome::Reprobe {
            reason,
            plan: params.reprobe_plan(),
        }
    }
}
