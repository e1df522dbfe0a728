//! Chapter 4 experiments: friction identification and friction suppression by tuned dither.

use super::*;
use crate::error::ExperimentError;
use crate::friction::{FrictionLaw, RoughnessMap};
use crate::ident::{
    CoefficientFit, FrictionFit, THESIS_FIG_4_6, fit_friction_coefficient, fit_friction_law,
};
use crate::sim::{Lockstep, SimConfig};
use crate::ticks::{Tick, WindowSummary, decimate, run_recording, sliding_periods, window};
use crate::tuner::{CostTunerParams, ThesisTunerParams, TunerConfig, TunerReport};
use serde::Serialize;

/// Lifts the tool off, re-zeroes the sensor in free air and presses back to the preload, as an
/// experimenter does between runs to remove the sensor's slow drift. Returns the time at the
/// middle of the averaging window (the instant the tare represents), or `None` if the tool did
/// not leave the surface (the tare is then not changed).
fn lift_and_retare(sim: &mut Lockstep) -> Option<f64> {
    let lift = 0.004;
    let ramp = (0.2 / sim.dt()).round() as usize;
    sim.servo_mut().set_force_control(false);
    for _ in 0..ramp {
        sim.servo_mut()
            .hybrid_mut()
            .shift_depth(-lift / ramp as f64);
        sim.step();
    }
    sim.run((0.3 / sim.dt()).round() as usize);
    let n = (3.0 / sim.dt()).round() as usize;
    let mut acc = crate::sensor::Wrench::default();
    let mut free = true;
    let t_mid = sim.time() + 0.5 * n as f64 * sim.dt();
    for _ in 0..n {
        sim.step();
        free &= sim.truth().contact_count == 0;
        let (r, _) = sim.reading();
        acc.force += r.wrench.force;
        acc.torque += r.wrench.torque;
    }
    if free {
        sim.servo_mut().set_tare(crate::sensor::Wrench {
            force: acc.force / n as f64,
            torque: acc.torque / n as f64,
        });
    }
    for _ in 0..ramp {
        sim.servo_mut().hybrid_mut().shift_depth(lift / ramp as f64);
        sim.step();
    }
    sim.servo_mut().set_force_control(true);
    sim.run((0.8 / sim.dt()).round() as usize);
    free.then_some(t_mid)
}

// ---------------------------------------------------------------------------------------------
// friction-id

/// Summary of `friction-id`.
#[derive(Debug, Clone, Serialize)]
pub struct FrictionIdSummary {
    /// The configured (true) law at the reference normal force.
    pub truth: FrictionLaw,
    /// The identified law and its residual.
    pub fit: FrictionFit,
    /// Relative errors (identified − true)/true: F_t, F_v, F_s, ẋ_s.
    pub relative_error: [f64; 4],
    /// (speed m/s, friction N) per velocity level, averaged over ± strokes.
    pub levels: Vec<[f64; 2]>,
    /// Levels dropped because the tool stuck and slipped (velocity spread > 30 %).
    pub dropped_levels: Vec<f64>,
    /// Levels before which the sensor could not be re-zeroed (tool did not lift off).
    pub retare_failures: usize,
}

