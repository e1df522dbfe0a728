//! The force loop against contacts from foam to steel (docs/contact.md).

use super::*;

/// A lockstep simulation at rest in contact of stiffness `k_e` (N/m), the servo told `k_e`,
/// at `rate_hz`; `beta` overrides the rate feedforward's fraction.
fn at_rest(k_e: f64, rate_hz: f64, beta: Option<f64>) -> Lockstep {
    let mut cfg = SimConfig::default();
    cfg.plant.contact.interaction_stiffness_n_per_m = k_e;
    cfg.servo.hybrid.stiffness_estimate_n_per_m = k_e;
    cfg.servo.rate_hz = rate_hz;
    let mut sim = Lockstep::new(&cfg).unwrap();
    if let Some(b) = beta {
        sim.servo_mut().hybrid_mut().set_rate_feedforward(b);
    }
    sim
}

/// The true normal force's range (N) over `seconds` after one second of settling.
fn hold_range(sim: &mut Lockstep, seconds: f64) -> (f64, f64) {
    sim.run((1.0 / sim.dt()).round() as usize);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for _ in 0..(seconds / sim.dt()).round() as usize {
        sim.step();
        let f = sim.truth().normal_force_n;
        lo = lo.min(f);
        hi = hi.max(f);
    }
    (lo, hi)
}

/// From foam to steel, at every servo rate, the servo holds the preload at rest within 0.1 N
/// (the sensor's noise moves it by ±0.03 N). With the whole set-point rate fed forward
/// (β = 1, as before docs/contact.md), 1 MN/m chattered between 0 and 13 N at 10 kHz.
#[test]
fn a_contact_of_any_stiffness_is_held_without_chatter() {
    for rate in [10e3, 1e3, 500.0] {
        for k_e in [1e3, 1e4, 1e5, 1e6] {
            let mut sim = at_rest(k_e, rate, None);
            let preload = sim.servo().hybrid().params().preload_n;
            let (lo, hi) = hold_range(&mut sim, 2.0);
            assert!(
                lo > preload - 0.1 && hi < preload + 0.1,
                "{rate} Hz, k_e {k_e:e} N/m: F_N {lo:.3}..{hi:.3} N"
            );
        }
    }
}

/// The derivation puts the limit of the rate feedforward at twice the β the servo picks
/// (where the delayed feedforward takes all the servo's damping). On a steel contact the
/// plant holds at that β and loses contact at twice the predicted limit.
#[test]
fn the_rate_feedforward_loses_the_contact_beyond_its_derived_limit() {
    for rate in [10e3, 500.0] {
        let beta = at_rest(1e6, rate, None).servo().hybrid().rate_feedforward();
        assert!(beta < 0.2, "{rate} Hz: β {beta}");
        let (lo, _) = hold_range(&mut at_rest(1e6, rate, Some(beta)), 2.0);
        assert!(lo > 2.4, "{rate} Hz, β {beta:.4}: F_N fell to {lo:.3} N");
        let (lo, _) = hold_range(&mut at_rest(1e6, rate, Some(4.0 * beta)), 2.0);
        assert!(
            lo < 0.5,
            "{rate} Hz, β {:.4}: F_N stayed ≥ {lo:.3} N",
            4.0 * beta
        );
    }
}

/// Prints the measured margin table of docs/contact.md: the hold's range at multiples of the
/// picked β. `cargo test -p afs-shared --profile ci --lib rate_feedforward_margins -- --ignored --nocapture`
#[test]
#[ignore = "prints docs/contact.md's table"]
fn rate_feedforward_margins() {
    println!("| rate (Hz) | k_e (N/m) | β picked | β/β picked: F_N range (N) |");
    for rate in [10e3, 1e3, 500.0] {
        for k_e in [1e5, 1e6] {
            let beta = at_rest(k_e, rate, None).servo().hybrid().rate_feedforward();
            let mut row = format!("| {rate} | {k_e:e} | {beta:.4} |");
            for f in [1.0, 2.0, 3.0, 4.0, 6.0, 8.0] {
                if beta * f > 1.0 {
                    continue;
                }
                let (lo, hi) = hold_range(&mut at_rest(k_e, rate, Some(beta * f)), 2.0);
                row += &format!(" ×{f}: {lo:.2}–{hi:.2};");
            }
            println!("{row}");
        }
    }
}

