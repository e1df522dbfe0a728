//! The deterministic lockstep simulation: plant, force sensor and servo stepped together in
//! simulated time, with seeded noise. The sensor samples at its own rate (default 7 kHz) and the
//! servo (default 10 kHz) uses the latest sample, exactly as the multi-process stack does in
//! real time; the same [`World`], [`SensorModel`] and [`ServoCore`] code runs in both.

use crate::config::SimConfig;
use crate::error::{ConfigError, SnapshotError};
use crate::plant::PlantTruth;
use crate::sensor::{Reading, SensorModel, Wrench};
use crate::servo::ServoCore;
use crate::surface::Surface;
use crate::tangent::{self, TangentOutcome};
use crate::tick::{Force, Step, servo_tick};
use crate::world::World;
use serde::Serialize;

/// Zeroes the sensor in free air, as before contact: the mean of 0.1 s of zero-load readings.
pub fn tare(sensor: &mut SensorModel) -> Wrench {
    let n = (0.1 * sensor.params().rate_hz).round().max(1.0) as usize;
    let mut acc = Wrench::default();
    for _ in 0..n {
        let r = sensor.sample(Wrench::default());
        acc.force += r.wrench.force;
        acc.torque += r.wrench.torque;
    }
    Wrench {
        force: acc.force / n as f64,
        torque: acc.torque / n as f64,
    }
}

/// One answer of the estimator, as the lockstep logged it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EstimateLog {
    /// Simulated time of the answer (s).
    pub time_s: f64,
    /// The estimated tangent the probes were relative to (rad).
    pub base_angle_rad: f64,
    /// The true tangent angle at the contact (rad).
    pub true_angle_rad: f64,
    /// The answer.
    pub outcome: TangentOutcome,
}

/// The three boards in lockstep.
#[derive(Debug, Clone)]
pub struct Lockstep {
    world: World,
    sensor: SensorModel,
    servo: ServoCore,
    /// The servo as built, before its first tick: what a restarted servo starts from.
    fresh: ServoCore,
    dt: f64,
    sensor_period: f64,
    ticks: u64,
    sensor_ticks: u64,
    reading: Reading,
    reading_time: f64,
    estimates: Vec<EstimateLog>,
    auto_estimate: bool,
    force_valid: bool,
}

impl Lockstep {
    /// Builds the set-up at rest in contact at the preload.
    pub fn new(cfg: &SimConfig) -> Result<Self, ConfigError> {
        let cfg = &crate::world::resolve(cfg)?;
        cfg.validate()?;
        let q = cfg.start_configuration()?;
        let world = World::new(cfg, q)?;
        let mut sensor = SensorModel::new(cfg.sensor, cfg.seed);
        let tare = tare(&mut sensor);
        // The sensor has been reading the contact for 10 ms (many filter time constants)
        // when the servo starts.
        let mut reading = sensor.sample(world.truth().sensor_wrench);
        for _ in 0..(0.01 * cfg.sensor.rate_hz).ceil() as usize {
            reading = sensor.sample(world.truth().sensor_wrench);
        }
        let tangent = cfg.surface.tangent_angle_at(cfg.start_u_m) + cfg.tangent_error_rad;
        let mut servo = ServoCore::new(
            cfg.servo_params(),
            cfg.plant.arm,
            cfg.plant.elbow,
            q,
            reading.wrench.tared(tare),
            tangent,
        )?;
        servo.set_tare(tare);
        Ok(Self {
            world,
            sensor,
            fresh: servo.clone(),
            servo,
            dt: cfg.servo.dt(),
            sensor_period: 1.0 / cfg.sensor.rate_hz,
            ticks: 0,
            sensor_ticks: 1,
            reading,
            reading_time: 0.0,
            estimates: Vec::new(),
            auto_estimate: true,
            force_valid: true,
        })
    }

    /// One servo period: sensor samples due, servo tick, plant step.
    pub fn step(&mut self) {
        self.step_with(|_, _| Step::Ran);
    }

    /// One servo period with `before` first: the sensor samples due, then [`servo_tick`] (the
    /// servo board's tick routine: `before`, the controller, the world), then the estimator.
    /// The stack's lockstep reference drives its scenario and replays the stack's commands in
    /// `before`; [`Step::Done`] from it ends the period with nothing stepped.
    pub fn step_with(&mut self, before: impl FnOnce(&World, &mut ServoCore) -> Step) -> Step {
        let t = self.ticks as f64 * self.dt;
        while (self.sensor_ticks as f64) * self.sensor_period <= t + 1e-12 {
            self.reading = self.sensor.sample(self.world.truth().sensor_wrench);
            self.reading_time = self.sensor_ticks as f64 * self.sensor_period;
            self.sensor_ticks += 1;
        }
        let force = Force {
            reading: self.reading.wrench,
            valid: self.force_valid,
        };
        let step = servo_tick(&mut self.world, &mut self.servo, force, self.dt, before);
        if step == Step::Ran {
            self.ticks += 1;
            self.answer_estimator();
        }
        step
    }