/// Constant-velocity back-and-forth strokes at 17 speeds from 1 to 200 mm/s, no dither. The
/// friction of a stroke is the mean measured tangential force over its cruise, normalised to the
/// reference normal force by the mean measured normal force; the ± strokes of a level are
/// averaged so a residual sensor offset cancels. The tool lifts off and the sensor is re-zeroed
/// after every ~6 s of cruise, and each stroke is corrected for the drift interpolated linearly
/// between the tares around it: the viscous term F_v·v is only ~1 % of the friction at
/// 200 mm/s, so a drift of a few mN would otherwise swamp it. Fast levels repeat their strokes
/// so each level gathers at least 2 s of cruise, 40 s from 40 mm/s up.
pub fn friction_id(opts: &Options) -> Result<Outcome<FrictionIdSummary>, ExperimentError> {
    struct Stroke {
        t_mid: f64,
        force: crate::math::Vec2,
        phi: f64,
        dir: f64,
        speed: f64,
        spread: f64,
    }
    let mut cfg = config(opts, TunerConfig::Fixed);
    cfg.servo.hybrid.tangential_acceleration_m_per_s2 = 2.0;
    let truth = cfg.plant.friction;
    let f_ref = cfg.plant.reference_normal_force_n;
    let mut sim = Lockstep::new(&cfg)?;
    let speeds: [f64; 17] = [
        0.001, 0.002, 0.003, 0.005, 0.007, 0.01, 0.015, 0.02, 0.03, 0.04, 0.05, 0.07, 0.1, 0.12,
        0.15, 0.17, 0.2,
    ];
    let accel = cfg.servo.hybrid.tangential_acceleration_m_per_s2;
    let mut levels = Vec::new();
    let mut strokes_plot = Vec::new();
    let mut dropped = Vec::new();
    let mut retare_failures = 0;
    let mut tare_time = sim.time();
    match lift_and_retare(&mut sim) {
        Some(t) => tare_time = t,
        None => retare_failures += 1,
    }
    let mut tare_before = (tare_time, sim.servo().tare());
    for &v in &speeds {
        let distance = (v * 1.5).min(0.04);
        let cruise = distance / v;
        let ramp = v / accel;
        // F_v shows only at the fast levels: gather more cruise there.
        let min_cruise = if v >= 0.04 { 80.0 } else { 2.0 };
        let pairs = ((min_cruise / (2.0 * cruise)).ceil() as usize).clamp(1, 100);
        // Re-zero the sensor after every block of about 6 s of cruise.
        let per_block = ((6.0 / (2.0 * cruise)).floor() as usize).max(1);
        let (mut fsum, mut vsum, mut count, mut stuck) = (0.0, 0.0, 0.0, false);
        let mut done = 0;
        while done < pairs {
            let block = per_block.min(pairs - done);
            done += block;
            let mut strokes = Vec::new();
            for k in 0..2 * block {
                let dir = if k % 2 == 0 { 1.0 } else { -1.0 };
                sim.servo_mut().hybrid_mut().set_velocity(dir * v);
                let n_total = (cruise / sim.dt()).round() as usize;
                let n_skip = ((ramp + 0.05 + 0.1 * cruise) / sim.dt()).round() as usize;
                let (mut f, mut ts, mut phi, mut vs, mut v2, mut c) =
                    (crate::math::Vec2::zeros(), 0.0, 0.0, 0.0, 0.0, 0.0);
                for i in 0..n_total {
                    sim.step();
                    if i >= n_skip {
                        let d = *sim.servo().diag();
                        let frame = *sim.servo().hybrid().frame();
                        f += frame.normal() * d.normal_force_n
                            + frame.tangent() * d.tangential_force_n;
                        ts += sim.time();
                        let q = sim.plant().joints().0;
                        phi += q[0] + q[1];
                        let vv = d.tangent_velocity_m_per_s * dir;
                        vs += vv;
                        v2 += vv * vv;
                        c += 1.0;
                    }
                }
                sim.servo_mut().hybrid_mut().set_velocity(0.0);
                sim.run(((ramp + 0.1) / sim.dt()).round() as usize);
                if c > 0.0 {
                    let mv = vs / c;
                    strokes.push(Stroke {
                        t_mid: ts / c,
                        force: f / c,
                        phi: phi / c,
                        dir,
                        speed: mv,
                        spread: (v2 / c - mv * mv).max(0.0).sqrt(),
                    });
                }
            }
            match lift_and_retare(&mut sim) {
                Some(t) => tare_time = t,
                None => retare_failures += 1,
            }
            let tare_after = (tare_time, sim.servo().tare());
            // Drift of the sensor between the two tares, in the sensor frame.
            let drift = tare_after.1.force - tare_before.1.force;
            let span = (tare_after.0 - tare_before.0).max(1e-9);
            let frame = *sim.servo().hybrid().frame();
            for st in &strokes {
                let frac = (st.t_mid - tare_before.0) / span;
                let (sn, cs) = st.phi.sin_cos();
                let dw = drift * frac;
                let drift_world =
                    crate::math::Vec2::new(cs * dw.x - sn * dw.y, sn * dw.x + cs * dw.y);
                let corrected = st.force - drift_world;
                let normal = corrected.dot(&frame.normal());
                let friction = -corrected.dot(&frame.tangent()) * st.dir * f_ref / normal;
                stuck |= st.spread > 0.3 * st.speed;
                strokes_plot.push([st.speed, friction]);
                fsum += friction;
                vsum += st.speed;
                count += 1.0;
            }
            tare_before = tare_after;
        }
        if stuck || count == 0.0 {
            dropped.push(v);
        } else {
            levels.push([vsum / count, fsum / count]);
        }
    }
    let data: Vec<(f64, f64)> = levels.iter().map(|p| (p[0], p[1])).collect();
    let fit = fit_friction_law(&data).map_err(|e| ExperimentError::no_result("friction-id", e))?;
    let rel = |a: f64, b: f64| (a - b) / b;
    let relative_error = [
        rel(fit.law.kinetic_n, truth.kinetic_n),
        rel(fit.law.viscous_n_s_per_m, truth.viscous_n_s_per_m),
        rel(fit.law.stribeck_n, truth.stribeck_n),
        rel(
            fit.law.stribeck_velocity_m_per_s,
            truth.stribeck_velocity_m_per_s,
        ),
    ];
    let checks = vec![
        Check::at_most(
            "rezero_failures",
            "sensor re-zeroing failures",
            retare_failures as f64,
            0.0,
        ),
        Check::at_most(
            "kinetic_error",
            "|F_t error| (fraction)",
            relative_error[0].abs(),
            0.05,
        ),
        Check::at_most(
            "viscous_error",
            "|F_v error| (fraction)",
            relative_error[1].abs(),
            0.05,
        ),
        Check::at_most(
            "stribeck_error",
            "|F_s error| (fraction)",
            relative_error[2].abs(),
            0.05,
        ),
        Check::at_most(
            "stribeck_velocity_error",
            "|x_s error| (fraction)",
            relative_error[3].abs(),
            0.10,
        ),
    ];
    let curve = |law: FrictionLaw| -> Vec<[f64; 2]> {
        (0..200)
            .map(|k| {
                let v = 5e-4 * (400f64).powf(k as f64 / 199.0);
                [v * 1e3, law.resistance(v)]
            })
            .collect()
    };
    let figure = Figure {
        title: "friction-id: constant-velocity strokes and eq. 4.5".into(),
        x_label: "sliding speed (mm/s)".into(),
        log_x: true,
        panels: vec![Panel {
            x_label: None,
            y_label: "friction force (N)".into(),
            series: vec![
                markers(
                    "strokes (measured)",
                    strokes_plot.iter().map(|p| [p[0] * 1e3, p[1]]).collect(),
                ),
                markers(
                    "level means",
                    levels.iter().map(|p| [p[0] * 1e3, p[1]]).collect(),
                ),
                series("truth (eq. 4.23)", curve(truth)),
                series("identified", curve(fit.law)),
            ],
        }],
    };
    Ok(Outcome {
        summary: FrictionIdSummary {
            truth,
            fit,
            relative_error,
            levels,
            dropped_levels: dropped,
            retare_failures,
        },
        checks,
        simulated_s: sim.time(),
        figure,
    })
}

// ---------------------------------------------------------------------------------------------
// fig4.5