/// The true normal force's range and RMS deviation from the preload (N) over 2 s, after 2 s,
/// of sliding at `velocity` (m/s) with the dither held at `a_omega` (m/s) on a contact of
/// stiffness `k_e` (N/m), the servo told `k_e`, the tangent off by `tilt_deg`, the contact
/// mode's damping ratio set to `zeta`. The dither's amplitude bound is lifted (it allows
/// 0.04 mm at 1 MN/m, docs/contact.md).
fn dithered(
    k_e: f64,
    a_omega: f64,
    velocity: f64,
    tilt_deg: f64,
    zeta: f64,
) -> (f64, f64, f64, f64) {
    let mut cfg = SimConfig::default();
    cfg.plant.contact.interaction_stiffness_n_per_m = k_e;
    cfg.servo.hybrid.stiffness_estimate_n_per_m = k_e;
    cfg.servo.dither.tangent_uncertainty_deg = 0.01;
    cfg.servo.contact_damping_ratio = zeta;
    cfg.tangent_error_rad = tilt_deg.to_radians();
    let preload = cfg.servo.hybrid.preload_n;
    let mut sim = Lockstep::new(&cfg).unwrap();
    let added = sim.servo().normal_damping();
    sim.servo_mut().set_tuning(false);
    sim.servo_mut().set_a_omega(a_omega);
    sim.servo_mut().hybrid_mut().set_velocity(velocity);
    sim.run((2.0 / sim.dt()).round() as usize);
    let n = (2.0 / sim.dt()).round() as usize;
    let (mut lo, mut hi, mut sq) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
    for _ in 0..n {
        sim.step();
        let f = sim.truth().normal_force_n;
        lo = lo.min(f);
        hi = hi.max(f);
        sq += (f - preload).powi(2);
    }
    (lo, hi, (sq / n as f64).sqrt(), added)
}

/// The damping added along the normal gives the contact mode the requested ratio, and none
/// is added where the servo's own damping suffices.
#[test]
fn the_added_damping_gives_the_contact_mode_its_ratio() {
    use crate::servo::contact_damping;
    let (ks, m, cs) = (1520.0, 18.0, 231.0);
    for (zeta, ke) in [(0.25, 1e5), (0.25, 1e6), (0.7, 1e4), (0.7, 1e6)] {
        let added = contact_damping(zeta, ke, ks, m, cs);
        let ratio = (cs + added) / (2.0 * ((ke + ks) * m).sqrt());
        assert!((ratio - zeta).abs() < 1e-12, "ζ {zeta}, k_e {ke}: {ratio}");
    }
    assert_eq!(contact_damping(0.25, 1e4, ks, m, cs), 0.0);
    assert_eq!(contact_damping(0.0, 1e6, ks, m, cs), 0.0);
    // The default set-up's contact is damped enough: nothing is added, nothing changes.
    let sim = Lockstep::new(&SimConfig::default()).unwrap();
    assert_eq!(sim.servo().normal_damping(), 0.0);
}

/// The damping ratio that keeps the contact mode from amplifying the dither: at it the mode's
/// gain at the dither's frequency, `1/√((1 − r²)² + (2ζr)²)`, is exactly 1 where r < √2, and
/// none is needed above (the default 10 kN/m contact, whose mode is at 4 Hz against the 10-Hz
/// dither); 0.57 on 100 kN/m, 0.69 on 1 MN/m (default arm: m = 17.7 kg, k_s = 1 524 N/m).
#[test]
fn the_contact_mode_is_damped_so_that_it_does_not_amplify_the_dither() {
    use crate::servo::dither_damping_ratio;
    let (w, ks, m) = (std::f64::consts::TAU * 10.0, 1524.0, 17.7);
    for ke in [5e4, 1e5, 1e6, 1e7] {
        let zeta = dither_damping_ratio(w, ke, ks, m);
        let r = w / ((ke + ks) / m).sqrt();
        let gain = 1.0 / ((1.0 - r * r).powi(2) + (2.0 * zeta * r).powi(2)).sqrt();
        assert!(
            r < 2f64.sqrt() && (gain - 1.0).abs() < 1e-12,
            "k_e {ke:e}: ζ {zeta}, gain {gain}"
        );
    }
    assert!((dither_damping_ratio(w, 1e5, ks, m) - 0.57).abs() < 0.01);
    assert!((dither_damping_ratio(w, 1e6, ks, m) - 0.69).abs() < 0.01);
    assert_eq!(dither_damping_ratio(w, 1e4, ks, m), 0.0);
    assert_eq!(dither_damping_ratio(w, 1e3, ks, m), 0.0);
    assert_eq!(dither_damping_ratio(f64::NAN, 1e5, ks, m), 0.0);
    // A servo adopting 100 kN/m damps its mode to that ratio, not to the configured 0.25.
    let mut cfg = SimConfig::default();
    cfg.plant.contact.interaction_stiffness_n_per_m = 1e5;
    let mut sim = Lockstep::new(&cfg).unwrap();
    sim.servo_mut().adopt_stiffness(1e5);
    let [mass, cs, k_servo] = sim.servo().contact_mode();
    let zeta = (cs + sim.servo().normal_damping()) / (2.0 * ((1e5 + k_servo) * mass).sqrt());
    let want = dither_damping_ratio(w, 1e5, k_servo, mass);
    assert!(
        (zeta - want).abs() < 1e-9 && want > 0.5,
        "ζ {zeta}, want {want}"
    );
}

