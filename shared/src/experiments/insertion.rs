//! Force-guided insertion (docs/insertion.md): a peg under a compliant wrist into a hole, from
//! initial errors drawn per seed, by one of three controllers; success, time, peak force,
//! jams and wedges.

use super::*;
use crate::error::ConfigError;
use crate::insertion::controller::{Controller, ControllerParams, Input, Method, Phase};
use crate::insertion::estimate::{Estimator, class};
use crate::insertion::plant::{ContactState, PegParams, PegPlant};
use crate::insertion::whitney::Fit;
use crate::sensor::{SensorModel, SensorParams, Wrench};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, Uniform};
use serde::Serialize;

/// The insertion experiment's own settings (`afs experiment insertion --clearance ...`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct InsertionOptions {
    /// Clearance ratio c = (D − d)/D.
    pub clearance_ratio: f64,
    /// Friction coefficient μ at every contact.
    pub mu: f64,
    /// Chamfer leg (mm); 0: none.
    pub chamfer_mm: f64,
    /// Initial lateral error (mm); None: uniform in ±2 mm per seed.
    pub lateral_mm: Option<f64>,
    /// Initial angle error (deg); None: uniform in ±2° per seed.
    pub angle_deg: Option<f64>,
    /// The controller.
    pub method: Method,
    /// Time allowed (s).
    pub time_limit_s: f64,
    /// The force limit, as a multiple of the commanded insertion force.
    pub force_limit_factor: f64,
}

impl Default for InsertionOptions {
    fn default() -> Self {
        Self {
            clearance_ratio: 0.002,
            mu: 0.3,
            chamfer_mm: 0.5,
            lateral_mm: None,
            angle_deg: None,
            method: Method::Dither,
            time_limit_s: 10.0,
            force_limit_factor: 3.0,
        }
    }
}

impl InsertionOptions {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ConfigError> {
        // (name, value, upper bound, whether 0 is allowed): a chamfer may be 0 (a sharp edge);
        // a clearance, a friction or a time may not.
        let rules = [
            ("insertion.clearance", self.clearance_ratio, 0.5, false),
            ("insertion.mu", self.mu, 2.0, false),
            ("insertion.chamfer_mm", self.chamfer_mm, 3.0, true),
            ("insertion.time_limit_s", self.time_limit_s, 600.0, false),
        ];
        for (name, v, max, zero_ok) in rules {
            if !(v.is_finite() && (v > 0.0 || zero_ok && v == 0.0) && v < max) {
                let zero = if zero_ok { " or 0" } else { "" };
                return Err(ConfigError::rule(
                    name,
                    format!("is {v}; it must be in (0, {max}){zero}"),
                ));
            }
        }
        for (name, v, limit) in [
            ("insertion.lateral_mm", self.lateral_mm, 4.0),
            ("insertion.angle_deg", self.angle_deg, 10.0),
        ] {
            if let Some(v) = v
                && !(v.is_finite() && v.abs() <= limit)
            {
                return Err(ConfigError::rule(
                    name,
                    format!("is {v}; it must be within ±{limit}"),
                ));
            }
        }
        Ok(())
    }
}

