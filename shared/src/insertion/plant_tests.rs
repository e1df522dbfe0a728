use super::*;
use crate::insertion::whitney::Fit;

fn sharp() -> PegParams {
    let mut p = PegParams::default();
    p.geometry.chamfer_m = 0.0;
    p
}

/// Pressed flat on the face beside the hole by the wrist, the peg settles where the wrist's
/// spring equals its two tip corners' contact springs: depth k_y Δ / (k_y + 2 k_c).
#[test]
fn pressed_on_the_face_the_corners_carry_the_wrist() {
    let p = sharp();
    let start = [0.015, 0.0, 0.0];
    let mut plant = PegPlant::new(p, start);
    let push = 2e-3;
    for _ in 0..5000 {
        plant.step([0.015, -push, 0.0], [0.0; 3], 1e-4);
    }
    let (ky, kc) = (p.wrist_stiffness[1], p.contact_stiffness_n_per_m);
    let want = ky * push / (ky + 2.0 * kc);
    let t = plant.truth();
    assert!(
        (t.depth_m - want).abs() < 1e-3 * want,
        "{} vs {want}",
        t.depth_m
    );
    assert_eq!((t.contacts, t.state), (2, ContactState::Face));
    assert!((t.force.y - ky * (push - want)).abs() < 1e-3 * ky * push);
}

/// At rest on the face, leaned on by a tilted and offset wrist (its compliance centre 30 mm
/// above the tip), the wrench the wrist applies balances the contacts': equal and opposite
/// forces, and moments about the tip (not zero here: the wrist's k_θ Δθ and its force's
/// lever from the compliance centre).
#[test]
fn at_rest_the_applied_wrench_balances_the_contacts() {
    let p = sharp();
    assert!(p.compliance_above_tip_m > 0.0);
    let mut plant = PegPlant::new(p, [0.015, 0.0, 0.0]);
    for _ in 0..10_000 {
        plant.step([0.0153, -2e-3, 0.02], [0.0; 3], 1e-4);
    }
    let t = plant.truth();
    let v = t.velocity;
    assert!(v[0].abs() + v[1].abs() < 1e-6 && v[2].abs() < 1e-4, "{v:?}");
    let scale = t.force.norm();
    assert!(
        scale > 1.0 && t.applied_moment_about_tip.abs() > 0.01,
        "{t:?}"
    );
    assert!((t.applied_force + t.force).norm() < 1e-3 * scale, "{t:?}");
    let dm = t.applied_moment_about_tip + t.moment_about_tip;
    assert!(dm.abs() < 1e-3 * t.applied_moment_about_tip.abs(), "{t:?}");
}

/// Dragged along the face at 10 mm/s (far above the Stribeck velocity), the friction on
/// the peg is μ times the normal force, against the motion.
#[test]
fn dragged_on_the_face_friction_is_mu_times_the_normal_force() {
    let p = sharp();
    let mut plant = PegPlant::new(p, [0.010, 0.0, 0.0]);
    let (push, speed, dt) = (2e-3, 0.01, 1e-4);
    let mut ratio = Vec::new();
    for i in 0..6000 {
        let x = 0.010 + speed * i as f64 * dt;
        plant.step([x, -push, 0.0], [speed, 0.0, 0.0], dt);
        let t = plant.truth();
        if i > 3000 {
            ratio.push(-t.force.x / t.force.y);
        }
    }
    let mean = ratio.iter().sum::<f64>() / ratio.len() as f64;
    assert!((mean - p.mu()).abs() < 0.01 * p.mu(), "{mean}");
}

/// A peg in two-point contact (tilted 0.3°, sharp edge, RCC at the tip) under a wrench
/// inside Whitney's parallelogram slides in; outside it (a moment that leans it into the
/// contacts, or a lateral push beyond 1/μ) it stays: jammed.
#[test]
fn two_point_contact_slides_inside_the_parallelogram_and_jams_outside() {
    let mut p = sharp();
    p.compliance_above_tip_m = 0.0;
    p.wrist_stiffness = [200.0, 200.0, 0.05];
    let g = p.geometry;
    let fit = Fit {
        peg_width_m: g.peg_width_m,
        clearance_ratio: g.clearance_ratio,
        friction: p.mu(),
    };
    let theta = 0.3f64.to_radians();
    let l = fit.two_point_depth_m(theta).unwrap();
    let (r, big_d) = (0.5 * g.peg_width_m, g.hole_width_m());
    let tip = [
        -0.5 * big_d + r * theta.cos() + l * theta.sin(),
        r * theta.sin() - l * theta.cos(),
        theta,
    ];
    let lambda = fit.lambda(l);
    let fz = 4.0;
    // Depth gained in the first 0.1 s, in the next 0.2 s, and the state at the end.
    let run = |fx_over_fz: f64, m_over_rfz: f64| -> (f64, f64, ContactState) {
        let mut plant = PegPlant::new(p, tip);
        let k = p.wrist_stiffness;
        let target = [
            tip[0] + fx_over_fz * fz / k[0],
            tip[1] - fz / k[1],
            tip[2] + m_over_rfz * r * fz / k[2],
        ];
        for _ in 0..1000 {
            plant.step(target, [0.0; 3], 1e-4);
        }
        let early = plant.truth().depth_m + tip[1];
        for _ in 0..2000 {
            plant.step(target, [0.0; 3], 1e-4);
        }
        let late = plant.truth().depth_m + tip[1] - early;
        (early, late, plant.truth().state)
    };
    assert!(fit.slides(l, 0.0, 0.0));
    for (fx, m) in [(0.0, 0.0), (0.0, 0.8 * lambda), (-0.5, 0.0)] {
        assert!(fit.slides(l, fx, m));
        let slid = run(fx, m);
        assert!(slid.0 > 1e-3, "inside ({fx}, {m}): {slid:?}");
    }
    for (fx, m) in [
        (0.0, 1.2 * lambda),
        (0.0, 2.0 * lambda),
        (1.2 / fit.friction, 0.0),
    ] {
        assert!(!fit.slides(l, fx, m));
        let held = run(fx, m);
        assert!(held.1.abs() < 1e-5, "outside ({fx}, {m}): {held:?}");
        assert_eq!(held.2, ContactState::Jammed, "({fx}, {m})");
    }
}