/// Summary of `fig4.5`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig45Summary {
    /// Nominal velocity ẋ_o (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Commanded Aω (m/s) of the dithered run.
    pub a_omega_commanded_m_per_s: f64,
    /// The traverse without dither.
    pub without_dither: WindowSummary,
    /// The traverse with dither.
    pub with_dither: WindowSummary,
    /// Dithered / undithered mean friction.
    pub mean_ratio: f64,
    /// Cycle average of eq. 4.5 by quadrature at the ẋ_o and Aω the contact saw, times the
    /// mean friction scale (N).
    pub quadrature_mean_seen_n: f64,
    /// The same at the commanded Aω (N): what a perfect servo would give.
    pub quadrature_mean_commanded_n: f64,
    /// (measured − quadrature at seen)/quadrature at seen.
    pub gap_to_quadrature: f64,
    /// Aω seen / Aω commanded: the servo's attenuation of the dither.
    pub transmission: f64,
}

/// The same 6 s traverse at 10 mm/s over a surface with seeded rough patches, once without
/// dither and once with Aω = 5ẋ_o (statistics over whole dither periods from 1 s to 6 s).
pub fn fig4_5(opts: &Options) -> Result<Outcome<Fig45Summary>, ExperimentError> {
    let v = 0.01;
    let duration = 6.0;
    let ratio = 5.0;
    let mut cfg = config(opts, TunerConfig::Fixed);
    cfg.start_u_m = -0.5 * v * duration;
    cfg.plant.roughness =
        RoughnessMap::random(opts.seed, cfg.start_u_m, v * duration, 12, 0.003, 0.4);
    let mut runs = Vec::new();
    let mut traces = Vec::new();
    let mut simulated = 0.0;
    for a in [0.0, ratio * v] {
        let mut sim = Lockstep::new(&cfg)?;
        sim.servo_mut().hybrid_mut().set_velocity(v);
        sim.servo_mut().set_a_omega(a);
        let mut ticks = Vec::with_capacity((duration / sim.dt()) as usize + 1);
        let mut ph = 0.0;
        run_recording(&mut sim, duration, &mut ticks, &mut ph);
        simulated += sim.time();
        runs.push(window(&ticks, 1.0, duration));
        traces.push(ticks);
    }
    let (off, on) = (runs[0], runs[1]);
    let law = cfg.plant.friction;
    let (q_seen, _) = law.cycle_by_quadrature(on.velocity_seen_m_per_s, on.a_omega_seen_m_per_s);
    let (q_cmd, _) = law.cycle_by_quadrature(on.velocity_seen_m_per_s, ratio * v);
    let q_seen = q_seen * on.friction_scale;
    let q_cmd = q_cmd * on.friction_scale;
    let mean_ratio = on.mean_force_n / off.mean_force_n;
    let gap = (on.mean_force_n - q_seen) / q_seen;
    let checks = vec![
        Check::at_most(
            "dithered_over_undithered_friction",
            "dithered / undithered mean friction",
            mean_ratio,
            0.20,
        ),
        Check::at_most(
            "dithered_mean_over_quadrature_error",
            "|dithered mean − quadrature at seen velocity| / quadrature",
            gap.abs(),
            0.15,
        ),
    ];
    let running = |ticks: &[Tick]| -> Vec<[f64; 2]> {
        sliding_periods(ticks, 1)
            .iter()
            .map(|p| [p[0], p[1]])
            .collect()
    };
    let figure = Figure {
        title: format!(
            "fig4.5: friction without and with dither (Aω = {ratio}·ẋ_o, ẋ_o = {} mm/s)",
            v * 1e3
        ),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "tangential force, no dither (N)".into(),
                series: vec![
                    series("measured", decimate(&traces[0], 10, |k| k.friction)),
                    series("mean per period", running(&traces[0])),
                ],
            },
            Panel {
                x_label: None,
                y_label: "tangential force, dither (N)".into(),
                series: vec![
                    series("measured", decimate(&traces[1], 10, |k| k.friction)),
                    series("mean per period", running(&traces[1])),
                ],
            },
        ],
    };
    Ok(Outcome {
        summary: Fig45Summary {
            nominal_velocity_m_per_s: v,
            a_omega_commanded_m_per_s: ratio * v,
            without_dither: off,
            with_dither: on,
            mean_ratio,
            quadrature_mean_seen_n: q_seen,
            quadrature_mean_commanded_n: q_cmd,
            gap_to_quadrature: gap,
            transmission: on.a_omega_seen_m_per_s / (ratio * v),
        },
        checks,
        simulated_s: simulated,
        figure,
    })
}

// ---------------------------------------------------------------------------------------------
// fig4.6

/// Summary of `fig4.6`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig46Summary {
    /// "thesis-table" or "simulated".
    pub source: &'static str,
    /// (F_N, F_t) per trial (N).
    pub trials: Vec<[f64; 2]>,
    /// The fit.
    pub fit: CoefficientFit,
    /// The coefficient as the thesis prints it (3 decimals).
    pub coefficient: String,
    /// Simulated only: the true μ = eq. 4.5 at the trial speed / reference normal force.
    pub true_mu: Option<f64>,
    /// Simulated only: (μ − true)/true.
    pub relative_error: Option<f64>,
}

