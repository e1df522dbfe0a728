//! The trace printer docs/contact.md's traces come from: `fig5.6` (or `corners`) run tick by
//! tick on a set-up of the environment's choosing, printing the true normal force's
//! dither-period mean and range, the servo's mode, its tangent error and how far the tip
//! trails the set-point, then the estimator's answers.
//!
//! `AFS_TRACE_K=1e5 AFS_TRACE_FROM=38.3 AFS_TRACE_TO=38.6 AFS_TRACE_EVERY=40 cargo test -p
//! afs-shared --profile ci --lib print_a_tracking_trace -- --ignored --nocapture`
//! Settings (all optional): `AFS_TRACE_K` contact stiffness (N/m, default 1e5),
//! `AFS_TRACE_SEED` (1), `AFS_TRACE_FROM`/`AFS_TRACE_TO` the window (s), `AFS_TRACE_EVERY` ticks
//! between lines (1000), `AFS_TRACE_CORNERS=1` the corners profile instead of the sinusoid,
//! `AFS_TRACE_PROBE_FORCE_LOOP=frozen|on|auto`, `AFS_TRACE_DRIFT=setpoint|tip|auto`,
//! `AFS_TRACE_U` the dither's tangent uncertainty (deg), `AFS_TRACE_A` the probes' stroke (m),
//! `AFS_TRACE_RATE` the servo's rate (Hz), `AFS_TRACE_TOLD` the stiffness the servo is told (N/m),
//! `AFS_TRACE_MJCF=FILE` a MuJoCo arm (with `--features mujoco`).

use crate::config::SimConfig;
use crate::msg::{PlantSample, ServoSample};
use crate::servo::{DriftSource, ProbeForceLoop};
use crate::sim::Lockstep;
use crate::window::SlidingWindow;

fn setting<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

#[test]
#[ignore = "prints a trace for docs/contact.md"]
fn print_a_tracking_trace() {
    let mut cfg = SimConfig {
        seed: setting("AFS_TRACE_SEED", 1),
        ..SimConfig::default()
    };
    cfg.plant.contact.interaction_stiffness_n_per_m = setting("AFS_TRACE_K", 1e5);
    cfg.servo.probe_force_loop = match std::env::var("AFS_TRACE_PROBE_FORCE_LOOP").as_deref() {
        Ok("frozen") => ProbeForceLoop::Frozen,
        Ok("on") => ProbeForceLoop::On,
        _ => ProbeForceLoop::Auto,
    };
    cfg.servo.tracking.drift_source = match std::env::var("AFS_TRACE_DRIFT").as_deref() {
        Ok("setpoint") => DriftSource::Setpoint,
        Ok("tip") => DriftSource::Tip,
        _ => DriftSource::Auto,
    };
    cfg.servo.dither.tangent_uncertainty_deg =
        setting("AFS_TRACE_U", cfg.servo.dither.tangent_uncertainty_deg);
    cfg.servo.tangent.amplitude_m = setting("AFS_TRACE_A", cfg.servo.tangent.amplitude_m);
    cfg.servo.rate_hz = setting("AFS_TRACE_RATE", cfg.servo.rate_hz);
    cfg.servo.hybrid.stiffness_estimate_n_per_m = setting(
        "AFS_TRACE_TOLD",
        cfg.servo.hybrid.stiffness_estimate_n_per_m,
    );
    if let Ok(mjcf) = std::env::var("AFS_TRACE_MJCF") {
        cfg.world.kind = crate::config::WorldKind::Mujoco;
        cfg.world.mjcf = Some(mjcf);
    }
    // The experiments' own set-ups: fig5.6's sinusoid, or the corners' profile.
    let u_end = if std::env::var("AFS_TRACE_CORNERS").is_ok() {
        crate::setups::on_corner_profile(&mut cfg).1
    } else {
        super::tracking::on_fig5_6_sinusoid(&mut cfg)
    };
    cfg.servo.tracking.enabled = true;
    let (from, to) = (setting("AFS_TRACE_FROM", 0.0), setting("AFS_TRACE_TO", 1e9));
    let every: u64 = setting("AFS_TRACE_EVERY", 1000);
    let mut sim = Lockstep::new(&cfg).unwrap();
    sim.servo_mut().set_a_omega(0.025);
    sim.servo_mut().hybrid_mut().set_velocity(0.005);
    let period = (1.0 / (cfg.servo.dither.frequency_hz * sim.dt())).round() as usize;
    let mut window = SlidingWindow::new(period);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    println!(
        "t (s) | mode | period-mean F_N (N) | F_N range since the last line (N) | tangent error (deg) | tip behind the set-point along the tangent (mm) | dither amplitude (mm)"
    );
    for seq in 0..(600.0 / sim.dt()) as u64 {
        sim.step();
        let p = PlantSample::of_tick(sim.truth(), seq, 0);
        let s = ServoSample::of_tick(sim.servo(), seq, 0, sim.time());
        window.push(p.normal_force_n);
        lo = lo.min(p.normal_force_n);
        hi = hi.max(p.normal_force_n);
        let t = sim.time();
        if seq % every == 0 && (from..=to).contains(&t) {
            let tangent = crate::math::unit(s.tangent_angle_rad);
            let behind = (crate::math::Vec2::from(s.set_point_m)
                - crate::math::Vec2::from(p.tip_m))
            .dot(&tangent);
            println!(
                "{t:.4} | {} | {:.3} | {lo:.2}–{hi:.2} | {:.2} | {:.3} | {:.3}",
                s.mode,
                window.mean(),
                crate::math::wrap_angle(s.tangent_angle_rad - p.tangent_angle_rad).to_degrees(),
                behind * 1e3,
                s.dither_amplitude_m * 1e3,
            );
            (lo, hi) = (f64::INFINITY, f64::NEG_INFINITY);
        }
        if p.surface_u_m >= u_end {
            break;
        }
    }
    for e in sim.estimates() {
        println!(
            "answer at {:.3} s: true tangent {:.2}°, probed from {:.2}°: {:?}",
            e.time_s,
            e.true_angle_rad.to_degrees(),
            e.base_angle_rad.to_degrees(),
            e.outcome
        );
    }
    println!("{:?}", sim.servo().counters());
}