    /// The estimator board: answers a finished probe run at once (the real stack answers
    /// over iceoryx2 a few milliseconds later; the servo holds meanwhile).
    fn answer_estimator(&mut self) {
        if !self.auto_estimate {
            return;
        }
        let Some(req) = self.servo.pending_probe() else {
            return;
        };
        let outcome = tangent::estimate(
            req.samples,
            req.plan,
            req.base_angle,
            &req.params,
            req.reprobe,
        );
        let log = EstimateLog {
            time_s: self.time(),
            base_angle_rad: req.base_angle,
            true_angle_rad: self.world.truth().tangent_angle_rad,
            outcome,
        };
        self.servo.apply_tangent_outcome(&outcome);
        self.estimates.push(log);
    }

    /// Replaces the servo by one built as the first was and given the old one's state
    /// ([`ServoCore::state`], [`ServoCore::restore`]), as the stack's servo board does when
    /// the supervisor restarts it: the lockstep goes through the same restart.
    pub fn restart_servo(&mut self) -> Result<(), SnapshotError> {
        let state = self.servo.state();
        let tare = self.servo.tare();
        let mut servo = self.fresh.clone();
        servo.restore(&state)?;
        servo.set_tare(tare);
        self.servo = servo;
        Ok(())
    }

    /// Whether the in-process estimator answers probe runs (default true); off, the caller
    /// answers through [`ServoCore::apply_tangent_outcome`].
    pub fn set_auto_estimate(&mut self, on: bool) {
        self.auto_estimate = on;
    }

    /// Marks the force data as (in)valid, as the servo process's watchdog does when the sensor
    /// dies or sends garbage: with `false` the servo goes to its safe state.
    pub fn set_force_valid(&mut self, valid: bool) {
        self.force_valid = valid;
    }

    /// Every estimator answer so far.
    pub fn estimates(&self) -> &[EstimateLog] {
        &self.estimates
    }

    /// Runs `n` ticks.
    pub fn run(&mut self, n: usize) {
        for _ in 0..n {
            self.step();
        }
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        self.ticks as f64 * self.dt
    }

    /// Servo period (s).
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The world (built-in plant or MuJoCo).
    pub fn world(&self) -> &World {
        &self.world
    }

    /// Moves the surface in the world ([`World::set_surface`]).
    pub fn set_surface(&mut self, surface: Surface) {
        self.world.set_surface(surface);
    }

    /// The world truth of the last step.
    pub fn truth(&self) -> &PlantTruth {
        self.world.truth()
    }

    /// The servo.
    pub fn servo(&self) -> &ServoCore {
        &self.servo
    }

    /// The servo, mutable (commands: velocity, dither, tangent).
    pub fn servo_mut(&mut self) -> &mut ServoCore {
        &mut self.servo
    }

