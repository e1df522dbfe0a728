//! Chapter 4, friction suppression by a fixed dither: the same traverse without and with a
//! dither (fig. 4.5), and the dither's amplitude raised step-wise (fig. 4.7).

use super::*;
use crate::error::ExperimentError;
use crate::friction::RoughnessMap;
use crate::sim::Lockstep;
use crate::ticks::{Tick, WindowSummary, decimate, run_recording, sliding_periods, window};
use crate::tuner::TunerConfig;
use serde::Serialize;

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
    let law = crate::world::friction_law(&cfg);
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
    let law = crate::world::friction_law(&cfg);
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
