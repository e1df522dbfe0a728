use super::*;

fn law() -> FrictionLaw {
    FrictionLaw::THESIS
}

/// Cycle mean and mean square agree with quadrature over both regimes (no reversal /
/// reversal), across the Stribeck region and far above it, for both signs of ẋ_o.
#[test]
fn cycle_statistics_match_quadrature() {
    let law = law();
    for &x0 in &[0.0, 0.002, 0.01, 0.02, 0.05, -0.015] {
        for &a in &[0.0, 0.001, 0.004, 0.0099, 0.0101, 0.02, 0.05, 0.1, 0.3] {
            if x0 == 0.0 && a == 0.0 {
                continue;
            }
            let st = law.cycle(x0, a);
            let (m, ms) = law.cycle_by_quadrature(x0, a);
            assert!(
                (st.mean - m).abs() < 1e-9,
                "mean at x0={x0} a={a}: closed {} vs quadrature {m}",
                st.mean
            );
            assert!(
                (st.mean_square - ms).abs() < 1e-9,
                "mean square at x0={x0} a={a}: closed {} vs quadrature {ms}",
                st.mean_square
            );
        }
    }
}

/// The analytic derivatives match central differences of the closed form.
#[test]
fn cycle_derivatives_match_numerical_gradient() {
    let law = law();
    for &x0 in &[0.005, 0.02, -0.02] {
        for &a in &[0.001, 0.01, 0.019, 0.021, 0.05, 0.2] {
            let st = law.cycle(x0, a);
            let h = 1e-7 * a.max(1e-3);
            let p = law.cycle(x0, a + h);
            let q = law.cycle(x0, a - h);
            let dm = (p.mean - q.mean) / (2.0 * h);
            let dms = (p.mean_square - q.mean_square) / (2.0 * h);
            let tol = |v: f64| 1e-5 * v.abs().max(1.0);
            assert!(
                (st.d_mean_da - dm).abs() < tol(dm),
                "d mean at {x0},{a}: {} vs {dm}",
                st.d_mean_da
            );
            assert!(
                (st.d_mean_square_da - dms).abs() < tol(dms),
                "d mean square at {x0},{a}: {} vs {dms}",
                st.d_mean_square_da
            );
        }
    }
}

/// Without dither the cycle mean is the law itself; with pure dither (ẋ_o = 0) the mean is
/// zero (eq. 4.9); the Coulomb part with reversal is (2/π)·F_t·asin(ẋ_o/a).
#[test]
fn cycle_limits() {
    let law = law();
    for &v in &[0.001, 0.01, 0.04] {
        let st = law.cycle(v, 0.0);
        assert!((st.mean - law.resistance(v)).abs() < 1e-12);
        assert!((st.mean_square - law.resistance(v).powi(2)).abs() < 1e-10);
    }
    let st = law.cycle(0.0, 0.05);
    assert!(st.mean.abs() < 1e-12, "pure dither mean {}", st.mean);
    let coulomb = FrictionLaw {
        stribeck_n: 0.0,
        viscous_n_s_per_m: 0.0,
        ..law
    };
    let st = coulomb.cycle(0.01, 0.05);
    let expected = 2.0 / PI * law.kinetic_n * (0.2f64).asin();
    assert!((st.mean - expected).abs() < 1e-12);
    // Pure Coulomb: F² ≡ F_t², the dither only moves force from the mean into the oscillation.
    assert!((st.mean_square - law.kinetic_n.powi(2)).abs() < 1e-12);
}

/// Below reversal the mean friction under dither follows the curvature of the Stribeck
/// term (Jensen): it falls where the curve is concave (|ẋ_o| < ẋ_s/√3) and *rises* where
/// it is convex. Prints the numbers quoted in docs/friction-suppression.md.
#[test]
fn sub_reversal_dither_follows_stribeck_curvature() {
    let law = law();
    for (x0, expected) in [
        (0.002, -0.0081),
        (0.005, -0.0122),
        (0.01, 0.0370),
        (0.02, 0.1005),
    ] {
        let rise = law.cycle(x0, 0.99 * x0).mean - law.resistance(x0);
        println!(
            "x0 = {:.0} mm/s, Aω = 0.99 x0: mean − undithered = {rise:+.4} N",
            x0 * 1e3
        );
        assert!((rise - expected).abs() < 5e-4, "{x0}: {rise}");
    }
    assert!(
        0.005 < law.stribeck_velocity_m_per_s / 3f64.sqrt()
            && law.stribeck_velocity_m_per_s / 3f64.sqrt() < 0.01
    );
}

/// Eq. 4.5 limits: Stribeck excess at zero speed, kinetic + viscous far above ẋ_s, odd symmetry.
#[test]
fn friction_law_limits() {
    let law = law();
    assert!((law.resistance(1e-9) - law.breakaway()).abs() < 1e-6);
    let v = 10.0;
    let far = law.kinetic_n + law.viscous_n_s_per_m * v + law.stribeck_n / (1.0 + 1e6);
    assert!((law.resistance(v) - far).abs() < 1e-12);
    assert_eq!(law.resistance(0.0), 0.0);
    assert!((law.resistance(-0.02) + law.resistance(0.02)).abs() < 1e-15);
    // At ẋ = ẋ_s the Stribeck term is half its peak.
    let half = law.kinetic_n + 0.5 * law.stribeck_n + law.viscous_n_s_per_m * 0.01;
    assert!((law.resistance(0.01) - half).abs() < 1e-12);
}

