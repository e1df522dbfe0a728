//! Force-guided insertion (docs/insertion.md): a peg under a compliant wrist into a hole, from
//! initial errors drawn per seed, by one of three controllers; success, time, peak force,
//! jams and wedges.

use super::*;
use crate::insertion::monitor::{InsertionMonitor, InsertionRun, PegTick};
use crate::insertion::whitney::Fit;
use crate::sensor::{SensorModel, Wrench};
use serde::Serialize;

pub use crate::insertion::monitor::WHITNEY_LEAST_FZ_N;
pub use crate::insertion::rig::{InsertionOptions, InsertionRig};

/// Summary of one insertion.
#[derive(Debug, Clone, Serialize)]
pub struct InsertionSummary {
    /// The controller.
    pub method: &'static str,
    /// What positions the wrist's flange: `ideal` or `arm`.
    pub drive: &'static str,
    /// The peg's world: `builtin` (afs's contacts) or `mujoco` (MuJoCo's).
    pub world: &'static str,
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
    /// The error of the face's tangent as the controller estimated it at the end (deg): the
    /// angle error itself when it never probed the face (docs/insertion.md).
    pub face_error_deg: f64,
    /// Whitney's wedging angle for the fit (deg).
    pub wedging_angle_deg: f64,
    /// The insertion's figures (`InsertionRun`: inserted, time, peak force, depth, jams and
    /// wedges, classification, phase starts, the jamming diagram's samples).
    #[serde(flatten)]
    pub run: InsertionRun,
}

/// One insertion on the built-in plant (docs/insertion.md): the peg starts 1 mm above the
/// face, offset and tilted by the seed's errors, and the controller inserts it 15 mm.
pub fn insertion(opts: &Options) -> Result<Outcome<InsertionSummary>, ExperimentError> {
    let o = opts.insertion;
    let fit = o.fit();
    let dt = opts.base.servo.dt();
    let mut rig = InsertionRig::on_world(&o, opts.seed, &opts.base.world, dt)?;
    let sensor_params = opts.base.sensor;
    let mut sensor = SensorModel::new(sensor_params, opts.seed);
    let tare = crate::sim::tare(&mut sensor);
    // The servo's period (10 kHz; `--rate-hz` sets a real robot's 1 kHz or 500 Hz): `dt`.
    let mut monitor = InsertionMonitor::new(dt, fit, o.force_limit_n());
    let (mut reading, mut next_sample, period) =
        (Wrench::default(), 0.0, 1.0 / sensor_params.rate_hz);
    while rig.time_s() < o.time_limit_s {
        while next_sample <= rig.time_s() {
            reading = sensor.sample(rig.sensor_wrench()).wrench;
            next_sample += period;
        }
        rig.step(Some(reading.tared(tare)), dt);
        monitor.push(&PegTick {
            t: rig.time_s(),
            phase: rig.phase(),
            estimated: rig.estimated(),
            truth: *rig.truth(),
        });
        if rig.finished() {
            break;
        }
    }
    let run = monitor.report();
    let (lateral, angle) = rig.initial_errors();
    let force = o.controller_params().insertion_force_n;
    let checks = insertion_checks(
        &o,
        run.inserted,
        run.peak_force_n / force,
        run.state_classification_accuracy,
        run.insertion_time_s,
    );
    let figure = insertion_figure(
        monitor.trace(),
        monitor.whitney(),
        &fit,
        run.depth_mm * 1e-3,
    );
    Ok(Outcome {
        simulated_s: rig.time_s(),
        summary: InsertionSummary {
            method: o.method.name(),
            drive: o.drive.name(),
            world: rig.world().kind().name(),
            clearance_ratio: o.clearance_ratio,
            mu: o.mu,
            chamfer_mm: o.chamfer_mm,
            lateral_error_mm: lateral * 1e3,
            angle_error_deg: angle.to_degrees(),
            face_error_deg: rig.face_error_rad().to_degrees(),
            wedging_angle_deg: fit.wedging_angle_rad().to_degrees(),
            run,
        },
        checks,
        figure,
    })
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