    /// The latest sensor reading and its time (s).
    pub fn reading(&self) -> (Reading, f64) {
        (self.reading, self.reading_time)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::servo::ServoMode;

    /// At rest in contact, the stack holds the preload: after 1 s the mean normal force is
    /// the preload within the sensor's noise, and the tool has not moved along the surface.
    #[test]
    fn holds_preload_at_rest() {
        let cfg = SimConfig::default();
        let mut sim = Lockstep::new(&cfg).unwrap();
        sim.run(10_000);
        let mut sum = 0.0;
        for _ in 0..2000 {
            sim.step();
            sum += sim.truth().normal_force_n;
        }
        let mean = sum / 2000.0;
        assert!((mean - 2.5).abs() < 0.05, "mean normal force {mean}");
        let x = sim.truth().tip.x;
        assert!((x - 0.4).abs() < 1e-4, "tip drifted to {x}");
    }

    /// A requested estimate corrects a 3° tangent error on a flat surface to within 0.1°.
    #[test]
    fn closed_loop_tangent_estimate_corrects_the_error() {
        let cfg = SimConfig {
            tangent_error_rad: 3f64.to_radians(),
            ..SimConfig::default()
        };
        let mut sim = Lockstep::new(&cfg).unwrap();
        sim.run(2000);
        sim.servo_mut().request_tangent_estimate();
        let mut n = 0;
        while sim.estimates().is_empty() && n < 200_000 {
            sim.step();
            n += 1;
        }
        let log = sim.estimates()[0];
        let TangentOutcome::Estimate(e) = log.outcome else {
            panic!("{:?}", log.outcome)
        };
        let err = (e.tangent_angle_rad - log.true_angle_rad).to_degrees();
        assert!(err.abs() < 0.1, "error {err}° ({e:?})");
        // It holds until the normal force is back at the preload, then tracks again.
        assert_eq!(sim.servo().mode(), crate::servo::ServoMode::Resuming);
        let mut n = 0;
        while sim.servo().mode() != crate::servo::ServoMode::Track && n < 40_000 {
            sim.step();
            n += 1;
        }
        assert_eq!(sim.servo().mode(), crate::servo::ServoMode::Track);
        assert!((sim.servo().hybrid().frame().tangent_angle - e.tangent_angle_rad).abs() < 1e-12);
    }

    /// Losing the force data mid-traverse with the dither running: tangential motion stops
    /// within 50 ms, the dither is gone within 100 ms, from 30 ms on the normal force stays
    /// below the preload and the tool keeps contact; when the data returns, the servo restores the preload, then velocity and
    /// dither.
    #[test]
    fn lost_force_data_puts_the_servo_in_its_safe_state() {
        let cfg = SimConfig::default();
        let preload = cfg.servo.hybrid.preload_n;
        let mut sim = Lockstep::new(&cfg).unwrap();
        sim.servo_mut().hybrid_mut().set_velocity(0.01);
        sim.servo_mut().set_a_omega(0.05);
        sim.run(10_000);
        let a_before = sim.servo().diag().a_omega_m_per_s;
        assert!(a_before > 0.04);
        sim.set_force_valid(false);
        sim.step();
        assert!(sim.servo().is_safe());
        assert_eq!(sim.servo().hybrid().velocity_target(), 0.0);
        let (mut max_after, mut min_after) = (0.0f64, f64::INFINITY);
        for k in 1..5000 {
            sim.step();
            if k == 500 {
                assert_eq!(sim.servo().hybrid().nominal_velocity(), 0.0);
            }
            if k == 1000 {
                assert!(sim.servo().diag().a_omega_m_per_s < 0.01 * a_before);
            }
            if k >= 300 {
                max_after = max_after.max(sim.truth().normal_force_n);
                min_after = min_after.min(sim.truth().normal_force_n);
            }
        }
        assert!(max_after <= preload, "normal force rose to {max_after} N");
        assert!(
            min_after > 0.5 * preload,
            "contact nearly lost: {min_after} N"
        );
        assert_eq!(sim.servo().counters().safe_entries, 1);
        sim.set_force_valid(true);
        let mut n = 0;
        while sim.servo().mode() != crate::servo::ServoMode::Track && n < 50_000 {
            sim.step();
            n += 1;
        }
        assert!(!sim.servo().is_safe());
        assert_eq!(sim.servo().hybrid().velocity_target(), 0.01);
        assert!((sim.servo().diag().a_omega_m_per_s - a_before).abs() < 1e-9);
        sim.run(5000);
        assert!((sim.truth().normal_force_n - preload).abs() < 0.5 * preload);
    }

    /// Same seed, same run, bit for bit.
    #[test]
    fn lockstep_is_deterministic() {
        let cfg = SimConfig::default();
        let mut a = Lockstep::new(&cfg).unwrap();
        let mut b = Lockstep::new(&cfg).unwrap();
        a.servo_mut().hybrid_mut().set_velocity(0.02);
        b.servo_mut().hybrid_mut().set_velocity(0.02);
        a.run(3000);
        b.run(3000);
        assert_eq!(a.truth(), b.truth());
    }

    /// A servo restarted from its own state carries on bit for bit where nothing comes back in
    /// brief: tracking with the cost tuner running (its period window is kept whole), at any
    /// of several restart ticks, with the same world, torques and tuner as a servo that never
    /// stopped. The state round-trips through the snapshot unchanged but for the moving
    /// average of the normal force, which comes back in brief (its mean and variance, to
    /// rounding).
    #[test]
    fn a_restarted_servo_carries_on_bit_for_bit() {
        use crate::tuner::{CostTunerParams, TunerConfig};
        let mut cfg = SimConfig::default();
        cfg.servo.tuner = TunerConfig::Cost(CostTunerParams::default());
        for restart_at in [1, 4_321, 12_345] {
            let mut a = Lockstep::new(&cfg).unwrap();
            let mut b = Lockstep::new(&cfg).unwrap();
            for sim in [&mut a, &mut b] {
                sim.servo_mut().hybrid_mut().set_velocity(0.01);
                sim.servo_mut().set_a_omega(0.02);
                sim.servo_mut().set_tuning(true);
                sim.run(restart_at);
            }
            b.restart_servo().unwrap();
            let (sa, mut sb) = (a.servo().state(), b.servo().state());
            let (wa, wb) = (sa.normal_window, sb.normal_window);
            assert_eq!(wa.len, wb.len);
            assert!(
                (wa.mean - wb.mean).abs() <= 1e-12 * wa.mean.abs(),
                "{wa:?} {wb:?}"
            );
            assert!(
                (wa.variance - wb.variance).abs() <= 1e-6 * wa.variance,
                "{wa:?} {wb:?}"
            );
            sb.normal_window = wa;
            assert_eq!(sa, sb, "restart at {restart_at}");
            for k in 0..20_000 {
                a.step();
                b.step();
                assert_eq!(
                    a.truth(),
                    b.truth(),
                    "restart at {restart_at}, tick {k} after"
                );
                assert_eq!(a.servo().diag(), b.servo().diag());
            }
            assert_eq!(a.servo().tuner_report(), b.servo().tuner_report());
        }
    }

    /// A servo restarted in the middle of its probe strokes (or while it awaits the estimate)
    /// probes again from the start: it holds the stroke's set-point, stops, settles, strokes,
    /// gets its estimate and tracks on; the normal force stays within 1.5× the preload
    /// throughout, and the estimation counters carry on.
    #[test]
    fn a_servo_restarted_mid_probe_probes_again() {
        let cfg = SimConfig {
            tangent_error_rad: 3f64.to_radians(),
            ..SimConfig::default()
        };
        let preload = cfg.servo.hybrid.preload_n;
        for (mode, after) in [(ServoMode::Probing, 3_000), (ServoMode::Probing, 17_777)] {
            let mut sim = Lockstep::new(&cfg).unwrap();
            sim.set_auto_estimate(false);
            sim.run(2000);
            sim.servo_mut().request_tangent_estimate();
            while sim.servo().mode() != mode {
                sim.step();
            }
            sim.run(after);
            assert_eq!(sim.servo().mode(), mode);
            sim.restart_servo().unwrap();
            assert_eq!(sim.servo().mode(), ServoMode::Stopping);
            assert_eq!(sim.servo().counters().started, 1);
            sim.set_auto_estimate(true);
            let mut max = 0.0f64;
            let mut n = 0;
            while sim.estimates().is_empty() && n < 200_000 {
                sim.step();
                max = max.max(sim.truth().normal_force_n);
                n += 1;
            }
            assert!(
                max <= 1.5 * preload,
                "normal force {max} N after the restart"
            );
            let log = sim.estimates()[0];
            let TangentOutcome::Estimate(e) = log.outcome else {
                panic!("{:?}", log.outcome)
            };
            assert!(
                (e.tangent_angle_rad - log.true_angle_rad)
                    .to_degrees()
                    .abs()
                    < 0.1
            );
            assert_eq!(sim.servo().counters().estimates, 1);
        }
        // Awaiting the estimate: the record is gone with the process; probe again.
        let mut sim = Lockstep::new(&cfg).unwrap();
        sim.set_auto_estimate(false);
        sim.servo_mut().request_tangent_estimate();
        while sim.servo().mode() != ServoMode::AwaitingEstimate {
            sim.step();
        }
        sim.restart_servo().unwrap();
        assert_eq!(sim.servo().mode(), ServoMode::Stopping);
    }

    /// A snapshot with a non-finite number is refused and changes nothing.
    #[test]
    fn an_insane_snapshot_is_refused() {
        let cfg = SimConfig::default();
        let mut sim = Lockstep::new(&cfg).unwrap();
        sim.run(100);
        let before = sim.servo().state();
        let mut bad = before;
        bad.hybrid.depth_m = f64::NAN;
        assert!(sim.servo_mut().restore(&bad).is_err());
        bad = before;
        bad.mode = 9;
        assert!(sim.servo_mut().restore(&bad).is_err());
        assert_eq!(sim.servo().state(), before);
    }
}

#[cfg(test)]
#[path = "sim_contact_tests.rs"]
mod contact_tests;