/// `fig5.6` at seed 1 on a contact of `stiffness` (N/m), the servo told the default and
/// adapting, with `set` applied to the set-up.
fn fig5_6_on(
    stiffness: f64,
    set: impl FnOnce(&mut SimConfig),
) -> crate::experiments::Outcome<crate::experiments::Fig56Summary> {
    let mut base = SimConfig::default();
    base.plant.contact.interaction_stiffness_n_per_m = stiffness;
    set(&mut base);
    let opts = crate::experiments::Options {
        seed: 1,
        base,
        ..Default::default()
    };
    crate::experiments::fig5_6(&opts).unwrap()
}

/// The force loop stays on during the probes where the contact's mode sits above ω_d/√2:
/// k_e > m ω_d²/2 − k_s, 33 kN/m on the default arm. Not on the default 10 kN/m contact
/// (nothing changes there), on 100 kN/m and 1 MN/m.
#[test]
fn the_force_loop_stays_on_during_the_probes_of_a_stiff_contact() {
    use crate::servo::contact_mode_above_dither;
    let (w, ks, m) = (std::f64::consts::TAU * 10.0, 1524.0, 17.7);
    let edge = m * w * w / 2.0 - ks;
    assert!((edge - 33.4e3).abs() < 100.0, "{edge}");
    assert!(!contact_mode_above_dither(w, edge * 0.99, ks, m));
    assert!(contact_mode_above_dither(w, edge * 1.01, ks, m));
    for (ke, on) in [(1e3, false), (1e4, false), (1e5, true), (1e6, true)] {
        assert_eq!(contact_mode_above_dither(w, ke, ks, m), on, "{ke:e}");
    }
    assert!(!contact_mode_above_dither(f64::NAN, 1e5, ks, m));
    assert!(!contact_mode_above_dither(w, -1e5, ks, m));
}

/// fig5.6 on 100 kN/m (seed 1): with the force loop frozen during the strokes, as in the
/// thesis, the dither's normal error along a tangent 1° off swings the force through zero and
/// the contact guard abandons the probe runs; kept on (`auto`), every check passes.
#[test]
fn probes_on_a_stiff_contact_hold_the_preload() {
    use crate::servo::ProbeForceLoop;
    let run = |mode| fig5_6_on(1e5, |c| c.servo.probe_force_loop = mode);
    let auto = run(ProbeForceLoop::Auto);
    let r = &auto.summary.run;
    assert!(
        auto.passed() && r.estimations.contact_losses == 0,
        "auto: {:.2}°, deviation {:.3}, {} ticks off, {} losses",
        r.tangent_error_rms_deg,
        r.worst_normal_deviation,
        r.ticks_without_contact,
        r.estimations.contact_losses
    );
    let frozen = run(ProbeForceLoop::Frozen);
    let r = &frozen.summary.run;
    assert!(
        !frozen.passed() && r.estimations.contact_losses > 0,
        "frozen: {} losses",
        r.estimations.contact_losses
    );
}