/// Summary of one insertion.
#[derive(Debug, Clone, Serialize)]
pub struct InsertionSummary {
    /// The controller.
    pub method: &'static str,
    /// Clearance ratio, μ, chamfer (mm).
    pub clearance_ratio: f64,
    /// μ.
    pub mu: f64,
    /// Chamfer (mm).
    pub chamfer_mm: f64,
    /// Initial lateral error (mm) and angle error (deg).
    pub lateral_error_mm: f64,
    /// Initial angle error (deg).
    pub angle_error_deg: f64,
    /// Whitney's wedging angle for the fit (deg).
    pub wedging_angle_deg: f64,
    /// Depth reached within the time limit without exceeding the force limit.
    pub inserted: bool,
    /// Time from the first contact to the depth (s), if reached.
    pub insertion_time_s: Option<f64>,
    /// Largest contact force (N).
    pub peak_force_n: f64,
    /// Largest depth (mm).
    pub depth_mm: f64,
    /// Ticks spent jammed and wedged (true state).
    pub jammed_ticks: u64,
    /// Ticks spent wedged.
    pub wedged_ticks: u64,
    /// Ticks whose estimated contact state was the true one, over those counted (outside
    /// 10 ms of a change of the true state; two-point, jammed and wedged are one class).
    pub state_classification_accuracy: f64,
    /// Ticks counted.
    pub classified_ticks: usize,
    /// Time each phase began (s): find, align, insert, done.
    pub phase_starts_s: [Option<f64>; 4],
    /// Samples (every 5 ms) of the applied wrench while the wrist pressed the peg in the hole
    /// with at least [`WHITNEY_LEAST_FZ_N`].
    pub jamming_diagram_samples: usize,
    /// The fraction of them inside Whitney's jamming parallelogram at the depth of the moment
    /// (None without samples).
    pub inside_parallelogram: Option<f64>,
}

/// The initial errors of `seed` (uniform ±2 mm, ±2°) unless set.
fn initial_errors(o: &InsertionOptions, seed: u64) -> (f64, f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x1a5e_7100);
    let u = Uniform::new_inclusive(-1.0f64, 1.0).expect("valid range");
    let (a, b) = (u.sample(&mut rng), u.sample(&mut rng));
    (
        o.lateral_mm.unwrap_or(2.0 * a) * 1e-3,
        o.angle_deg.unwrap_or(2.0 * b).to_radians(),
    )
}

