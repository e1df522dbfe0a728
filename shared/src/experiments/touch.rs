//! First touch: the tool starts off the surface and the servo's guarded approach brings it
//! into contact (docs/contact.md, *First touch*). What a stiff part punishes first is the
//! impact, so the check is the peak contact force against the preload, whatever the contact.

use super::*;
use crate::error::ExperimentError;
use crate::servo::ServoMode;
use crate::sim::Lockstep;
use serde::Serialize;

/// The gap the tool starts at when the set-up does not set one (m).
pub const TOUCH_GAP_M: f64 = 1e-3;

/// Summary of `touch`.
#[derive(Debug, Clone, Serialize)]
pub struct TouchSummary {
    /// The gap the tool started at (m).
    pub gap_m: f64,
    /// The servo's approach speed (m/s).
    pub approach_speed_m_per_s: f64,
    /// The preload F_d (N).
    pub preload_n: f64,
    /// When the tool first touched the surface (s; None: it never did).
    pub touch_s: Option<f64>,
    /// The largest contact normal force, the world's truth (N).
    pub peak_normal_n: f64,
    /// When it was reached (s).
    pub peak_s: f64,
    /// When the servo ended its approach (its force reached the touch fraction, s).
    pub approach_ended_s: Option<f64>,
    /// When the servo was tracking again, the preload settled (s).
    pub tracking_s: Option<f64>,
    /// Ticks without contact after the first touch (bounces).
    pub ticks_without_contact_after_touch: u64,
    /// The mean normal force over the last 0.5 s (N).
    pub final_normal_n: f64,
    /// The stiffness in use at the end (N/m) and the servo's adoptions.
    pub stiffness_in_use_n_per_m: f64,
    /// Times the servo adopted its fitted stiffness.
    pub adoptions: u32,
}

/// The tool starts `start_gap_m` off the surface (1 mm where the set-up leaves it 0) at rest,
/// the servo approaches, touches, settles the preload and holds it for 1.5 s. Checks: the peak
/// contact force at most twice the preload, no bounce, the preload held at the end.
pub fn touch(opts: &Options) -> Result<Outcome<TouchSummary>, ExperimentError> {
    let mut cfg = config(opts, opts.base.servo.tuner);
    if cfg.start_gap_m == 0.0 {
        cfg.start_gap_m = TOUCH_GAP_M;
    }
    let gap = cfg.start_gap_m;
    let preload = cfg.servo.hybrid.preload_n;
    let mut sim = Lockstep::new(&cfg)?;
    let speed = sim.servo().approach_speed();
    let dt = sim.dt();
    // The set-point closes the gap, then the force loop settles the preload (slowly on soft
    // contacts, where the approach's speed compresses little); the run holds 1.5 s after the
    // servo tracks again, or gives up 10 s after the gap should have closed.
    let mut duration = 1.5 * gap / speed + 10.0;
    let mut s = TouchSummary {
        gap_m: gap,
        approach_speed_m_per_s: speed,
        preload_n: preload,
        touch_s: None,
        peak_normal_n: 0.0,
        peak_s: 0.0,
        approach_ended_s: None,
        tracking_s: None,
        ticks_without_contact_after_touch: 0,
        final_normal_n: 0.0,
        stiffness_in_use_n_per_m: 0.0,
        adoptions: 0,
    };
    let mut trace = Vec::new();
    let (mut tail_sum, mut tail_n) = (0.0, 0u64);
    let every = ((1e-3 / dt).round() as usize).max(1);
    let mut tick = 0usize;
    while sim.time() < duration {
        sim.step();
        tick += 1;
        let t = sim.time();
        let truth = sim.truth();
        let f = truth.normal_force_n;
        let touching = truth.contact_count > 0;
        if touching && s.touch_s.is_none() {
            s.touch_s = Some(t);
        }
        if s.touch_s.is_some() && !touching {
            s.ticks_without_contact_after_touch += 1;
        }
        if f > s.peak_normal_n {
            s.peak_normal_n = f;
            s.peak_s = t;
        }
        let mode = sim.servo().mode();
        if mode != ServoMode::Approach && s.approach_ended_s.is_none() {
            s.approach_ended_s = Some(t);
        }
        if mode == ServoMode::Track && s.tracking_s.is_none() {
            s.tracking_s = Some(t);
            duration = t + 1.5;
        }
        if t > duration - 0.5 {
            tail_sum += f;
            tail_n += 1;
        }
        if tick.is_multiple_of(every) {
            trace.push([t, f, sim.servo().diag().normal_force_n]);
        }
    }
    s.final_normal_n = tail_sum / tail_n.max(1) as f64;
    s.stiffness_in_use_n_per_m = sim.servo().hybrid().params().stiffness_estimate_n_per_m;
    s.adoptions = sim.servo().stiffness_adoptions();
    let checks = vec![
        Check::at_most(
            "peak_over_preload",
            "largest contact normal force / preload, first touch included",
            s.peak_normal_n / preload,
            2.0,
        ),
        Check::at_most(
            "ticks_without_contact_after_touch",
            "ticks without contact after the first touch (bounces)",
            s.ticks_without_contact_after_touch as f64,
            0.0,
        ),
        Check::at_most(
            "final_force_error",
            "|mean normal force over the last 0.5 s − preload| / preload",
            (s.final_normal_n - preload).abs() / preload,
            0.05,
        ),
        Check::at_least(
            "tracking",
            "the servo tracks again after the touch (1 = yes)",
            f64::from(u8::from(s.tracking_s.is_some())),
            1.0,
        ),
    ];
    let figure = Figure {
        title: format!(
            "touch: {:.1} mm off the surface, approach at {:.2} mm/s",
            gap * 1e3,
            speed * 1e3
        ),
        x_label: "time (s)".into(),
        log_x: false,
        panels: vec![Panel {
            x_label: None,
            y_label: "normal force (N)".into(),
            series: vec![
                series(
                    "contact (truth)",
                    trace.iter().map(|p| [p[0], p[1]]).collect(),
                ),
                series("measured", trace.iter().map(|p| [p[0], p[2]]).collect()),
                series(
                    "twice the preload",
                    vec![[0.0, 2.0 * preload], [duration, 2.0 * preload]],
                ),
            ],
        }],
    };
    Ok(Outcome {
        summary: s,
        checks,
        simulated_s: sim.time(),
        figure,
    })
}