/// fig5.6 on 1 MN/m (seed 1): read from the set-point's rate, `ω_f (F_d − F̄_N)/k̂`, the drift
/// trigger turns 0.01 N of wander in the period-mean force into 0.75° and fires every 2.5 mm,
/// and the 120 mm are not tracked within the experiment's 400 s; read from the tip (`auto` on
/// a stiff contact), every check passes.
#[test]
fn the_drift_on_steel_is_read_from_the_tip() {
    use crate::servo::DriftSource;
    let run = |source| fig5_6_on(1e6, |c| c.servo.tracking.drift_source = source);
    let auto = run(DriftSource::Auto);
    let r = &auto.summary.run;
    assert!(
        auto.passed(),
        "auto: {:.2}°, deviation {:.3}, {} ticks off, {:.1} mm, {} started",
        r.tangent_error_rms_deg,
        r.worst_normal_deviation,
        r.ticks_without_contact,
        r.travelled_m * 1e3,
        r.estimations.started
    );
    let setpoint = run(DriftSource::Setpoint);
    let s = &setpoint.summary.run;
    assert!(
        !setpoint.passed() && s.estimations.started > 2 * r.estimations.started,
        "set-point: {} estimations started (tip: {})",
        s.estimations.started,
        r.estimations.started
    );
}

/// The probes are recorded at 1 kHz at every servo rate: 10 kHz keeps every tenth tick, 1 kHz
/// and 500 Hz every tick. With every tenth tick at any rate, a 500-Hz servo recorded 50 Hz, and
/// `tangent` at seed 3 missed the no-friction check (0.26° against 0.1°).
#[test]
fn the_probes_are_recorded_at_a_kilohertz_at_every_rate() {
    use crate::servo::probe_decimation;
    assert_eq!(probe_decimation(10_000.0), 10);
    assert_eq!(probe_decimation(1_000.0), 1);
    assert_eq!(probe_decimation(500.0), 1);
    assert_eq!(probe_decimation(f64::NAN), 1);
    let mut base = SimConfig::default();
    base.servo.rate_hz = 500.0;
    let opts = crate::experiments::Options {
        seed: 3,
        base,
        ..Default::default()
    };
    let out = crate::experiments::tangent(&opts).unwrap();
    assert!(
        out.passed(),
        "{:?}",
        out.checks
            .iter()
            .filter(|c| !c.pass)
            .map(|c| (c.id.clone(), c.value))
            .collect::<Vec<_>>()
    );
}

/// Sliding and dithering on steel (1 MN/m): friction's reversals at the dither's frequency
/// shake the contact mode (37 Hz, ζ = 0.03 undamped). Without the added damping the tool
/// leaves the surface; with the default ζ_c = 0.25 it stays pressed.
#[test]
fn the_damped_contact_mode_keeps_a_dithered_tool_on_steel() {
    let (lo, hi, _, _) = dithered(1e6, 0.03, 0.005, 0.0, 0.25);
    assert!(lo > 1.5 && hi < 3.5, "damped: F_N {lo:.2}..{hi:.2} N");
    let (lo, _, _, _) = dithered(1e6, 0.03, 0.005, 0.0, 0.0);
    assert!(lo < 0.5, "undamped: F_N stayed ≥ {lo:.2} N");
}

/// Prints docs/contact.md's table of the dithered contact's normal force, with and without
/// the added damping. `cargo test -p afs-shared --profile ci --lib contact_damping_table -- --ignored --nocapture`
#[test]
#[ignore = "prints docs/contact.md's table"]
fn contact_damping_table() {
    println!(
        "| k_e (N/m) | Aω (m/s) | tangent error | ζ_c | added damping (N·s/m) | F_N range (N) | RMS deviation (N) |"
    );
    println!("|---|---:|---:|---:|---:|---|---:|");
    let sim = Lockstep::new(&SimConfig::default()).unwrap();
    let [m, c_s, k_s] = sim.servo().contact_mode();
    eprintln!("m = {m:.2} kg, c_s = {c_s:.1} N·s/m, k_s = {k_s:.0} N/m");
    for k_e in [1e4, 1e5, 1e6] {
        let zeta = c_s / (2.0 * ((k_e + k_s) * m).sqrt());
        let hz = ((k_e + k_s) / m).sqrt() / std::f64::consts::TAU;
        eprintln!("k_e {k_e:e}: the servo's own ζ = {zeta:.3}, mode at {hz:.1} Hz");
    }
    for k_e in [1e4, 1e5, 1e6] {
        for (a_omega, tilt) in [(0.03, 0.0), (0.06, 0.0), (0.06, 2.0)] {
            for zeta in [0.0, 0.25, 0.7] {
                let (lo, hi, rms, c) = dithered(k_e, a_omega, 0.005, tilt, zeta);
                println!(
                    "| {k_e:e} | {a_omega} | {tilt}° | {zeta} | {c:.0} | {lo:.2}–{hi:.2} | {rms:.3} |"
                );
            }
        }
    }
}

