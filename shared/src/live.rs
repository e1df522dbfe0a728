//! What a person watching a running stack wants per tick, in one flat record: the sensed and
//! true normal force, the tangential force and friction, the dither's Aω, the tangent error,
//! the force data's age and the servo's flags. Built from the world and controller samples of
//! one tick (the tangent error needs the world's true tangent, which the controller never
//! sees); the live view and the recording publish it as the `/live` topic, and
//! `examples/foxglove-layout.json` plots it.

use crate::math::wrap_angle;
use crate::monitor::MonitorTick;
use crate::msg::{PlantSample, ServoFlags, ServoSample};
use serde::Serialize;

/// One tick, for display. Units are in the field names.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct LiveSample {
    /// Servo tick index (the two samples' common `seq`).
    pub seq: u64,
    /// Monotonic time the controller's sample was published (ns).
    pub publish_ns: u64,
    /// Simulated time (s).
    pub time_s: f64,
    /// Normal force the controller measured (N).
    pub normal_force_n: f64,
    /// True normal force (N).
    pub true_normal_force_n: f64,
    /// Tangential force the controller measured (N, along the estimated tangent).
    pub tangential_force_n: f64,
    /// Measured friction resisting the nominal motion (N).
    pub friction_n: f64,
    /// Commanded Aω (m/s).
    pub a_omega_m_per_s: f64,
    /// Nominal tangential velocity (m/s).
    pub nominal_velocity_m_per_s: f64,
    /// Estimated minus true tangent angle, wrapped to (−180°, 180°] (deg).
    pub tangent_error_deg: f64,
    /// Age of the force data the controller used (µs).
    pub force_age_us: f64,
    /// Controller mode (`ServoMode` wire code: 0 track, 1 stopping, 2 probing, 3 awaiting
    /// the estimate, 4 resuming).
    pub mode: u32,
    /// The servo is in its safe state.
    pub safe: bool,
    /// The force sample used passed the gate.
    pub force_valid: bool,
    /// The set-point was out of reach and held.
    pub setpoint_held: bool,
    /// Waiting for the estimator's answer.
    pub awaiting_estimate: bool,
    /// The tool touches the surface.
    pub in_contact: bool,
}