/// μ from six trials at the thesis's normal forces (1.75–5.26 N), each a ± stroke pair at
/// 20 mm/s without dither; or, with `thesis_table`, from the six trials printed in fig. 4.6.
pub fn fig4_6(opts: &Options) -> Result<Outcome<Fig46Summary>, ExperimentError> {
    let (trials, simulated, true_mu, speed) = if opts.thesis_table {
        (
            THESIS_FIG_4_6
                .iter()
                .map(|&(a, b)| [a, b])
                .collect::<Vec<_>>(),
            0.0,
            None,
            None,
        )
    } else {
        let cfg = config(opts, TunerConfig::Fixed);
        let mut sim = Lockstep::new(&cfg)?;
        let v = 0.02;
        let mut trials = Vec::new();
        let mut vsum = 0.0;
        for &(preload, _) in THESIS_FIG_4_6.iter() {
            sim.servo_mut().hybrid_mut().set_preload(preload);
            sim.run((1.5 / sim.dt()) as usize);
            let (mut fsum, mut nsum, mut c) = (0.0, 0.0, 0.0);
            for dir in [1.0, -1.0] {
                sim.servo_mut().hybrid_mut().set_velocity(dir * v);
                for k in 0..(1.5 / sim.dt()) as usize {
                    sim.step();
                    if k as f64 * sim.dt() >= 0.3 {
                        let d = sim.servo().diag();
                        fsum += -d.tangential_force_n * dir;
                        nsum += d.normal_force_n;
                        vsum += d.tangent_velocity_m_per_s * dir;
                        c += 1.0;
                    }
                }
                sim.servo_mut().hybrid_mut().set_velocity(0.0);
                sim.run((0.3 / sim.dt()) as usize);
            }
            trials.push([nsum / c, fsum / c]);
        }
        let n_samples = 2.0 * THESIS_FIG_4_6.len() as f64 * ((1.5 - 0.3) / sim.dt()).round();
        let speed = vsum / n_samples;
        let mu = cfg.plant.friction.resistance(speed) / cfg.plant.reference_normal_force_n;
        (trials, sim.time(), Some(mu), Some(speed))
    };
    let pairs: Vec<(f64, f64)> = trials.iter().map(|p| (p[0], p[1])).collect();
    let fit =
        fit_friction_coefficient(&pairs).map_err(|e| ExperimentError::no_result("fig4.6", e))?;
    let relative_error = true_mu.map(|m| (fit.mu - m) / m);
    let mut checks = Vec::new();
    if let Some(e) = relative_error {
        checks.push(Check::at_most(
            "mu_error",
            "|μ − true μ| / true μ",
            e.abs(),
            0.03,
        ));
    } else {
        checks.push(Check::at_most(
            "mu_error_to_thesis_table",
            "|μ − 0.709| (thesis table)",
            (fit.mu - 0.709).abs(),
            0.0005,
        ));
    }
    let fmax = trials.iter().map(|p| p[0]).fold(0.0, f64::max) * 1.1;
    let mut series_list = vec![
        markers("trials", trials.clone()),
        series(
            &format!("F_t = {:.3}·F_N (mean of ratios)", fit.mu),
            vec![[0.0, 0.0], [fmax, fit.mu * fmax]],
        ),
        series(
            &format!("F_t = {:.3}·F_N (least squares)", fit.mu_least_squares),
            vec![[0.0, 0.0], [fmax, fit.mu_least_squares * fmax]],
        ),
    ];
    if let Some(m) = true_mu {
        series_list.push(series(
            &format!("truth μ = {m:.3} at {:.1} mm/s", speed.unwrap_or(0.0) * 1e3),
            vec![[0.0, 0.0], [fmax, m * fmax]],
        ));
    }
    let figure = Figure {
        title: format!(
            "fig4.6: tangential vs normal force, coefficient of friction {:.3}",
            fit.mu
        ),
        x_label: "normal force F_N (N)".into(),
        log_x: false,
        panels: vec![Panel {
            x_label: None,
            y_label: "tangential force F_t (N)".into(),
            series: series_list,
        }],
    };
    Ok(Outcome {
        summary: Fig46Summary {
            source: if opts.thesis_table {
                "thesis-table"
            } else {
                "simulated"
            },
            trials,
            coefficient: format!("{:.3}", fit.mu),
            fit,
            true_mu,
            relative_error,
        },
        checks,
        simulated_s: simulated,
        figure,
    })
}

// ---------------------------------------------------------------------------------------------
// fig4.7

/// One amplitude step of `fig4.7`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct AmplitudeStep {
    /// Commanded dither amplitude (m).
    pub amplitude_m: f64,
    /// Statistics over the step's last 0.8 s.
    pub window: WindowSummary,
    /// Model standard deviation: eq. 4.5 over the cycle at the seen velocities, plus the tool's
    /// inertial force m ω Aω/√2 (N).
    pub model_std_n: f64,
    /// Worst |F_N − preload| / preload over the window, true force.
    pub normal_worst_deviation: f64,
}

/// Summary of `fig4.7`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig47Summary {
    /// σ at 6 mm / σ at 1 mm: over the thesis's 5 mm increase. The thesis saw the oscillation
    /// double. On afs's rig, once the dither reverses the motion, σ is set by the friction
    /// reversal (≈ F_t) and the tool's inertial force adds little; on the thesis's rig the
    /// normal force swings with the dither and the friction with it
    /// (docs/friction-suppression.md §8).
    pub growth_ratio: f64,
    /// The same ratio of the model σ (eq. 4.5 over the cycle plus the tool's inertia).
    pub model_growth_ratio: f64,
    /// Nominal velocity (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Dither frequency (Hz).
    pub frequency_hz: f64,
    /// Per step.
    pub steps: Vec<AmplitudeStep>,
}

