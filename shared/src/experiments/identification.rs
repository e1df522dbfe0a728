//! Chapter 4, friction identification: the coefficients of eq. 4.23 from constant-velocity
//! strokes (`friction-id`), and the friction coefficient from force trials (fig. 4.6).

use super::*;
use crate::error::ExperimentError;
use crate::friction::FrictionLaw;
use crate::ident::{
    CoefficientFit, FrictionFit, THESIS_FIG_4_6, fit_friction_coefficient, fit_friction_law,
};
use crate::sim::Lockstep;
use crate::tuner::TunerConfig;
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
    let mut cfg = config(opts, TunerConfig::Fixed);
    cfg.servo.hybrid.tangential_acceleration_m_per_s2 = 2.0;
    // Eq. 4.5 must be in the world to be identified: on MuJoCo its Stribeck and viscous terms
    // join the Coulomb cone as applied forces (docs/mujoco.md).
    cfg.world.mujoco.applied_friction = true;
    let truth = crate::world::friction_law(&cfg);
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
                strokes.extend(Stroke::run(&mut sim, dir, v, cruise, ramp));
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
    let checks = friction_id_checks(retare_failures, &relative_error);
    let figure = friction_id_figure(&strokes_plot, &levels, truth, fit.law);
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

/// One constant-velocity stroke's means over its cruise (after the ramp and a settling time).
struct Stroke {
    t_mid: f64,
    force: crate::math::Vec2,
    phi: f64,
    dir: f64,
    speed: f64,
    spread: f64,
}

impl Stroke {
    /// A stroke at `dir × v` for `cruise` seconds after a `ramp`, then a stop; None if no tick
    /// was past the settling time.
    fn run(sim: &mut Lockstep, dir: f64, v: f64, cruise: f64, ramp: f64) -> Option<Self> {
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
                f += frame.normal() * d.normal_force_n + frame.tangent() * d.tangential_force_n;
                ts += sim.time();
                let q = sim.world().joints().0;
                phi += q[0] + q[1];
                let vv = d.tangent_velocity_m_per_s * dir;
                vs += vv;
                v2 += vv * vv;
                c += 1.0;
            }
        }
        sim.servo_mut().hybrid_mut().set_velocity(0.0);
        sim.run(((ramp + 0.1) / sim.dt()).round() as usize);
        (c > 0.0).then(|| {
            let mv = vs / c;
            Stroke {
                t_mid: ts / c,
                force: f / c,
                phi: phi / c,
                dir,
                speed: mv,
                spread: (v2 / c - mv * mv).max(0.0).sqrt(),
            }
        })
    }
}

/// `friction-id`'s checks: every re-zeroing done, each coefficient of eq. 4.23 recovered.
fn friction_id_checks(retare_failures: usize, relative_error: &[f64; 4]) -> Vec<Check> {
    vec![
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
    ]
}

/// `friction-id`'s plot: the strokes, the level means, the truth and the identified law.
fn friction_id_figure(
    strokes_plot: &[[f64; 2]],
    levels: &[[f64; 2]],
    truth: FrictionLaw,
    identified: FrictionLaw,
) -> Figure {
    let curve = |law: FrictionLaw| -> Vec<[f64; 2]> {
        (0..200)
            .map(|k| {
                let v = 5e-4 * (400f64).powf(k as f64 / 199.0);
                [v * 1e3, law.resistance(v)]
            })
            .collect()
    };
    Figure {
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
                series("identified", curve(identified)),
            ],
        }],
    }
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
        let mu =
            crate::world::friction_law(&cfg).resistance(speed) / cfg.plant.reference_normal_force_n;
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
