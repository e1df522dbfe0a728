//! The tangent error α0 from two or more probes' responses: the thesis's eqs. 5.8, 5.9 and
//! 6.1 as written, the exact two-probe form, and the signed least squares of three or more
//! (docs/surface-tracking.md).

/// Eq. 5.8 as printed (small angles): `α0 = (R1 δα2 − R2 δα1)/(R2 − R1)`, valid while
/// (α0 + δα1)(α0 + δα2) > 0. `None` when R1 = R2.
pub fn eq_5_8(r1: f64, r2: f64, d1: f64, d2: f64) -> Option<f64> {
    let den = r2 - r1;
    (den != 0.0).then(|| (r1 * d2 - r2 * d1) / den)
}

/// Eq. 5.9 (small angles, δα1 = −δα2 = δα, |α0| < δα): `α0 = δα (R1 − R2)/(R1 + R2)`.
pub fn eq_5_9(r1: f64, r2: f64, d: f64) -> Option<f64> {
    let den = r1 + r2;
    (den != 0.0).then(|| d * (r1 - r2) / den)
}

/// Eq. 6.1 (asymmetric strokes A1 ≠ A2): `α0 = (R1 A2 δα2 − R2 A1 δα1)/(R2 A1 − R1 A2)`.
pub fn eq_6_1(r1: f64, r2: f64, a1: f64, a2: f64, d1: f64, d2: f64) -> Option<f64> {
    let den = r2 * a1 - r1 * a2;
    (den != 0.0).then(|| (r1 * a2 * d2 - r2 * a1 * d1) / den)
}

/// Exact same-side form of eq. 5.8/6.1: from `ρ_i = R_i/A_i = K' sin(α0 + δα_i)` (same sign),
/// `tan α0 = (ρ2 sin δα1 − ρ1 sin δα2)/(ρ1 cos δα2 − ρ2 cos δα1)`.
pub fn alpha0_exact(rho1: f64, rho2: f64, d1: f64, d2: f64) -> Option<f64> {
    let num = rho2 * d1.sin() - rho1 * d2.sin();
    let den = rho1 * d2.cos() - rho2 * d1.cos();
    if den == 0.0 && num == 0.0 {
        return None;
    }
    // α0 within ±90°: the branch with K' of the same sign as ρ.
    let a = (num / den).atan();
    Some(a)
}

/// Signed least squares over any number of probes: `ρ_i = u sin δα_i + w cos δα_i` with
/// `u = K' cos α0`, `w = K' sin α0`. Returns (α0, K', residual RMS, standard error of α0).
pub fn alpha0_least_squares(
    rho: &[f64],
    offsets: &[f64],
    rho_std: &[f64],
) -> Option<(f64, f64, f64, f64)> {
    let n = rho.len().min(offsets.len());
    if n < 2 {
        return None;
    }
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for k in 0..n {
        let (s, c) = offsets[k].sin_cos();
        a11 += s * s;
        a12 += s * c;
        a22 += c * c;
        b1 += s * rho[k];
        b2 += c * rho[k];
    }
    let det = a11 * a22 - a12 * a12;
    if det.abs() < 1e-12 {
        return None;
    }
    let u = (a22 * b1 - a12 * b2) / det;
    let w = (a11 * b2 - a12 * b1) / det;
    let k = (u * u + w * w).sqrt();
    let alpha = if u >= 0.0 {
        (w / u).atan()
    } else {
        (w / u).atan() + std::f64::consts::PI.copysign(w)
    };
    let sse: f64 = (0..n)
        .map(|j| {
            let (s, c) = offsets[j].sin_cos();
            (rho[j] - u * s - w * c).powi(2)
        })
        .sum();
    let resid = (sse / n as f64).sqrt();
    // Standard error of α0: propagate the measurement errors through (u, w) → atan(w/u).
    let sigma = rho_std.iter().take(n).map(|s| s * s).sum::<f64>() / n as f64;
    let (ci11, ci12, ci22) = (a22 / det, -a12 / det, a11 / det);
    let (gu, gw) = (-w / (k * k), u / (k * k));
    let var_a = sigma * (gu * gu * ci11 + 2.0 * gu * gw * ci12 + gw * gw * ci22);
    Some((alpha, k, resid, var_a.max(0.0).sqrt()))
}