/// At a low nominal velocity (2 mm/s) the dither amplitude is raised every second, 0 to 6 mm;
/// the oscillation of the tangential force is measured per step and compared with the model.
pub fn fig4_7(opts: &Options) -> Result<Outcome<Fig47Summary>, ExperimentError> {
    let v = 0.002;
    // The thesis saw the oscillation double over a 5 mm increase: steps of 1 mm to 6 mm. The
    // surface is flat and its tangent known exactly here, so the amplitude bound (kept for a
    // tangent known to ±3°) is lifted to 6 mm on both rigs.
    let amplitudes = [0.0, 1e-3, 2e-3, 3e-3, 4e-3, 5e-3, 6e-3];
    let mut cfg = config(opts, TunerConfig::Fixed);
    cfg.servo.dither.max_amplitude_m = cfg.servo.dither.max_amplitude_m.max(6e-3);
    cfg.servo.dither.tangent_uncertainty_deg = cfg.servo.dither.tangent_uncertainty_deg.min(1.5);
    cfg.start_u_m = -0.5 * v * amplitudes.len() as f64;
    let mut sim = Lockstep::new(&cfg)?;
    let omega = cfg.servo.dither.omega();
    sim.servo_mut().hybrid_mut().set_velocity(v);
    let mut ticks = Vec::new();
    let mut ph = 0.0;
    let mut steps = Vec::new();
    let law = cfg.plant.friction;
    for &a in &amplitudes {
        let t0 = sim.time();
        sim.servo_mut().set_a_omega(a * omega);
        run_recording(&mut sim, 1.0, &mut ticks, &mut ph);
        let w = window(&ticks, t0 + 0.2, sim.time());
        let st = law
            .scaled(w.friction_scale)
            .cycle(w.velocity_seen_m_per_s, w.a_omega_seen_m_per_s);
        let inertial = cfg.plant.tool_mass_kg * omega * w.a_omega_seen_m_per_s / 2f64.sqrt();
        let model_std = (st.std().powi(2) + inertial.powi(2)).sqrt();
        let preload = cfg.servo.hybrid.preload_n;
        let normal_worst = ticks
            .iter()
            .filter(|k| k.t >= t0 + 0.2)
            .map(|k| (k.normal_true - preload).abs() / preload)
            .fold(0.0, f64::max);
        steps.push(AmplitudeStep {
            amplitude_m: a,
            window: w,
            model_std_n: model_std,
            normal_worst_deviation: normal_worst,
        });
    }
    let undithered = steps[0].window.std_force_n.max(1e-9);
    let smallest_dithered = steps
        .iter()
        .skip(1)
        .map(|s| s.window.std_force_n)
        .fold(f64::INFINITY, f64::min);
    let worst_model_gap = steps
        .iter()
        .filter(|s| s.amplitude_m > 0.0)
        .map(|s| (s.window.std_force_n - s.model_std_n).abs() / s.model_std_n)
        .fold(0.0, f64::max);
    let growth = steps[6].window.std_force_n / steps[1].window.std_force_n;
    let model_growth = steps[6].model_std_n / steps[1].model_std_n;
    let mut checks = vec![
        Check::at_least(
            "dithered_over_undithered_sigma_min",
            "smallest dithered σ / undithered σ",
            smallest_dithered / undithered,
            10.0,
        ),
        Check::at_most(
            "sigma_model_error_max",
            "worst |σ measured − σ model| / σ model",
            worst_model_gap,
            0.25,
        ),
    ];
    checks.push(match opts.rig {
        // afs's rig: the growth is the model's (friction reversal plus tool inertia).
        crate::setups::Rig::Afs => Check::at_most(
            "sigma_growth_model_error",
            "|σ growth 1 → 6 mm − model growth|",
            (growth - model_growth).abs(),
            0.1,
        ),
        // The thesis's rig: the growth the thesis saw (it doubled over 5 mm).
        crate::setups::Rig::Thesis => {
            Check::at_least("sigma_growth_1_to_6_mm", "σ growth 1 → 6 mm", growth, 1.5)
        }
    });
    let mut mean_removed = Vec::new();
    for (i, s) in steps.iter().enumerate() {
        let lo = i as f64;
        for k in ticks
            .iter()
            .filter(|k| k.t > lo && k.t <= lo + 1.0)
            .step_by(5)
        {
            mean_removed.push([k.t, k.friction - s.window.mean_force_n]);
        }
    }
    let figure = Figure {
        title: "fig4.7: oscillation of the tangential force as the dither amplitude rises".into(),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "tangential force about its step mean (N)".into(),
                series: vec![series("measured", mean_removed)],
            },
            Panel {
                x_label: None,
                y_label: "std of tangential force (N)".into(),
                series: vec![
                    markers(
                        "measured",
                        steps
                            .iter()
                            .enumerate()
                            .map(|(i, s)| [i as f64 + 0.6, s.window.std_force_n])
                            .collect(),
                    ),
                    markers(
                        "model",
                        steps
                            .iter()
                            .enumerate()
                            .map(|(i, s)| [i as f64 + 0.6, s.model_std_n])
                            .collect(),
                    ),
                ],
            },
            Panel {
                x_label: None,
                y_label: "dither amplitude (mm)".into(),
                series: vec![series(
                    "commanded",
                    decimate(&ticks, 100, |k| k.a_cmd / omega * 1e3),
                )],
            },
        ],
    };
    Ok(Outcome {
        summary: Fig47Summary {
            growth_ratio: growth,
            model_growth_ratio: model_growth,
            nominal_velocity_m_per_s: v,
            frequency_hz: cfg.servo.dither.frequency_hz,
            steps,
        },
        checks,
        simulated_s: sim.time(),
        figure,
    })
}

// ---------------------------------------------------------------------------------------------
// fig4.8

/// One tuner's run in `fig4.8`.
#[derive(Debug, Clone, Serialize)]
pub struct TunerRun {
    /// "thesis" or "cost".
    pub tuner: &'static str,
    /// Mean friction at the start, Aω = 0.2 ẋ_o (N).
    pub start_mean_n: f64,
    /// Mean friction over the 3 periods ending 5 s after tuning started (N).
    pub mean_at_5s_n: f64,
    /// mean_at_5s / start.
    pub ratio_at_5s: f64,
    /// First time (s after tuning started) the 3-period mean fell below 25 % of the start.
    pub time_to_quarter_s: Option<f64>,
    /// Worst |F_N − preload| / preload after 0.5 s, true force.
    pub worst_normal_deviation: f64,
    /// Same on the measured (noisy) force.
    pub worst_normal_deviation_measured: f64,
    /// Smallest true normal force over the run (N).
    pub min_normal_n: f64,
    /// Aω averaged over the last second (m/s).
    pub settled_a_omega_m_per_s: f64,
    /// settled Aω / ẋ_o.
    pub settled_ratio: f64,
    /// Change of Aω over the last second ((m/s)/s).
    pub final_rate_m_per_s2: f64,
    /// Upper bound of Aω (m/s).
    pub a_omega_bound_m_per_s: f64,
    /// The tuner's final state.
    pub report: TunerReport,
    /// Where it settles and why.
    pub why: String,
}

/// Summary of `fig4.8`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig48Summary {
    /// Nominal velocity (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Preload (N).
    pub preload_n: f64,
    /// Per tuner.
    pub runs: Vec<TunerRun>,
}