#[test]
fn invalid_laws_are_rejected() {
    let bad = FrictionLaw {
        stribeck_velocity_m_per_s: 0.0,
        ..law()
    };
    assert!(bad.validate().is_err());
    let bad = FrictionLaw {
        kinetic_n: f64::NAN,
        ..law()
    };
    assert!(bad.validate().is_err());
    assert!(law().validate().is_ok());
    let p = PreslidingParams {
        breakaway_ratio: 1.0,
        ..Default::default()
    };
    assert!(p.validate().is_err());
}

/// Steady sliding converges to eq. 4.5.
#[test]
fn presliding_converges_to_sliding_law() {
    let law = law();
    let params = PreslidingParams::default();
    let mut z = Presliding::default();
    let mut f = 0.0;
    for _ in 0..20000 {
        f = z.step(&law, &params, 0.02, 1e-4);
    }
    assert!(
        (f - law.resistance(0.02)).abs() < 1e-9,
        "{f} vs {}",
        law.resistance(0.02)
    );
}

/// A 1-DOF mass on the surface, driven through a spring, under a load oscillating below
/// break-away around a non-zero bias: the elasto-plastic state does not drift (LuGre does).
#[test]
fn presliding_does_not_drift_under_sub_breakaway_oscillation() {
    let law = law();
    let params = PreslidingParams::default();
    let mass = 1.0;
    let dt = 1e-4;
    let (mut x, mut v) = (0.0f64, 0.0f64);
    let mut z = Presliding::default();
    let fb = law.breakaway();
    let mut x_at = Vec::new();
    let period = 0.1;
    let steps_per_period = (period / dt) as usize;
    for k in 0..(200 * steps_per_period) {
        let t = k as f64 * dt;
        let applied = 0.3 * fb + 0.3 * fb * (2.0 * PI * t / period).sin();
        let fr = z.step(&law, &params, v, dt);
        let acc = (applied - fr) / mass;
        v += acc * dt;
        x += v * dt;
        if k % steps_per_period == 0 {
            x_at.push(x);
        }
    }
    let drift = (x_at[190] - x_at[20]).abs();
    assert!(drift < 1e-9, "drift over 170 cycles {drift} m");
    assert!(x.abs() < 2.0 * fb / params.stiffness_n_per_m);
}

/// Stick-slip: a mass dragged slowly through a soft, lightly damped spring sticks and slips
/// periodically; with strong damping it slides smoothly.
#[test]
fn stick_slip_appears_with_a_soft_lightly_damped_drive() {
    let law = FrictionLaw {
        kinetic_n: 1.0,
        viscous_n_s_per_m: 0.0,
        stribeck_n: 0.8,
        stribeck_velocity_m_per_s: 0.01,
    };
    let params = PreslidingParams::default();
    let run = |damping: f64| -> (f64, f64) {
        let (mass, k, drive) = (1.0, 200.0, 0.002);
        let dt = 1e-4;
        let (mut x, mut v) = (0.0f64, 0.0f64);
        let mut z = Presliding::default();
        let (mut vmin, mut vmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for i in 0..200_000 {
            let t = i as f64 * dt;
            let spring = k * (drive * t - x) + damping * (drive - v);
            let fr = z.step(&law, &params, v, dt);
            v += (spring - fr) / mass * dt;
            x += v * dt;
            if t > 10.0 {
                vmin = vmin.min(v.abs());
                vmax = vmax.max(v.abs());
            }
        }
        (vmin, vmax)
    };
    let (vmin, vmax) = run(0.5);
    assert!(
        vmin < 0.1 * 0.002 && vmax > 5.0 * 0.002,
        "expected stick-slip, |v| in [{vmin}, {vmax}]"
    );
    let (vmin, vmax) = run(200.0);
    assert!(
        vmin > 0.5 * 0.002 && vmax < 2.0 * 0.002,
        "expected smooth sliding, |v| in [{vmin}, {vmax}]"
    );
}

#[test]
fn roughness_map_is_reproducible_and_local() {
    let a = RoughnessMap::random(7, 0.0, 0.1, 5, 0.005, 0.5);
    let b = RoughnessMap::random(7, 0.0, 0.1, 5, 0.005, 0.5);
    assert_eq!(a, b);
    let flat = RoughnessMap::default();
    assert_eq!(flat.factor(0.3), 1.0);
    let one = RoughnessMap {
        patches: vec![RoughnessPatch {
            centre_m: 0.0,
            half_width_m: 0.01,
            gain: 0.5,
        }],
    };
    assert!((one.factor(0.0) - 1.5).abs() < 1e-12);
    assert_eq!(one.factor(0.02), 1.0);
    // Mean of cos² bump over its support is 1/2.
    assert!((one.mean_factor(-0.01, 0.01) - 1.25).abs() < 1e-6);
}