impl LiveSample {
    /// The record of one tick; None when the two samples are of different ticks.
    pub fn of_tick(p: &PlantSample, s: &ServoSample) -> Option<Self> {
        if p.seq != s.seq {
            return None;
        }
        let m = MonitorTick::from_samples(p, s);
        Some(Self {
            seq: s.seq,
            publish_ns: s.publish_ns,
            time_s: s.time_s,
            normal_force_n: s.normal_force_n,
            true_normal_force_n: p.normal_force_n,
            tangential_force_n: s.tangential_force_n,
            friction_n: m.friction,
            a_omega_m_per_s: s.a_omega_m_per_s,
            nominal_velocity_m_per_s: s.nominal_velocity_m_per_s,
            tangent_error_deg: wrap_angle(m.tangent_estimated - m.tangent_true).to_degrees(),
            force_age_us: s.force_age_ns as f64 * 1e-3,
            mode: s.mode,
            safe: s.flags.contains(ServoFlags::SAFE),
            force_valid: s.flags.contains(ServoFlags::FORCE_VALID),
            setpoint_held: s.flags.contains(ServoFlags::SETPOINT_HELD),
            awaiting_estimate: s.flags.contains(ServoFlags::AWAITING_ESTIMATE),
            in_contact: m.contact,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(seq: u64) -> (PlantSample, ServoSample) {
        let p = PlantSample {
            seq,
            normal_force_n: 10.5,
            contact_count: 1,
            tangent_angle_rad: 179f64.to_radians(),
            ..Default::default()
        };
        let mut s = ServoSample {
            seq,
            normal_force_n: 9.5,
            tangential_force_n: -2.0,
            velocity_target_m_per_s: 0.02,
            tangent_angle_rad: -179f64.to_radians(),
            force_age_ns: 143_000,
            ..Default::default()
        };
        s.flags.set(ServoFlags::SAFE, true);
        (p, s)
    }

    #[test]
    fn the_tangent_error_wraps_and_the_fields_come_from_their_tick() {
        let (p, s) = pair(7);
        let l = LiveSample::of_tick(&p, &s).unwrap();
        // −179° estimated against 179° true is 2°, not −358°.
        assert!((l.tangent_error_deg - 2.0).abs() < 1e-9, "{l:?}");
        assert_eq!((l.normal_force_n, l.true_normal_force_n), (9.5, 10.5));
        // Friction resists the nominal (positive) motion: the measured force is −2 N.
        assert_eq!(l.friction_n, 2.0);
        assert!((l.force_age_us - 143.0).abs() < 1e-9);
        assert!(l.safe && !l.force_valid && !l.awaiting_estimate && l.in_contact);
        let (q, _) = pair(8);
        assert_eq!(LiveSample::of_tick(&q, &s), None);
    }
}

/// One insertion tick, for display (the `/insertion` topic of the `insertion` scenario): the
/// depth, the contact force and moment, the tilt, the phase, the true and estimated contact
/// states and the applied wrench on Whitney's axes. Units are in the field names.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct InsertionLive {
    /// Servo tick index.
    pub seq: u64,
    /// Monotonic time the sample was published (ns).
    pub publish_ns: u64,
    /// Simulated time (s).
    pub time_s: f64,
    /// Depth of the peg's tip below the face (mm).
    pub depth_mm: f64,
    /// Contact force on the peg across the hole's axis (N).
    pub force_x_n: f64,
    /// Contact force on the peg along the hole's axis (N, out of the hole positive).
    pub force_y_n: f64,
    /// Its moment about the tip (N·m).
    pub moment_nm: f64,
    /// The peg's tilt from the hole's axis (deg).
    pub tilt_deg: f64,
    /// Commanded lateral position of the tip (mm).
    pub target_x_mm: f64,
    /// The applied wrench on Whitney's axes, F_x/F_z (0 while the wrist pushes less than
    /// 0.25 N into the hole).
    pub whitney_f: f64,
    /// M/(r F_z), likewise.
    pub whitney_m: f64,
    /// Phase (0 approach, 1 find, 2 align, 3 insert, 4 done).
    pub phase: u32,
    /// True contact state (0 free, 1 face, 2 chamfer, 3 one-point, 4 two-point, 5 jammed,
    /// 6 wedged, 7 bottom).
    pub true_state: u32,
    /// Estimated contact state (same codes).
    pub estimated_state: u32,
    /// The controller had force data this tick.
    pub force_valid: bool,
}

impl InsertionLive {
    /// The record of one insertion tick, for a peg of width `peg_width_m`.
    pub fn of_sample(g: &crate::msg::PegSample, peg_width_m: f64) -> Self {
        let t = &g.truth;
        let fz = -t.applied_force_n[1];
        let pushed = t.depth_m > 0.0 && fz > crate::insertion::monitor::WHITNEY_LEAST_FZ_N;
        let (whitney_f, whitney_m) = if pushed {
            (
                t.applied_force_n[0] / fz,
                t.applied_moment_nm / (0.5 * peg_width_m * fz),
            )
        } else {
            (0.0, 0.0)
        };
        Self {
            seq: g.seq,
            publish_ns: g.publish_ns,
            time_s: g.time_s,
            depth_mm: t.depth_m * 1e3,
            force_x_n: t.force_n[0],
            force_y_n: t.force_n[1],
            moment_nm: t.moment_nm,
            tilt_deg: t.pose[2].to_degrees(),
            target_x_mm: g.target[0] * 1e3,
            whitney_f,
            whitney_m,
            phase: g.phase,
            true_state: t.state,
            estimated_state: g.estimated_state,
            force_valid: g.flags.contains(crate::msg::PegFlags::FORCE_VALID),
        }
    }
}

/// What the servo knows of its contact, for display (the `/contact` topic, a few times a
/// second): read from its newest world snapshot, so it costs the servo nothing. Units are in
/// the field names; a figure not determined yet is NaN (null in JSON).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct ContactLive {
    /// Servo tick of the snapshot.
    pub seq: u64,
    /// Monotonic time the record was made (ns).
    pub publish_ns: u64,
    /// Simulated time of the snapshot (s).
    pub time_s: f64,
    /// The contact stiffness the gains are derived for (N/m): configured, the approach's
    /// assumption, or adopted from the fit.
    pub stiffness_in_use_n_per_m: f64,
    /// The on-line fit's stiffness (N/m).
    pub fitted_n_per_m: f64,
    /// Its standard error (N/m).
    pub fitted_std_error_n_per_m: f64,
    /// Times the servo adopted its fit.
    pub adoptions: u32,
    /// The gains are still the guarded approach's assumption.
    pub provisional: bool,
    /// β, the fraction of the force loop's rate fed forward.
    pub rate_feedforward: f64,
    /// Damping added along the normal (N·s/m).
    pub added_damping_n_s_per_m: f64,
    /// Controller mode (`ServoMode` wire code; 5 is the approach).
    pub mode: u32,
}

impl ContactLive {
    /// The record of a world snapshot, made at `publish_ns`.
    pub fn of_snapshot(w: &crate::msg::WorldSnapshot, publish_ns: u64) -> Self {
        let r = crate::servo::ContactReport::from_state(&w.controller);
        Self {
            seq: w.seq,
            publish_ns,
            time_s: w.plant.time_s,
            stiffness_in_use_n_per_m: r.stiffness_in_use_n_per_m,
            fitted_n_per_m: r.fitted_n_per_m.unwrap_or(f64::NAN),
            fitted_std_error_n_per_m: r.fitted_std_error_n_per_m.unwrap_or(f64::NAN),
            adoptions: r.adoptions,
            provisional: w.controller.contact.provisional != 0,
            rate_feedforward: r.rate_feedforward,
            added_damping_n_s_per_m: r.added_damping_n_s_per_m,
            mode: w.controller.mode,
        }
    }
}

#[cfg(test)]
mod contact_tests {
    use super::*;
    use crate::config::SimConfig;
    use crate::msg::WorldSnapshot;
    use crate::sim::Lockstep;