/// Each tuner runs on the same 6.5 s traverse at 10 mm/s: 0.5 s at Aω = 0.2 ẋ_o (the starting
/// value), then tuning on line.
pub fn fig4_8(opts: &Options) -> Result<Outcome<Fig48Summary>, ExperimentError> {
    let v = 0.01;
    let duration = 6.5;
    let t_tune = 0.5;
    let mut runs = Vec::new();
    let mut checks = Vec::new();
    let mut simulated = 0.0;
    let mut panels = vec![
        Panel {
            x_label: None,
            y_label: "Aω (mm/s)".into(),
            series: vec![],
        },
        Panel {
            x_label: None,
            y_label: "mean tangential force, 3 periods (N)".into(),
            series: vec![],
        },
        Panel {
            x_label: None,
            y_label: "std of tangential force, 3 periods (N)".into(),
            series: vec![],
        },
        Panel {
            x_label: None,
            y_label: "normal force (N)".into(),
            series: vec![],
        },
    ];
    for tuner in [
        TunerConfig::Thesis(ThesisTunerParams::default()),
        TunerConfig::Cost(CostTunerParams::default()),
    ] {
        let mut cfg = config(opts, tuner);
        cfg.start_u_m = -0.5 * v * duration;
        let preload = cfg.servo.hybrid.preload_n;
        let mut sim = Lockstep::new(&cfg)?;
        sim.servo_mut().hybrid_mut().set_velocity(v);
        sim.servo_mut().set_a_omega(0.2 * v);
        let mut ticks = Vec::new();
        let mut ph = 0.0;
        run_recording(&mut sim, t_tune, &mut ticks, &mut ph);
        sim.servo_mut().set_tuning(true);
        run_recording(&mut sim, duration - t_tune, &mut ticks, &mut ph);
        simulated += sim.time();
        let name = sim.servo().tuner_name();
        let start = window(&ticks, 0.15, t_tune).mean_force_n;
        let sliding = sliding_periods(&ticks, 3);
        let at5 = sliding
            .iter()
            .rfind(|p| p[0] <= t_tune + 5.0 + 1e-9)
            .map_or(f64::NAN, |p| p[1]);
        let quarter = sliding
            .iter()
            .find(|p| p[0] > t_tune && p[1] < 0.25 * start)
            .map(|p| p[0] - t_tune);
        let after: Vec<&Tick> = ticks.iter().filter(|k| k.t >= 0.5).collect();
        let worst = after
            .iter()
            .map(|k| (k.normal_true - preload).abs() / preload)
            .fold(0.0, f64::max);
        let worst_meas = after
            .iter()
            .map(|k| (k.normal - preload).abs() / preload)
            .fold(0.0, f64::max);
        let min_normal = ticks
            .iter()
            .map(|k| if k.contact { k.normal_true } else { 0.0 })
            .fold(f64::INFINITY, f64::min);
        let last: Vec<&Tick> = ticks.iter().filter(|k| k.t > duration - 1.0).collect();
        let settled = last.iter().map(|k| k.a_cmd).sum::<f64>() / last.len().max(1) as f64;
        let rate = last.last().map_or(0.0, |k| k.a_cmd) - last.first().map_or(0.0, |k| k.a_cmd);
        let report = sim.servo().tuner_report();
        let bound = sim.servo().tuner_context().a_max;
        let why = explain(name, &report, settled, rate, bound, v, &cfg);
        checks.push(Check::at_most(
            format!("{name}_mean_at_5s_over_start"),
            format!("{name}: mean at 5 s / start"),
            at5 / start,
            0.25,
        ));
        checks.push(Check::at_most(
            format!("{name}_normal_deviation_max"),
            format!("{name}: worst |F_N − preload|/preload after 0.5 s"),
            worst,
            0.10,
        ));
        checks.push(Check::at_least(
            format!("{name}_normal_force_min_n"),
            format!("{name}: smallest normal force (N), contact kept"),
            min_normal,
            1e-6,
        ));
        let ms = |s: &[[f64; 3]], i: usize| -> Vec<[f64; 2]> {
            s.iter().map(|p| [p[0], p[i]]).collect()
        };
        panels[0]
            .series
            .push(series(name, decimate(&ticks, 100, |k| k.a_cmd * 1e3)));
        panels[1].series.push(series(name, ms(&sliding, 1)));
        panels[2].series.push(series(name, ms(&sliding, 2)));
        panels[3]
            .series
            .push(series(name, decimate(&ticks, 20, |k| k.normal_true)));
        runs.push(TunerRun {
            tuner: name,
            start_mean_n: start,
            mean_at_5s_n: at5,
            ratio_at_5s: at5 / start,
            time_to_quarter_s: quarter,
            worst_normal_deviation: worst,
            worst_normal_deviation_measured: worst_meas,
            min_normal_n: min_normal,
            settled_a_omega_m_per_s: settled,
            settled_ratio: settled / v,
            final_rate_m_per_s2: rate,
            a_omega_bound_m_per_s: bound,
            report,
            why,
        });
    }
    let preload = opts.base.servo.hybrid.preload_n;
    Ok(Outcome {
        summary: Fig48Summary {
            nominal_velocity_m_per_s: v,
            preload_n: preload,
            runs,
        },
        checks,
        simulated_s: simulated,
        figure: Figure {
            title:
                "fig4.8: on-line dither tuning from Aω = 0.2·ẋ_o (thesis eq. 4.22 vs cost tuner)"
                    .into(),
            x_label: "time (s)".into(),
            log_x: false,
            panels,
        },
    })
}

/// The slow on-line tuning run behind `fig4.9` and `fig4.10`.
struct SlowTuning {
    ticks: Vec<Tick>,
    nominal: f64,
    preload: f64,
    tune_at: f64,
    duration: f64,
    learning_rate: f64,
    simulated: f64,
}

