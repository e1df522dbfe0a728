use super::*;
use crate::math::GaussLegendre;
use std::f64::consts::PI;

/// The corrected eq. 4.24 is exactly the variance of the power-series law over a cycle
/// without reversal (checked by quadrature), and the inversion recovers ẋ_s.
#[test]
fn corrected_eq_4_24_matches_quadrature_and_inverts() {
    let law = FrictionLaw::THESIS;
    let gl = GaussLegendre::<32>::new();
    let (ft, fv, fs, xs) = (
        law.kinetic_n,
        law.viscous_n_s_per_m,
        law.stribeck_n,
        law.stribeck_velocity_m_per_s,
    );
    let series = |v: f64| ft + fv * v + fs - fs * (v / xs).powi(2);
    for &(x0, a) in &[(0.02, 0.005), (0.03, 0.02), (0.005, 0.001)] {
        let m = gl.integrate(0.0, PI, |t| series(x0 + a * t.cos())) / PI;
        let ms = gl.integrate(0.0, PI, |t| series(x0 + a * t.cos()).powi(2)) / PI;
        let var = ms - m * m;
        let formula = power_series_variance(&law, x0, a);
        assert!(
            (var - formula).abs() < 1e-12 * var.max(1.0),
            "{var} vs {formula}"
        );
        let est = stribeck_velocity_from_variance(formula, x0, a, fv, fs).unwrap();
        // The larger root is the true one when F_v is small (see docs).
        assert!((est - xs).abs() < 1e-9, "{est}");
        // The thesis as printed gives another number.
        let printed =
            (fv / 4.0 + fs / (2.0 * xs * xs)) * a * a + fs * fs / (4.0 * xs.powi(4)) * a.powi(4);
        assert!((printed - var).abs() > 0.1 * var);
    }
}

/// eq. 4.22's bracket is the exact derivative of ½F_f² with eq. 4.21, and its stationary
/// point (eq. 4.18) is a maximum of 4.21, not a minimum.
#[test]
fn thesis_gradient_is_derivative_of_its_model_and_4_18_is_a_maximum() {
    let (fv, fs, xs, lam) = (0.0976, 0.54, 0.01, 1.9);
    let ff = |a: f64| lam + fv * a / 2.0 - fs * a * a / (4.0 * xs * xs);
    for &a in &[1e-6, 1e-4, 0.01] {
        let h = 1e-9;
        let num = (0.5 * ff(a + h).powi(2) - 0.5 * ff(a - h).powi(2)) / (2.0 * h);
        let g = thesis_gradient(ff(a), fv, fs, xs, a);
        assert!((num - g).abs() < 1e-5 * g.abs().max(1.0), "{num} vs {g}");
    }
    let a_opt = fv * xs * xs / fs;
    assert!(ff(a_opt) > ff(a_opt * 0.9) && ff(a_opt) > ff(a_opt * 1.1));
}

/// The cost tuner's gradient matches a numerical gradient of its cost.
#[test]
fn cost_gradient_matches_numerical_gradient() {
    let law = FrictionLaw::THESIS;
    for &(x0, a) in &[(0.02, 0.003), (0.02, 0.05), (0.02, 0.15), (0.01, 0.011)] {
        let (_, g) = cost_and_gradient(&law, x0, a, 0.5, 0.05, 62.8);
        let h = 1e-7;
        let jp = cost_and_gradient(&law, x0, a + h, 0.5, 0.05, 62.8).0;
        let jm = cost_and_gradient(&law, x0, a - h, 0.5, 0.05, 62.8).0;
        let num = (jp - jm) / (2.0 * h);
        assert!(
            (g - num).abs() < 1e-5 * num.abs().max(1.0),
            "at a={a}: {g} vs {num}"
        );
    }
}

/// The minimiser a* barely depends on λ or ẋ_o: it is set by the Stribeck part of the mean
/// square against the tool's inertial oscillation. Prints the table in the docs.
#[test]
fn cost_minimiser_is_near_twelve_stribeck_velocities() {
    let law = FrictionLaw::THESIS;
    for x0 in [0.01, 0.02] {
        for lam in [0.3, 0.5, 0.7, 1.0] {
            let c = |a: f64| cost_and_gradient(&law, x0, a, lam, 0.05, 62.83).0;
            let (a, j) = grid_then_golden(1e-4, 0.5, 200, 60, c);
            let st = law.cycle(x0, a);
            println!(
                "x0 {:.0} mm/s λ {lam}: a* = {:.1} mm/s ({:.1} x0), J(a*) = {j:.3} N², J(0) = {:.3} N², mean {:.3} N, std {:.3} N",
                x0 * 1e3,
                a * 1e3,
                a / x0,
                c(0.0),
                st.mean,
                st.std()
            );
            assert!(a > 0.11 && a < 0.15, "a* = {a}");
        }
    }
}

/// The cost has an interior global minimum above ẋ_o and a local one at a = 0.
#[test]
fn cost_is_well_posed() {
    let law = FrictionLaw::THESIS;
    let x0 = 0.02;
    let cost = |a: f64| cost_and_gradient(&law, x0, a, 0.5, 0.05, 62.8).0;
    let (a_star, j_star) = grid_then_golden(1e-4, 0.3, 200, 60, cost);
    assert!(a_star > 2.0 * x0 && a_star < 0.3 * 0.99, "a* = {a_star}");
    assert!(j_star < cost(0.0));
    let (_, g) = cost_and_gradient(&law, x0, a_star, 0.5, 0.05, 62.8);
    assert!(g.abs() < 1e-3, "gradient at a* {g}");
    // Just above zero the cost rises: a = 0 is a local minimum.
    assert!(cost(0.2 * x0) > cost(0.0));
}