/// A servo told the default 10 kN/m that meets steel (1 MN/m) chattered between 0 and 14.6 N
/// at rest. Its stiffness fit reads the stiffer contact within a second, the servo adopts it
/// (β and the damping follow), and the preload holds within 0.1 N. Without the adaptation
/// (`contact_adaptation = false`) it chatters on.
#[test]
fn a_servo_told_a_soft_contact_learns_a_stiff_one() {
    for adapt in [true, false] {
        let mut cfg = SimConfig::default();
        cfg.plant.contact.interaction_stiffness_n_per_m = 1e6;
        cfg.servo.contact_adaptation = adapt;
        let truth = cfg.plant.contact.stiffness();
        let mut sim = Lockstep::new(&cfg).unwrap();
        let (lo, hi) = hold_range(&mut sim, 2.0);
        let in_use = sim.servo().hybrid().params().stiffness_estimate_n_per_m;
        if adapt {
            assert!(lo > 2.4 && hi < 2.6, "adapting: F_N {lo:.3}..{hi:.3} N");
            assert!(sim.servo().stiffness_adoptions() >= 1);
            assert!((in_use / truth - 1.0).abs() < 0.5, "adopted {in_use:e} N/m");
            // The dither's bound follows: the preload's penetration into the adopted contact.
            let bound = cfg
                .servo
                .dither
                .amplitude_bound(cfg.servo.hybrid.preload_n, in_use);
            assert_eq!(sim.servo().amplitude_bound(), bound);
            assert!(bound < 1e-4, "bound {bound} m");
        } else {
            assert!(lo < 0.5, "not adapting: F_N {lo:.3}..{hi:.3} N");
            assert_eq!(in_use, 10e3);
        }
    }
}

/// A servo restarted after it adopted a stiffer contact carries on bit for bit: the adopted
/// stiffness, β, the damping, the dither's bound and the fit come back with it.
#[test]
fn a_restarted_servo_keeps_what_it_learnt_of_its_contact() {
    let mut cfg = SimConfig::default();
    cfg.plant.contact.interaction_stiffness_n_per_m = 1e6;
    let mut a = Lockstep::new(&cfg).unwrap();
    let mut b = Lockstep::new(&cfg).unwrap();
    for sim in [&mut a, &mut b] {
        sim.servo_mut().hybrid_mut().set_velocity(0.005);
        sim.run(5_000);
        assert_eq!(sim.servo().stiffness_adoptions(), 1);
    }
    b.restart_servo().unwrap();
    assert_eq!(a.servo().amplitude_bound(), b.servo().amplitude_bound());
    assert_eq!(a.servo().normal_damping(), b.servo().normal_damping());
    for k in 0..5_000 {
        a.step();
        b.step();
        assert_eq!(a.truth(), b.truth(), "tick {k} after the restart");
    }
}