/// The thesis's tuner (eq. 4.22) at half its default learning rate ("kept at a very
/// low value so that the gradual effect of the parameter change could be visualized"), from
/// Aω = 0.2 ẋ_o at 10 mm/s: 1 s untuned, then 6 s of tuning.
fn slow_tuning(opts: &Options) -> Result<SlowTuning, ExperimentError> {
    let v = 0.01;
    let (tune_at, duration) = (1.0, 7.0);
    let params = ThesisTunerParams {
        learning_rate: 0.5 * ThesisTunerParams::default().learning_rate,
        ..Default::default()
    };
    let mut cfg = config(opts, TunerConfig::Thesis(params));
    cfg.start_u_m = -0.5 * v * duration;
    let mut sim = Lockstep::new(&cfg)?;
    sim.servo_mut().hybrid_mut().set_velocity(v);
    sim.servo_mut().set_a_omega(0.2 * v);
    let mut ticks = Vec::with_capacity((duration / sim.dt()) as usize + 1);
    let mut ph = 0.0;
    run_recording(&mut sim, tune_at, &mut ticks, &mut ph);
    sim.servo_mut().set_tuning(true);
    run_recording(&mut sim, duration - tune_at, &mut ticks, &mut ph);
    Ok(SlowTuning {
        ticks,
        nominal: v,
        preload: cfg.servo.hybrid.preload_n,
        tune_at,
        duration,
        learning_rate: params.learning_rate,
        simulated: sim.time(),
    })
}

impl SlowTuning {
    /// First time the commanded Aω exceeds ẋ_o (s).
    fn crossing(&self) -> Option<f64> {
        self.ticks
            .iter()
            .find(|k| k.a_cmd > self.nominal)
            .map(|k| k.t)
    }
}

/// Summary of `fig4.9`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig49Summary {
    /// Nominal velocity ẋ_o (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Learning rate of eq. 4.22 (half the default).
    pub learning_rate: f64,
    /// When tuning starts (s).
    pub tuning_starts_s: f64,
    /// When the commanded Aω first exceeds ẋ_o (s).
    pub crossing_s: Option<f64>,
    /// Mean friction before tuning, Aω = 0.2 ẋ_o (N).
    pub mean_before_n: f64,
    /// Standard deviation of the friction before tuning (N).
    pub std_before_n: f64,
    /// Largest 1-period standard deviation within ±0.5 s of the crossing (N): the thesis's
    /// "the signal became worse" in the transition.
    pub std_in_transition_n: f64,
    /// Mean friction over the last second (N).
    pub mean_last_s_n: f64,
    /// mean_last_s / mean_before.
    pub ratio_last_s: f64,
}

/// The thesis's fig. 4.9: a slow tuning that takes Aω from below ẋ_o to above it; the mean
/// friction is steady and non-zero while ẋ_o dominates, then falls towards zero once Aω passes
/// ẋ_o.
pub fn fig4_9(opts: &Options) -> Result<Outcome<Fig49Summary>, ExperimentError> {
    let run = slow_tuning(opts)?;
    let before = window(&run.ticks, 0.2, run.tune_at);
    let last = window(&run.ticks, run.duration - 1.0, run.duration);
    let crossing = run.crossing();
    let per_period = sliding_periods(&run.ticks, 1);
    let std_transition = crossing.map_or(f64::NAN, |tc| {
        per_period
            .iter()
            .filter(|p| (p[0] - tc).abs() <= 0.5)
            .map(|p| p[2])
            .fold(0.0, f64::max)
    });
    let ratio = last.mean_force_n / before.mean_force_n;
    let checks = vec![
        Check::at_most(
            "a_omega_crosses_nominal_velocity",
            "Aω crosses ẋ_o, seconds after tuning starts",
            crossing.map_or(f64::INFINITY, |t| t - run.tune_at),
            run.duration - run.tune_at - 2.0,
        ),
        Check::at_most(
            "last_second_over_before_friction",
            "mean friction over the last second / before",
            ratio,
            0.15,
        ),
    ];
    let three = sliding_periods(&run.ticks, 3);
    let v = run.nominal;
    let figure = Figure {
        title: "fig4.9: slow tuning (eq. 4.22), the mean friction as Aω passes ẋ_o".into(),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "tangential force (N)".into(),
                series: vec![
                    series("measured", decimate(&run.ticks, 10, |k| k.friction)),
                    series(
                        "mean, 3 periods",
                        three.iter().map(|p| [p[0], p[1]]).collect(),
                    ),
                ],
            },
            Panel {
                x_label: None,
                y_label: "Aω / ẋ_o".into(),
                series: vec![series(
                    "commanded",
                    decimate(&run.ticks, 100, |k| k.a_cmd / v),
                )],
            },
        ],
    };
    Ok(Outcome {
        summary: Fig49Summary {
            nominal_velocity_m_per_s: v,
            learning_rate: run.learning_rate,
            tuning_starts_s: run.tune_at,
            crossing_s: crossing,
            mean_before_n: before.mean_force_n,
            std_before_n: before.std_force_n,
            std_in_transition_n: std_transition,
            mean_last_s_n: last.mean_force_n,
            ratio_last_s: ratio,
        },
        checks,
        simulated_s: run.simulated,
        figure,
    })
}

/// Summary of `fig4.10`.
#[derive(Debug, Clone, Serialize)]
pub struct Fig410Summary {
    /// Nominal velocity ẋ_o (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Preload (N).
    pub preload_n: f64,
    /// Commanded Aω before tuning and at the end (m/s).
    pub a_omega_m_per_s: [f64; 2],
    /// 3-period standard deviation of the tangential force before tuning and over the last
    /// second (N).
    pub std_n: [f64; 2],
    /// Correlation over the run between the 3-period σ and the commanded Aω at its end.
    pub std_amplitude_correlation: f64,
    /// Standard deviation of the true normal force after tuning starts / preload.
    pub normal_std_fraction: f64,
    /// Worst |F_N − preload| / preload after tuning starts, true force.
    pub normal_worst_fraction: f64,
}

