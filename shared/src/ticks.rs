//! A run recorded tick by tick, and statistics over it: means, spreads and lock-in amplitudes
//! over whole dither periods, sliding over periods, decimated for plots. The friction
//! experiments and the friction-suppression scenario measure with it.

use crate::sim::Lockstep;
use serde::{Deserialize, Serialize};

/// One recorded servo tick.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Tick {
    pub(crate) t: f64,
    /// Measured friction resisting the nominal motion (N).
    pub(crate) friction: f64,
    /// Measured normal force (N).
    pub(crate) normal: f64,
    /// True normal force (N).
    pub(crate) normal_true: f64,
    /// Friction scale truth: F_N/F_ref × roughness.
    pub(crate) scale: f64,
    /// Tip velocity along the estimated tangent, in the nominal direction (m/s).
    pub(crate) velocity: f64,
    pub(crate) phase: f64,
    pub(crate) period_end: bool,
    pub(crate) a_cmd: f64,
    pub(crate) contact: bool,
}

pub(crate) fn record(sim: &Lockstep, last_phase: &mut f64) -> Tick {
    let d = sim.servo().diag();
    let tr = sim.truth();
    let dir = if sim.servo().hybrid().velocity_target() < 0.0 {
        -1.0
    } else {
        1.0
    };
    let period_end = d.dither_phase < *last_phase;
    *last_phase = d.dither_phase;
    let f_ref = sim.world().params().reference_normal_force_n;
    Tick {
        t: sim.time(),
        friction: -d.tangential_force_n * dir,
        normal: d.normal_force_n,
        normal_true: tr.normal_force_n,
        scale: tr.normal_force_n / f_ref * tr.roughness_factor,
        velocity: d.tangent_velocity_m_per_s * dir,
        phase: d.dither_phase,
        period_end,
        a_cmd: d.a_omega_m_per_s,
        contact: tr.contact_count > 0 && tr.normal_force_n > 0.0,
    }
}

/// Runs `sim` for `seconds`, recording every tick into `out`.
pub(crate) fn run_recording(
    sim: &mut Lockstep,
    seconds: f64,
    out: &mut Vec<Tick>,
    last_phase: &mut f64,
) {
    let n = (seconds / sim.dt()).round() as usize;
    for _ in 0..n {
        sim.step();
        out.push(record(sim, last_phase));
    }
}

/// Statistics over the whole dither periods inside [t0, t1).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct WindowSummary {
    /// Mean friction force resisting the motion (N), measured.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub mean_force_n: f64,
    /// Its standard deviation (N).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub std_force_n: f64,
    /// Mean tip velocity along the tangent (m/s): the ẋ_o the contact saw.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub velocity_seen_m_per_s: f64,
    /// Dither velocity amplitude at the tip (m/s, lock-in): the Aω the contact saw.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub a_omega_seen_m_per_s: f64,
    /// Mean commanded Aω (m/s).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub a_omega_commanded_m_per_s: f64,
    /// Mean measured normal force (N).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub mean_normal_n: f64,
    /// Mean of the true friction scale F_N/F_ref × roughness.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub friction_scale: f64,
    /// Peak-to-peak of the friction force (N).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub peak_to_peak_n: f64,
    /// Window start and end (s).
    #[serde(deserialize_with = "crate::nan::pair_or_null")]
    pub window_s: [f64; 2],
}

pub(crate) fn window(ticks: &[Tick], t0: f64, t1: f64) -> WindowSummary {
    // Align to period boundaries: from the first period end ≥ t0 to the last ≤ t1.
    let start = ticks
        .iter()
        .position(|k| k.t >= t0 && k.period_end)
        .map(|i| i + 1)
        .unwrap_or(0);
    let end = ticks
        .iter()
        .rposition(|k| k.t <= t1 && k.period_end)
        .map(|i| i + 1)
        .unwrap_or(ticks.len());
    let w = if end > start {
        &ticks[start..end]
    } else {
        ticks
    };
    let n = w.len().max(1) as f64;
    let mean = w.iter().map(|k| k.friction).sum::<f64>() / n;
    let var = w.iter().map(|k| (k.friction - mean).powi(2)).sum::<f64>() / n;
    let v0 = w.iter().map(|k| k.velocity).sum::<f64>() / n;
    let i = 2.0 * w.iter().map(|k| k.velocity * k.phase.cos()).sum::<f64>() / n;
    let q = 2.0 * w.iter().map(|k| k.velocity * k.phase.sin()).sum::<f64>() / n;
    let (lo, hi) = w
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), k| {
            (a.min(k.friction), b.max(k.friction))
        });
    WindowSummary {
        mean_force_n: mean,
        std_force_n: var.sqrt(),
        velocity_seen_m_per_s: v0,
        a_omega_seen_m_per_s: (i * i + q * q).sqrt(),
        a_omega_commanded_m_per_s: w.iter().map(|k| k.a_cmd).sum::<f64>() / n,
        mean_normal_n: w.iter().map(|k| k.normal).sum::<f64>() / n,
        friction_scale: w.iter().map(|k| k.scale).sum::<f64>() / n,
        peak_to_peak_n: hi - lo,
        window_s: [
            w.first().map_or(0.0, |k| k.t),
            w.last().map_or(0.0, |k| k.t),
        ],
    }
}

/// Sliding statistics over `periods` whole periods, one point per period end: (t, mean, std).
pub(crate) fn sliding_periods(ticks: &[Tick], periods: usize) -> Vec<[f64; 3]> {
    let ends: Vec<usize> = ticks
        .iter()
        .enumerate()
        .filter(|(_, k)| k.period_end)
        .map(|(i, _)| i)
        .collect();
    let mut out = Vec::new();
    for w in ends.windows(periods + 1) {
        let s = &ticks[w[0] + 1..=w[periods]];
        let n = s.len() as f64;
        let m = s.iter().map(|k| k.friction).sum::<f64>() / n;
        let v = s.iter().map(|k| (k.friction - m).powi(2)).sum::<f64>() / n;
        out.push([ticks[w[periods]].t, m, v.sqrt()]);
    }
    out
}

pub(crate) fn decimate<F: Fn(&Tick) -> f64>(ticks: &[Tick], every: usize, f: F) -> Vec<[f64; 2]> {
    ticks
        .iter()
        .step_by(every.max(1))
        .map(|k| [k.t, f(k)])
        .collect()
}