/// On the default contact the fit is never adopted: sliding with the tuner on, the tangent 3°
/// off, through a tangent estimation (stop, probe strokes, resume), at seeds 1 to 5, any reading tight enough
/// to be adopted (100 samples, relative error ≤ 10 %) stays below half the adoption threshold
/// of 4 times the stiffness in use, and nothing is adopted. On 10 kN/m the fit is mostly too
/// loose to be tight at all; as it starts from rest it reads 2 to 3 times the truth with a
/// relative error near 0.3, so an error gate loosened to 0.35 fails this.
#[test]
fn the_default_contact_is_not_relearnt() {
    use crate::servo::contact::{ADOPT_FACTOR, MAX_RELATIVE_ERROR, MIN_SAMPLES};
    for seed in 1..=5 {
        let cfg = SimConfig {
            seed,
            tangent_error_rad: 3f64.to_radians(),
            ..SimConfig::default()
        };
        let in_use = cfg.servo.hybrid.stiffness_estimate_n_per_m;
        let mut sim = Lockstep::new(&cfg).unwrap();
        sim.servo_mut().hybrid_mut().set_velocity(0.005);
        let mut largest = 0.0f64;
        for tick in 0..(20.0 / sim.dt()).round() as usize {
            if tick == (1.0 / sim.dt()).round() as usize {
                sim.servo_mut().request_tangent_estimate();
            }
            sim.step();
            if let Some(e) = sim.servo().stiffness_estimate()
                && e.samples >= MIN_SAMPLES
                && e.relative_error() <= MAX_RELATIVE_ERROR
            {
                largest = largest.max(e.stiffness_n_per_m / in_use);
            }
        }
        assert!(
            !sim.estimates().is_empty(),
            "seed {seed}: no tangent estimate"
        );
        assert!(
            largest < 0.5 * ADOPT_FACTOR,
            "seed {seed}: the fit read {largest:.2} × the stiffness in use"
        );
        assert_eq!(sim.servo().stiffness_adoptions(), 0, "seed {seed}");
    }
}

/// Prints docs/contact.md's figures of the stiffness fit: its reading over seeds 1..20 after
/// 5 s of sliding at 5 mm/s with the tuner on (told the truth, so nothing is adopted), and when
/// a servo told 10 kN/m adopts steel. `cargo test -p afs-shared --profile ci --lib
/// stiffness_fit_table -- --ignored --nocapture`
#[test]
#[ignore = "prints docs/contact.md's table"]
fn stiffness_fit_table() {
    println!(
        "| k_e (N/m) | fitted / true (contact and sensor in series): min, median, max over seeds 1..20 | stated relative standard error, median | fitted − true within 2 stated errors |"
    );
    println!("|---|---|---:|---:|");
    for k_e in [1e3, 1e4, 1e5, 1e6] {
        let (mut ratios, mut ses, mut within) = (Vec::new(), Vec::new(), 0);
        for seed in 1..=20 {
            let mut cfg = SimConfig::default();
            cfg.plant.contact.interaction_stiffness_n_per_m = k_e;
            cfg.servo.hybrid.stiffness_estimate_n_per_m = k_e;
            cfg.seed = seed;
            let truth = cfg.plant.contact.stiffness();
            let mut sim = Lockstep::new(&cfg).unwrap();
            sim.servo_mut().hybrid_mut().set_velocity(0.005);
            sim.run((5.0 / sim.dt()).round() as usize);
            let e = sim.servo().stiffness_estimate().unwrap();
            let r = e.stiffness_n_per_m / truth;
            ratios.push(r);
            ses.push(e.relative_error());
            if (r - 1.0).abs() <= 2.0 * e.relative_error() {
                within += 1;
            }
        }
        ratios.sort_by(f64::total_cmp);
        ses.sort_by(f64::total_cmp);
        println!(
            "| {k_e:e} | {:.2}, {:.2}, {:.2} | {:.3} | {within}/20 |",
            ratios[0], ratios[10], ratios[19], ses[10]
        );
    }
    let mut cfg = SimConfig::default();
    cfg.plant.contact.interaction_stiffness_n_per_m = 1e6;
    let truth = cfg.plant.contact.stiffness();
    let mut sim = Lockstep::new(&cfg).unwrap();
    let mut t = 0.0;
    while sim.servo().stiffness_adoptions() == 0 && t < 5.0 {
        sim.step();
        t += sim.dt();
    }
    let k = sim.servo().hybrid().params().stiffness_estimate_n_per_m;
    println!(
        "told 10 kN/m on 1 MN/m: adopted {k:.3e} N/m ({:.2} of the truth) after {t:.3} s",
        k / truth
    );
    for adapt in [false, true] {
        let mut cfg = SimConfig::default();
        cfg.plant.contact.interaction_stiffness_n_per_m = 1e6;
        cfg.servo.contact_adaptation = adapt;
        let (lo, hi) = hold_range(&mut Lockstep::new(&cfg).unwrap(), 2.0);
        println!("told 10 kN/m on 1 MN/m, adaptation {adapt}: F_N {lo:.2}–{hi:.2} N at rest");
    }
}