/// The thesis's fig. 4.10: the same slow tuning, the amplitude and the oscillation it brings,
/// with the normal force alongside.
pub fn fig4_10(opts: &Options) -> Result<Outcome<Fig410Summary>, ExperimentError> {
    let run = slow_tuning(opts)?;
    let three = sliding_periods(&run.ticks, 3);
    let a_at = |t: f64| {
        run.ticks
            .iter()
            .rfind(|k| k.t <= t)
            .map_or(f64::NAN, |k| k.a_cmd)
    };
    let pairs: Vec<[f64; 2]> = three.iter().map(|p| [a_at(p[0]), p[2]]).collect();
    let corr = crate::math::correlation(&pairs);
    let before = window(&run.ticks, 0.2, run.tune_at);
    let last = window(&run.ticks, run.duration - 1.0, run.duration);
    let after: Vec<&Tick> = run.ticks.iter().filter(|k| k.t >= run.tune_at).collect();
    let n = after.len().max(1) as f64;
    let mean_n = after.iter().map(|k| k.normal_true).sum::<f64>() / n;
    let std_n = (after
        .iter()
        .map(|k| (k.normal_true - mean_n).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let worst = after
        .iter()
        .map(|k| (k.normal_true - run.preload).abs() / run.preload)
        .fold(0.0, f64::max);
    let checks = vec![
        Check::at_least(
            "sigma_last_second_over_before",
            "σ over the last second / σ before tuning",
            last.std_force_n / before.std_force_n,
            10.0,
        ),
        Check::at_most(
            "normal_force_std_over_preload",
            "std of the normal force after tuning starts / preload",
            std_n / run.preload,
            0.05,
        ),
    ];
    let v = run.nominal;
    let figure = Figure {
        title: "fig4.10: slow tuning (eq. 4.22), amplitude, oscillation and normal force".into(),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "dither amplitude A (mm)".into(),
                series: vec![series(
                    "commanded",
                    decimate(&run.ticks, 100, |k| {
                        k.a_cmd / opts.base.servo.dither.omega() * 1e3
                    }),
                )],
            },
            Panel {
                x_label: None,
                y_label: "std of tangential force, 3 periods (N)".into(),
                series: vec![series(
                    "measured",
                    three.iter().map(|p| [p[0], p[2]]).collect(),
                )],
            },
            Panel {
                x_label: None,
                y_label: "normal force (N)".into(),
                series: vec![
                    series("true", decimate(&run.ticks, 10, |k| k.normal_true)),
                    series(
                        "preload",
                        vec![[0.0, run.preload], [run.duration, run.preload]],
                    ),
                ],
            },
        ],
    };
    Ok(Outcome {
        summary: Fig410Summary {
            nominal_velocity_m_per_s: v,
            preload_n: run.preload,
            a_omega_m_per_s: [0.2 * v, a_at(run.duration)],
            std_n: [before.std_force_n, last.std_force_n],
            std_amplitude_correlation: corr,
            normal_std_fraction: std_n / run.preload,
            normal_worst_fraction: worst,
        },
        checks,
        simulated_s: run.simulated,
        figure,
    })
}

fn explain(
    name: &str,
    r: &TunerReport,
    settled: f64,
    rate: f64,
    bound: f64,
    v: f64,
    cfg: &SimConfig,
) -> String {
    match name {
        "thesis" => {
            let stop = if r.at_upper_bound {
                format!(
                    "it stopped at the amplitude bound Aω = {:.1} mm/s",
                    bound * 1e3
                )
            } else {
                format!(
                    "it had not stopped: Aω = {:.1} mm/s and still rising at {:.1} mm/s per second; it stops only at the amplitude bound {:.1} mm/s",
                    settled * 1e3,
                    rate * 1e3,
                    bound * 1e3
                )
            };
            format!(
                "eq. 4.22 multiplies the instantaneous friction, whose mean stays positive while the tool moves, by (F_v/2 − F_s·Aω/(2ẋ̂_s²)), which is negative above the stationary point F_v·ẋ̂_s²/F_s = {:.3} mm/s (eq. 4.18 with ẋ̂_s = {:.1} mm/s re-estimated from the force variance, eq. 4.24). That point is a maximum of the approximated friction (eq. 4.21), not a minimum, and the law started above it, so Aω only grows; {stop}.",
                r.thesis_stationary_point_m_per_s * 1e3,
                r.stribeck_velocity_estimate_m_per_s * 1e3
            )
        }
        _ => {
            let lam = match cfg.servo.tuner {
                TunerConfig::Cost(p) => p.oscillation_weight,
                _ => f64::NAN,
            };
            if r.at_upper_bound || r.cost_minimiser_m_per_s >= r.transmission * bound * 0.999 {
                format!(
                    "J = F̄² + λσ² (λ = {lam}) still falls at the amplitude bound (dJ/da = {:.3e} N²·s/m there): it settles at the bound Aω = {:.1} mm/s",
                    r.cost_gradient_at_minimiser,
                    bound * 1e3
                )
            } else {
                format!(
                    "it settles at the interior minimum of J = F̄² + λσ² (λ = {lam}): a* = {:.1} mm/s at the contact ({:.1}·ẋ_o), commanded {:.1} mm/s with a measured transmission of {:.2}; there dJ/da = {:.1e} N²·s/m. Beyond a*, the oscillation the dither causes (friction reversal and the tool's inertial force m·ω·Aω) grows faster than the mean friction falls.",
                    r.cost_minimiser_m_per_s * 1e3,
                    r.cost_minimiser_m_per_s / v,
                    settled * 1e3,
                    r.transmission,
                    r.cost_gradient_at_minimiser
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table path of fig4.6 needs no simulation and prints the thesis's coefficient.
    #[test]
    fn fig4_6_thesis_table_prints_0_709() {
        let out = fig4_6(&Options {
            thesis_table: true,
            ..Default::default()
        })
        .unwrap();
        assert_eq!(out.summary.coefficient, "0.709");
        assert!(out.passed());
    }
}
