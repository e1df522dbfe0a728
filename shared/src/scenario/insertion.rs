//! The `insertion` scenario's lockstep reference: the rig the servo board runs
//! ([`InsertionRig`]), with the sensor model sampled on simulated time, tick by tick as the
//! stack numbers them, through the stack's force-invalid ticks.

use super::report::InvalidTicks;
use super::{Replay, Scenario, ScenarioReport};
use crate::error::{ConfigError, ScenarioError};
use crate::insertion::rig::InsertionRig;
use crate::msg::{PegSample, PlantSample, ServoSample};
use crate::sensor::{SensorModel, Wrench};
use crate::sim::tare;

/// Runs the insertion of `scenario` for `duration_s` (or to its time limit, holding at depth
/// once in; a force above the limit ends it at once, as the servo board does). A restarted servo
/// resumes the rig exactly (its whole state is in the world snapshot), so the restarts of
/// `replay` change nothing here; its force-invalid ticks hold the wrist as the stack's servo
/// did.
pub(super) fn run(
    scenario: &Scenario,
    duration_s: f64,
    replay: &Replay<'_>,
) -> Result<ScenarioReport, ScenarioError> {
    let o = scenario.insertion.ok_or_else(|| {
        ConfigError::rule(
            "scenario",
            "is not an insertion; it has no insertion settings",
        )
    })?;
    let cfg = &scenario.cfg;
    let dt = cfg.servo.dt();
    let mut rig = InsertionRig::on_world(&o, cfg.seed, &cfg.world, dt)?;
    let mut sensor = SensorModel::new(cfg.sensor, cfg.seed);
    let zero = tare(&mut sensor);
    let mut monitor = scenario.monitor();
    let limit = (duration_s.min(scenario.natural_duration_s) / dt).round() as u64;
    let (mut reading, mut next_sample, period) = (Wrench::default(), 0.0, 1.0 / cfg.sensor.rate_hz);
    let mut invalid = InvalidTicks::new(replay.force_invalid);
    for seq in 1..=limit {
        if rig.failed() {
            break;
        }
        while next_sample <= rig.time_s() {
            reading = sensor.sample(rig.sensor_wrench()).wrench;
            next_sample += period;
        }
        let valid = invalid.valid(seq);
        let used = valid.then(|| reading.tared(zero));
        rig.step(used, dt);
        monitor.push(
            &PlantSample::of_peg(&rig, seq, 0),
            &ServoSample::of_peg(&rig, seq, 0, used),
        );
        monitor.push_peg(&PegSample::of_rig(&rig, seq, 0, valid));
    }
    Ok(monitor.report())
}

#[cfg(test)]
mod tests {
    use super::super::{Scenario, TickRange, run_lockstep, run_lockstep_replay};
    use super::*;
    use crate::config::SimConfig;
    use crate::experiments::{Options, insertion};

    /// The scenario's lockstep is `afs experiment insertion` at the same seed, figure for
    /// figure: one rig, one sensor model, one monitor.
    #[test]
    fn the_insertion_scenario_is_the_experiment() {
        for seed in [1, 4] {
            let base = SimConfig {
                seed,
                ..SimConfig::default()
            };
            let s = Scenario::new("insertion", &base).unwrap();
            let r = run_lockstep(&s, 100.0).unwrap();
            let run = r.insertion.expect("an insertion report");
            let e = insertion(&Options {
                seed,
                ..Options::default()
            })
            .unwrap()
            .summary;
            assert!(run.inserted, "seed {seed}: {run:?}");
            assert_eq!(run.insertion_time_s, e.run.insertion_time_s);
            assert_eq!(run.peak_force_n, e.run.peak_force_n);
            assert_eq!(
                run.state_classification_accuracy,
                e.run.state_classification_accuracy
            );
            // It runs to the time limit, holding at depth once in.
            assert_eq!(r.ticks, 100_000);
            assert_eq!(r.safe_ticks, 0);
        }
    }

    /// The scenario takes the set-up's `[insertion]` settings (a stack file's
    /// `[sim.insertion]`): its fit, method and time limit.
    #[test]
    fn the_scenario_runs_the_set_ups_insertion() {
        let mut base = SimConfig::default();
        base.insertion.method = crate::insertion::controller::Method::Search;
        base.insertion.clearance_ratio = 0.01;
        base.insertion.time_limit_s = 4.0;
        let s = Scenario::new("insertion", &base).unwrap();
        assert_eq!(s.insertion, Some(base.insertion));
        assert_eq!(s.natural_duration_s, 4.0);
        let r = run_lockstep(&s, 100.0).unwrap();
        assert_eq!(r.ticks, 40_000);
        base.insertion.mu = f64::NAN;
        let e = Scenario::new("insertion", &base).unwrap_err();
        assert!(e.to_string().contains("insertion.mu"), "{e}");
    }

    /// The stack's force-invalid ticks are replayed: the wrist holds for exactly those ticks
    /// (the safe state), and the insertion goes on after them.
    #[test]
    fn the_reference_holds_the_wrist_on_the_stacks_invalid_ticks() {
        let s = Scenario::new("insertion", &SimConfig::default()).unwrap();
        let gaps = [
            TickRange {
                first: 8_000,
                len: 300,
            },
            TickRange {
                first: 20_000,
                len: 1,
            },
        ];
        let replay = Replay {
            force_invalid: &gaps,
            ..Replay::default()
        };
        let r = run_lockstep_replay(&s, 100.0, &replay).unwrap();
        assert_eq!(r.safe_ticks, 301);
        let run = r.insertion.unwrap();
        assert!(run.inserted, "{run:?}");
        let plain = run_lockstep(&s, 100.0).unwrap().insertion.unwrap();
        assert_ne!(run.insertion_time_s, plain.insertion_time_s);
    }
}