/// A set-up whose tool starts `gap_m` off a contact of stiffness `k_e` (N/m), at `rate_hz`;
/// the servo is told the default 10 kN/m.
fn off_the_surface(k_e: f64, rate_hz: f64, gap_m: f64) -> SimConfig {
    let mut cfg = SimConfig::default();
    cfg.plant.contact.interaction_stiffness_n_per_m = k_e;
    cfg.servo.rate_hz = rate_hz;
    cfg.start_gap_m = gap_m;
    cfg
}

/// The first touch (docs/contact.md, *First touch*): from 1 mm off the surface the guarded
/// approach touches foam and steel alike with a peak under twice the preload, no bounce, and
/// the preload settled, at 10 kHz and at 500 Hz. Approached as if the stiffest contact were
/// 10 kN/m (10 times faster), steel's impact is about 10 times the preload and the tool
/// bounces: the checks fail.
#[test]
fn a_first_touch_stays_under_twice_the_preload_at_any_stiffness() {
    use crate::experiments::{Options, touch};
    let run = |cfg: SimConfig| {
        let o = Options {
            base: cfg,
            ..Options::default()
        };
        touch(&o).unwrap()
    };
    for (k_e, rate) in [(1e3, 10_000.0), (1e6, 10_000.0), (1e3, 500.0), (1e6, 500.0)] {
        let out = run(off_the_surface(k_e, rate, 1e-3));
        let peak = out.summary.peak_normal_n / out.summary.preload_n;
        assert!(out.passed(), "{k_e:e} N/m at {rate} Hz: {:?}", out.checks);
        assert!(out.summary.touch_s.is_some() && peak > 0.9, "peak {peak}");
        assert_eq!(out.summary.adoptions, 1, "the fit replaces the assumption");
    }
    let mut fast = off_the_surface(1e6, 10_000.0, 1e-3);
    fast.servo.approach.stiffest_contact_n_per_m = 1e4;
    let out = run(fast);
    let failed: Vec<_> = out
        .checks
        .iter()
        .filter(|c| !c.pass)
        .map(|c| &c.id)
        .collect();
    assert_eq!(
        failed,
        ["peak_over_preload", "ticks_without_contact_after_touch"],
        "peak {} N",
        out.summary.peak_normal_n
    );
}

/// A servo restarted during the approach, and again just after the touch while its gains are
/// still the approach's assumption, carries on bit for bit: the mode, the provisional gains
/// and the fit cross the restart.
#[test]
fn a_servo_restarted_mid_approach_carries_on_bit_for_bit() {
    use crate::servo::ServoMode;
    let cfg = off_the_surface(1e6, 10_000.0, 0.5e-3);
    let mut a = Lockstep::new(&cfg).unwrap();
    let mut b = Lockstep::new(&cfg).unwrap();
    assert_eq!(a.servo().mode(), ServoMode::Approach);
    let mut restarted = [false; 2];
    for k in 0..40_000 {
        let approaching = b.servo().mode() == ServoMode::Approach;
        let settling = b.servo().mode() == ServoMode::Resuming;
        if (approaching && k == 5_000 && !restarted[0]) || (settling && !restarted[1]) {
            b.restart_servo().unwrap();
            restarted[usize::from(settling)] = true;
            assert_eq!(a.servo().normal_damping(), b.servo().normal_damping());
            assert_eq!(a.servo().amplitude_bound(), b.servo().amplitude_bound());
        }
        a.step();
        b.step();
        assert_eq!(a.truth(), b.truth(), "tick {k}");
    }
    assert_eq!(restarted, [true, true]);
    assert_eq!(b.servo().mode(), ServoMode::Track);
    assert_eq!(b.servo().stiffness_adoptions(), 1);
}

/// A gap or an approach setting that is not a number in range is refused by name.
#[test]
fn bad_approach_settings_are_refused_by_name() {
    for (gap, name) in [
        (-1e-3, "start_gap_m"),
        (f64::NAN, "start_gap_m"),
        (1.0, "start_gap_m"),
    ] {
        let cfg = SimConfig {
            start_gap_m: gap,
            ..SimConfig::default()
        };
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains(name), "{e}");
    }
    for (k, f) in [(0.0, 0.5), (f64::NAN, 0.5), (1e6, 0.0), (1e6, 1.0)] {
        let mut cfg = SimConfig::default();
        cfg.servo.approach.stiffest_contact_n_per_m = k;
        cfg.servo.approach.touch_fraction = f;
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains("servo.approach."), "{e}");
    }
}