/// One insertion on the built-in plant (docs/insertion.md): the peg starts 1 mm above the
/// face, offset and tilted by the seed's errors, and the controller inserts it 15 mm.
pub fn insertion(opts: &Options) -> Result<Outcome<InsertionSummary>, ExperimentError> {
    let o = opts.insertion;
    let params = peg_params(opts)?;
    let g = params.geometry;
    let fit = Fit {
        peg_width_m: g.peg_width_m,
        clearance_ratio: g.clearance_ratio,
        friction: o.mu,
    };
    let (lateral, angle) = initial_errors(&o, opts.seed);
    let start = [lateral, 1e-3, angle];
    let mut plant = PegPlant::new(params, start);
    let sensor_params = SensorParams {
        noise_force_n: 0.02,
        ..opts.base.sensor
    };
    let mut sensor = SensorModel::new(sensor_params, opts.seed);
    let tare = crate::sim::tare(&mut sensor);
    // The controller knows μ as friction identification gives it.
    let cp = ControllerParams {
        mu: o.mu,
        ..ControllerParams::default()
    };
    let chamfer_depth = g.chamfer_m / g.chamfer_angle_deg.to_radians().tan().max(1e-9);
    let mut ctl = Controller::new(cp, o.method, params.wrist_stiffness, start, chamfer_depth);
    let dt = 1e-4;
    let limit = o.force_limit_factor * cp.insertion_force_n;
    let (mut peak, mut depth, mut jammed, mut wedged) = (0.0f64, 0.0f64, 0u64, 0u64);
    let mut starts = [None; 4];
    let (mut trace, mut whitney, mut inside) = (Vec::new(), Vec::new(), 0usize);
    let (mut reading, mut next_sample, period) =
        (Wrench::default(), 0.0, 1.0 / sensor_params.rate_hz);
    let mut t = 0.0;
    let mut contact_t = None;
    let mut estimator = Estimator::new(0.0, chamfer_depth, g.peg_width_m, o.mu);
    let (mut states, mut changes, mut prev_tip_y) = (Vec::new(), Vec::new(), start[1]);
    while t < o.time_limit_s {
        let truth = *plant.truth();
        while next_sample <= t {
            reading = sensor
                .sample(Wrench {
                    force: truth.force,
                    torque: truth.moment_about_tip,
                })
                .wrench;
            next_sample += period;
        }
        let inp = Input {
            force: [
                reading.force.x - tare.force.x,
                reading.force.y - tare.force.y,
            ],
            moment_nm: reading.torque - tare.torque,
            tip: truth.pose,
        };
        let before = ctl.phase();
        let speed = (truth.pose[1] - prev_tip_y) / -dt;
        prev_tip_y = truth.pose[1];
        let truth_class = class(truth.state);
        if states
            .last()
            .is_none_or(|s: &(f64, ContactState, ContactState)| s.1 != truth_class)
        {
            changes.push(t);
        }
        states.push((t, truth_class, class(estimator.update(&inp, speed, dt))));
        let (target, rate) = ctl.step(&inp, dt);
        if ctl.phase() != before {
            let k = match ctl.phase() {
                Phase::Find => 0,
                Phase::Align => 1,
                Phase::Insert => 2,
                _ => 3,
            };
            starts[k] = Some(t);
            if k == 0 {
                contact_t = Some(t);
            }
        }
        plant.step(target, rate, dt);
        t += dt;
        let tr = plant.truth();
        peak = peak.max(tr.force.norm());
        depth = depth.max(tr.depth_m);
        match tr.state {
            ContactState::Jammed => jammed += 1,
            ContactState::Wedged => wedged += 1,
            _ => {}
        }
        if ((t / dt).round() as u64).is_multiple_of(50) {
            // The wrench the wrist applies, on Whitney's axes, while the peg is pressed in the hole.
            let fz = -tr.applied_force.y;
            if tr.depth_m > 0.0 && fz > WHITNEY_LEAST_FZ_N {
                let r = 0.5 * g.peg_width_m;
                let w = [
                    tr.applied_force.x / fz,
                    tr.applied_moment_about_tip / (r * fz),
                ];
                inside += usize::from(fit.slides(tr.depth_m, w[0], w[1]));
                whitney.push(w);
            }
            trace.push([
                t,
                tr.depth_m * 1e3,
                tr.force.x,
                tr.force.y,
                tr.pose[2].to_degrees(),
            ]);
        }
        if ctl.phase() == Phase::Done || peak > limit {
            break;
        }
    }
    let inserted = ctl.phase() == Phase::Done && peak <= limit;
    let time = match (inserted, contact_t, starts[3]) {
        (true, Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    let (right, counted) = classification(&states, &changes, TRANSITION_S);
    let accuracy = right as f64 / counted.max(1) as f64;
    let checks = insertion_checks(&o, inserted, peak / cp.insertion_force_n, accuracy, time);
    let figure = insertion_figure(&trace, &whitney, &fit, depth);
    Ok(Outcome {
        simulated_s: t,
        summary: InsertionSummary {
            method: o.method.name(),
            clearance_ratio: o.clearance_ratio,
            mu: o.mu,
            chamfer_mm: o.chamfer_mm,
            lateral_error_mm: lateral * 1e3,
            angle_error_deg: angle.to_degrees(),
            wedging_angle_deg: fit.wedging_angle_rad().to_degrees(),
            inserted,
            insertion_time_s: time,
            peak_force_n: peak,
            depth_mm: depth * 1e3,
            jammed_ticks: jammed,
            wedged_ticks: wedged,
            phase_starts_s: starts,
            state_classification_accuracy: accuracy,
            classified_ticks: counted,
            jamming_diagram_samples: whitney.len(),
            inside_parallelogram: (!whitney.is_empty())
                .then(|| inside as f64 / whitney.len() as f64),
        },
        checks,
        figure,
    })
}

/// The set-up of `opts`, checked: the peg and hole with the options' fit and chamfer.
fn peg_params(opts: &Options) -> Result<PegParams, ExperimentError> {
    let o = opts.insertion;
    o.validate()?;
    if opts.base.world.kind != crate::world::WorldKind::Builtin {
        return Err(ConfigError::rule(
            "world.kind",
            "is `mujoco`; insertion runs on the built-in plant only: the wrist is not in \
             MuJoCo's generated model yet (docs/insertion.md); run it without --plant",
        )
        .into());
    }
    let mut params = PegParams::default();
    params.geometry.clearance_ratio = o.clearance_ratio;
    params.geometry.chamfer_m = o.chamfer_mm * 1e-3;
    params.friction = params.friction.scaled(o.mu / params.mu());
    Ok(params)
}

/// The insertion's checks.
fn insertion_checks(
    o: &InsertionOptions,
    inserted: bool,
    peak_over_force: f64,
    accuracy: f64,
    time: Option<f64>,
) -> Vec<Check> {
    vec![
        Check::at_least(
            "inserted",
            "depth reached in time, force in limit (1 = yes)",
            f64::from(u8::from(inserted)),
            1.0,
        ),
        Check::at_most(
            "peak_force_over_insertion_force",
            "largest contact force / insertion force",
            peak_over_force,
            o.force_limit_factor,
        ),
        Check::at_least(
            "state_classification_accuracy",
            "contact states estimated right, outside 10 ms of a transition",
            accuracy,
            0.95,
        ),
        Check::at_most(
            "insertion_time_s",
            "time from contact to depth (s)",
            time.unwrap_or(f64::INFINITY),
            5.0,
        )
        .target(),
    ]
}

/// Ticks on either side of a change of the true contact state left out of the accuracy (s).
const TRANSITION_S: f64 = 0.01;

/// How many of `states` (time, true class, estimated class) were right, and how many were
/// counted: those farther than `window` from every time in `changes`.
fn classification(
    states: &[(f64, ContactState, ContactState)],
    changes: &[f64],
    window: f64,
) -> (usize, usize) {
    let (mut right, mut counted, mut k) = (0, 0, 0);
    for &(t, truth, est) in states {
        while k + 1 < changes.len() && changes[k + 1] <= t {
            k += 1;
        }
        let near = |i: usize| changes.get(i).is_some_and(|c| (c - t).abs() < window);
        if near(k) || near(k + 1) {
            continue;
        }
        counted += 1;
        right += usize::from(truth == est);
    }
    (right, counted)
}

/// The jamming diagram shows the applied wrench only while the wrist presses the peg in with at
/// least this force (N): below it, F_x/F_z and M/(r F_z) divide by next to nothing.
pub const WHITNEY_LEAST_FZ_N: f64 = 0.25;

/// Depth, contact force and tilt over time, and the wrench the wrist applies in the hole on
/// Whitney's jamming diagram with its parallelogram at 1 mm and at the depth reached.
fn insertion_figure(trace: &[[f64; 5]], whitney: &[[f64; 2]], fit: &Fit, depth_m: f64) -> Figure {
    let series = |label: &str, k: usize| Series {
        label: label.into(),
        points: trace.iter().map(|r| [r[0], r[k]]).collect(),
        markers: false,
    };
    Figure {
        title: "Insertion: depth, contact force and tilt".into(),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "depth (mm)".into(),
                series: vec![series("depth", 1)],
            },
            Panel {
                x_label: None,
                y_label: "contact force (N)".into(),
                series: vec![series("F_x", 2), series("F_y", 3)],
            },
            Panel {
                x_label: None,
                y_label: "tilt (deg)".into(),
                series: vec![series("θ", 4)],
            },
            Panel {
                x_label: Some("F_x / F_z (applied)".into()),
                y_label: "M / (r F_z) (applied)".into(),
                series: jamming_series(whitney, fit, depth_m),
            },
        ],
    }
}

/// The jamming diagram's series: the applied wrench (markers) and the parallelogram, closed,
/// at 1 mm and at `depth_m` (it widens with depth: λ = l/(μd)).
fn jamming_series(whitney: &[[f64; 2]], fit: &Fit, depth_m: f64) -> Vec<Series> {
    let mut out = vec![Series {
        label: "applied wrench in the hole".into(),
        points: whitney.to_vec(),
        markers: true,
    }];
    for l in [1e-3, depth_m.max(1e-3)] {
        let v = fit.parallelogram(l);
        out.push(Series {
            label: format!("parallelogram at {:.1} mm", l * 1e3),
            points: vec![v[0], v[1], v[2], v[3], v[0]],
            markers: false,
        });
    }
    out
}