    /// The `/contact` record carries what the servo's state says: after a touch on 1 MN/m the
    /// adopted stiffness, the fit, no longer provisional; during the approach the assumption.
    #[test]
    fn the_contact_record_is_the_servos_state() {
        let mut cfg = SimConfig::default();
        cfg.plant.contact.interaction_stiffness_n_per_m = 1e6;
        cfg.start_gap_m = 0.2e-3;
        let mut sim = Lockstep::new(&cfg).unwrap();
        let at = |sim: &Lockstep| {
            let w = WorldSnapshot {
                seq: 9,
                controller: sim.servo().state(),
                ..Default::default()
            };
            ContactLive::of_snapshot(&w, 5)
        };
        let l = at(&sim);
        assert!(l.provisional && l.mode == 5, "{l:?}");
        assert_eq!(l.stiffness_in_use_n_per_m, 1e6);
        assert!(l.fitted_n_per_m.is_nan() && l.adoptions == 0);
        sim.run(30_000);
        let l = at(&sim);
        assert!(!l.provisional && l.mode == 0 && l.adoptions == 1, "{l:?}");
        assert!(
            (l.stiffness_in_use_n_per_m / 1e6 - 0.9).abs() < 0.1,
            "{l:?}"
        );
        assert!(l.fitted_n_per_m > 5e5 && l.fitted_std_error_n_per_m > 0.0);
        assert_eq!((l.seq, l.publish_ns), (9, 5));
        let json = serde_json::to_value(at(&Lockstep::new(&cfg).unwrap())).unwrap();
        assert!(json["fitted_n_per_m"].is_null());
    }
}
