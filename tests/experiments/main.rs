//! The thesis experiments meet their acceptance criteria, and the `afs experiment` command
//! writes its plot and JSON. Run in release: `cargo test --release`.

use afs_shared::experiments::{self, Options};
use afs_shared::setups::Rig;
use std::process::Command;

#[cfg(feature = "mujoco")]
#[path = "../common/mod.rs"]
mod common;
#[cfg(feature = "mujoco")]
mod mujoco;

fn assert_passed<S>(name: &str, out: &experiments::Outcome<S>) {
    for c in &out.checks {
        assert!(
            c.pass,
            "{name}: check '{}' failed: {} {} {}",
            c.name,
            c.value,
            c.relation.symbol(),
            c.limit
        );
    }
}

/// friction-id recovers F_t, F_v, F_s within 5 % and ẋ_s within 10 % at the default noise.
#[test]
fn friction_identification_recovers_the_thesis_coefficients() {
    let out = experiments::friction_id(&Options::default()).unwrap();
    assert_passed("friction-id", &out);
}

/// With Aω = 5ẋ_o the mean friction is ≤ 20 % of the undithered one and within 15 % of the
/// law's cycle average at the velocity the contact saw.
#[test]
fn dither_suppresses_friction_as_the_cycle_average_predicts() {
    let out = experiments::fig4_5(&Options::default()).unwrap();
    assert_passed("fig4.5", &out);
    let s = &out.summary;
    assert!(
        s.transmission > 0.5 && s.transmission <= 1.05,
        "transmission {}",
        s.transmission
    );
}

/// μ from simulated trials is within 3 % of the truth; the thesis table gives 0.709.
#[test]
fn friction_coefficient_from_trials() {
    let out = experiments::fig4_6(&Options::default()).unwrap();
    assert_passed("fig4.6", &out);
    let table = experiments::fig4_6(&Options {
        thesis_table: true,
        ..Default::default()
    })
    .unwrap();
    assert_eq!(table.summary.coefficient, "0.709");
}

/// The oscillation of the force under dither matches the model at every amplitude.
#[test]
fn oscillation_per_amplitude_matches_the_model() {
    let out = experiments::fig4_7(&Options::default()).unwrap();
    assert_passed("fig4.7", &out);
}

/// The friction law's own figures (4.1–4.4) agree with their closed forms and quadrature, and
/// fig. 4.4's lockstep points with the exact cycle mean.
#[test]
fn friction_law_figures_match_closed_forms() {
    let opts = Options::default();
    assert_passed("fig4.1", &experiments::fig4_1(&opts).unwrap());
    let f42 = experiments::fig4_2(&opts).unwrap();
    assert_passed("fig4.2", &f42);
    // With eq. 4.23 the curve's minimum is near 0.1 m/s (the Stribeck dip meets F_v·ẋ).
    let v = f42.summary.minimum_velocity_m_per_s.unwrap();
    assert!((0.05..0.2).contains(&v), "minimum at {v} m/s");
    let f43 = experiments::fig4_3(&opts).unwrap();
    assert_passed("fig4.3", &f43);
    // The oscillation is not proportional to Aω (the thesis's statement): 32x the Aω gives
    // well under 2x the σ.
    assert!(f43.summary.std_growth < 2.0 && f43.summary.a_omega_ratio > 30.0);
    assert_passed("fig4.4", &experiments::fig4_4(&opts).unwrap());
}

/// Slow tuning (figs. 4.9, 4.10): Aω passes ẋ_o, the mean friction falls near zero, the
/// oscillation follows the amplitude and the normal force stays steady on afs's rig.
#[test]
fn slow_tuning_drives_the_mean_friction_near_zero() {
    let opts = Options::default();
    assert_passed("fig4.9", &experiments::fig4_9(&opts).unwrap());
    assert_passed("fig4.10", &experiments::fig4_10(&opts).unwrap());
}

/// The thesis's rig (PID only, coupled point) shows what the thesis saw and afs's rig does not:
/// the oscillation grows with the dither amplitude and the normal force swings.
#[test]
fn thesis_rig_shows_growth_and_normal_force_swings() {
    let on = |rig: Rig| {
        let mut base = afs_shared::config::SimConfig::default();
        rig.apply(&mut base).unwrap();
        Options {
            base,
            rig,
            ..Default::default()
        }
    };
    let (afs_rig, thesis_rig) = (on(Rig::Afs), on(Rig::Thesis));
    let a = experiments::fig4_7(&afs_rig).unwrap();
    let t = experiments::fig4_7(&thesis_rig).unwrap();
    assert_passed("fig4.7 thesis rig", &t);
    assert!(
        a.summary.growth_ratio < 1.2 && t.summary.growth_ratio >= 1.5,
        "growth {} (afs) vs {} (thesis)",
        a.summary.growth_ratio,
        t.summary.growth_ratio
    );
    let a = experiments::fig4_10(&afs_rig).unwrap();
    let t = experiments::fig4_10(&thesis_rig).unwrap();
    assert!(
        t.summary.normal_std_fraction > 3.0 * a.summary.normal_std_fraction,
        "normal-force std {} (afs) vs {} (thesis)",
        a.summary.normal_std_fraction,
        t.summary.normal_std_fraction
    );
}

/// On a turning surface the servo follows the drift form of eq. 5.10's RLS more closely than
/// the batch estimate, and exponential forgetting lags behind both.
#[test]
fn recursive_estimate_follows_a_turning_surface() {
    let out = experiments::rls(&Options::default()).unwrap();
    assert_passed("rls", &out);
    let runs = &out.summary.runs;
    assert_eq!(runs.len(), 3);
    let (batch, forgetting, drift) = (&runs[0], &runs[1], &runs[2]);
    assert!(drift.tracking_rms_error_deg < batch.tracking_rms_error_deg);
    assert!(forgetting.tracking_rms_error_deg > batch.tracking_rms_error_deg);
}

/// Both tuners bring the mean friction below 25 % within 5 s, hold the normal force within
/// ±10 % after 0.5 s and never lose contact; the JSON explains where each settles.
#[test]
fn both_tuners_suppress_friction_within_five_seconds() {
    let out = experiments::fig4_8(&Options::default()).unwrap();
    assert_passed("fig4.8", &out);
    let runs = &out.summary.runs;
    assert_eq!(runs.len(), 2);
    let cost = runs.iter().find(|r| r.tuner == "cost").unwrap();
    // The cost tuner settles: Aω no longer moves and the cost gradient vanishes at a*.
    assert!(
        cost.final_rate_m_per_s2.abs() < 1e-3,
        "cost tuner still moving {}",
        cost.final_rate_m_per_s2
    );
    assert!(cost.why.contains("interior minimum"), "{}", cost.why);
    let thesis = runs.iter().find(|r| r.tuner == "thesis").unwrap();
    assert!(thesis.why.contains("eq. 4.22"), "{}", thesis.why);
}

/// A different seed changes the noise but not the conclusions.
#[test]
fn tuning_conclusions_hold_for_another_seed() {
    let out = experiments::fig4_8(&Options {
        seed: 7,
        ..Default::default()
    })
    .unwrap();
    assert_passed("fig4.8 seed 7", &out);
}

fn afs() -> Command {
    Command::new(env!("CARGO_BIN_EXE_afs"))
}

#[test]
fn experiment_command_prints_json_and_writes_the_plot() {
    let dir = std::env::temp_dir().join(format!("afs-exp-{}", std::process::id()));
    let out = afs()
        .args(["experiment", "fig4.6", "--thesis-table", "--json", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: afs::tools::experiment::ExperimentReport =
        serde_json::from_slice(&out.stdout).expect("stdout is one experiment report");
    assert_eq!(r.experiment, "fig4.6");
    assert_eq!(r.summary["coefficient"], "0.709");
    assert!(r.passed && r.checks.iter().all(|c| c.pass), "{r}");
    assert!(r.plot.ends_with("fig4_6.svg"));
    let plot = dir.join("fig4_6.svg");
    let svg = std::fs::read_to_string(&plot).unwrap();
    assert!(svg.contains("normal force F_N (N)") && svg.contains("tangential force F_t (N)"));
    std::fs::remove_dir_all(&dir).ok();
}

/// `--rig thesis` names its plot after the rig and is refused where it is not defined.
#[test]
fn thesis_rig_option_is_reported_and_checked() {
    let dir = std::env::temp_dir().join(format!("afs-rig-{}", std::process::id()));
    let out = afs()
        .args(["experiment", "fig4.3", "--rig", "thesis", "--json", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: afs::tools::experiment::ExperimentReport = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r.rig, Rig::Thesis);
    assert!(r.plot.ends_with("fig4_3_thesis.svg") && dir.join("fig4_3_thesis.svg").exists());
    let out = afs()
        .args(["experiment", "tangent", "--rig", "thesis", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("friction experiments") && err.contains("without --rig"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn unknown_experiment_is_a_clear_error() {
    let out = afs()
        .args(["experiment", "fig9.9", "--out", "/tmp"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("invalid value 'fig9.9'") && err.contains("fig4.8") && err.contains("fig5.9"),
        "{err}"
    );
}

/// Tangent estimation: ≤ 0.1° without friction and ≤ 0.5° with friction while the suppression
/// dither runs, for |α0| ≤ 10°; up to 15° every accepted answer is within 0.5° (a fold asks for
/// a re-probe instead).
#[test]
fn tangent_estimates_are_accurate_and_never_folded() {
    let out = experiments::tangent(&Options::default()).unwrap();
    assert_passed("tangent", &out);
    for case in &out.summary.cases {
        assert_eq!(
            case.wrong_answers, 0,
            "{}: {} accepted answers > 0.5° off",
            case.case, case.wrong_answers
        );
        // Between the probes (α0 in (−10°, −5°)) the thesis's RMS form would fold: the
        // estimator either re-probed or answered within 0.5°.
        for t in case
            .trials
            .iter()
            .filter(|t| t.alpha0_deg > -10.0 && t.alpha0_deg < -5.0)
        {
            assert!(
                t.first == "reprobe" || t.error_deg.is_some_and(|e| e.abs() < 0.5),
                "{}: α0 {}: {:?}",
                case.case,
                t.alpha0_deg,
                t
            );
        }
    }
}

/// Tracking the sinusoid: tangent error RMS ≤ 1°, regulated normal force within ±20 %, never
/// out of contact, and the number of estimations reported.
#[test]
fn sinusoid_is_tracked() {
    let out = experiments::fig5_6(&Options::default()).unwrap();
    assert_passed("fig5.6", &out);
    assert!(out.summary.run.estimations.estimates > 0);
}

/// Every corner of the piecewise-linear profile is detected and tracked through.
#[test]
fn corners_are_detected_and_tracked_through() {
    let out = experiments::corners(&Options::default()).unwrap();
    assert_passed("corners", &out);
    assert_eq!(out.summary.tracked, out.summary.corners.len());
}

/// The preliminary correlation method tracks the corner profile worse than the dither method.
#[test]
fn preliminary_method_is_worse_at_corners() {
    let out = experiments::fig5_3(&Options::default()).unwrap();
    assert_passed("fig5.3", &out);
}

/// The rotation centre of a box pushed into a corner is estimated within 1 % of its size at
/// σ = 0.02 N while the box is rotated into the corner.
#[test]
fn rotation_centre_within_one_percent() {
    let out = experiments::fig5_9(&Options::default()).unwrap();
    assert_passed("fig5.9", &out);
    assert!(out.summary.estimates.len() >= 5);
}

/// Insertion at seed 1 (1.0 mm, −0.31° initial errors): the dither method inserts the peg
/// 15 mm within the force limit; the same controller without the dither does not (its walk
/// sticks and slips into the chamfer above the force limit): the check can fail.
#[test]
fn the_dither_method_inserts_where_its_baseline_does_not() {
    use afs_shared::insertion::controller::Method;
    let run = |method| {
        let mut opts = Options::default();
        opts.insertion.method = method;
        experiments::insertion(&opts).unwrap()
    };
    let ok = run(Method::Dither);
    // The insertion time is a target (the median's, over seeds), not a correctness check.
    for c in ok.checks.iter().filter(|c| !c.is_target()) {
        assert!(c.pass, "{}", c.line());
    }
    assert!(ok.summary.run.inserted && ok.summary.run.depth_mm >= 15.0);
    assert_eq!((ok.summary.method, ok.summary.drive), ("dither", "ideal"));
    let baseline = run(Method::NoDither);
    let inserted = afs_shared::check::find(&baseline.checks, "inserted").unwrap();
    assert!(!inserted.pass, "{}", inserted.line());
    // On Whitney's jamming diagram the dither method's applied wrench stays inside the
    // parallelogram far more often than the search's, which jams (seed 1: 0.82 and 0.37).
    let search = run(Method::Search);
    let inside = |o: &experiments::Outcome<experiments::InsertionSummary>| {
        assert!(o.summary.run.jamming_diagram_samples > 50);
        o.summary.run.inside_parallelogram.unwrap()
    };
    assert!(search.summary.run.jammed_ticks > 1000);
    assert!(inside(&ok) > 0.7 && inside(&search) < 0.5);
}

/// The insertion experiment at `seed` with the options `set` changes.
fn insertion_run(
    seed: u64,
    set: impl FnOnce(&mut afs_shared::insertion::rig::InsertionOptions),
) -> afs_shared::insertion::monitor::InsertionRun {
    let mut opts = Options {
        seed,
        ..Options::default()
    };
    set(&mut opts.insertion);
    experiments::insertion(&opts).unwrap().summary.run
}

/// The ticks of `run` whose true state was `truth` and estimated `estimated`.
fn wrong_ticks(
    run: &afs_shared::insertion::monitor::InsertionRun,
    truth: afs_shared::insertion::plant::ContactState,
    estimated: afs_shared::insertion::plant::ContactState,
) -> usize {
    run.wrong_states
        .iter()
        .filter(|w| (w.truth, w.estimated) == (truth, estimated))
        .map(|w| w.ticks)
        .sum()
}

/// The part's orientation unknown: at seeds 53 and 162 (turned −0.44° and −1.90°) the face
/// was named the chamfer for 8,100 ticks of the find phase while the estimator took the face's
/// depth in the frame the robot believed (classification 0.78 and 0.81); from the face's line
/// through the hole's nominal centre and its friction cone, at least 95 % right.
#[test]
fn an_unknown_parts_face_is_not_taken_for_the_chamfer() {
    use afs_shared::insertion::plant::ContactState;
    use afs_shared::insertion::rig::PartFrame;
    for seed in [53, 162] {
        let run = insertion_run(seed, |o| o.part_frame = PartFrame::Unknown);
        assert!(run.inserted, "seed {seed}");
        let face_as_chamfer = wrong_ticks(&run, ContactState::Face, ContactState::Chamfer);
        assert!(
            face_as_chamfer < run.classified_ticks / 100,
            "seed {seed}: {run:?}"
        );
        assert!(
            run.state_classification_accuracy >= 0.95,
            "seed {seed}: {run:?}"
        );
    }
}

/// The part's orientation unknown and no chamfer, seed 6 (turned 1.08°, 0.67 mm): the peg,
/// square to the face the robot believes, touches the face with its lower corner already in
/// the hole; taken for in the bore by its tilt in the robot's frame, it jammed at 1.57 mm and
/// never inserted. Counting the tilt the robot does not know, it walks on into the hole and
/// inserts.
#[test]
fn an_unknown_part_without_a_chamfer_is_not_entered_on_its_edge() {
    use afs_shared::insertion::rig::PartFrame;
    let mut opts = Options {
        seed: 6,
        ..Options::default()
    };
    opts.insertion.part_frame = PartFrame::Unknown;
    opts.insertion.chamfer_mm = 0.0;
    let run = experiments::insertion(&opts).unwrap().summary.run;
    assert!(run.inserted, "{run:?}");
}

/// Without a chamfer the peg walking over the hole rests its tip face on the hole's sharp
/// edge: that is the face (the peg is not in the bore), as the chamfer's top edge is, and the
/// estimator names it so. Seed 53 rests there through the find phase (1.1 s): named one-point
/// in the hole by the truth, the classification was 0.73 on either drive.
#[test]
fn a_peg_resting_on_the_sharp_edge_is_on_the_face() {
    use afs_shared::insertion::drive::Drive;
    use afs_shared::insertion::plant::ContactState;
    for drive in [Drive::Ideal, Drive::Arm] {
        let run = insertion_run(53, |o| {
            o.chamfer_mm = 0.0;
            o.drive = drive;
        });
        let one_point_as_face = wrong_ticks(&run, ContactState::OnePoint, ContactState::Face);
        assert!(
            run.inserted && one_point_as_face < run.classified_ticks / 100,
            "{drive:?}: {run:?}"
        );
        assert!(
            run.state_classification_accuracy >= 0.95,
            "{drive:?}: {run:?}"
        );
    }
}

/// The arm on a sharp edge, seeds 11 and 132: started tilted 0.37° and 0.33° with the corner
/// over the face the lower, the peg walked over the hole was left at that tilt and dropped
/// onto the far edge over the force limit (15.8 N and 16.9 N, 0.02 mm in). Tilted out to the
/// kept 0.5° on its side while it walks, it inserts.
#[test]
fn the_arm_enters_a_sharp_edged_hole_corner_first() {
    use afs_shared::insertion::drive::Drive;
    for seed in [11, 132] {
        let run = insertion_run(seed, |o| {
            o.chamfer_mm = 0.0;
            o.drive = Drive::Arm;
        });
        assert!(run.inserted, "seed {seed}: {run:?}");
    }
}

/// Bad insertion options are refused before anything runs, exit 2, naming the option.
#[test]
fn bad_insertion_options_are_refused_by_name() {
    for (flag, value, needle) in [
        ("--clearance", "0.7", "insertion.clearance"),
        ("--clearance", "0", "insertion.clearance"),
        ("--mu", "nan", "insertion.mu"),
        ("--lateral-mm", "-9", "insertion.lateral_mm"),
        ("--angle-deg", "inf", "insertion.angle_deg"),
        ("--plant", "bullet", "possible values: builtin, mujoco"),
        ("--drive", "wrist", "--drive"),
    ] {
        let out = afs()
            .args(["experiment", "insertion", flag, value])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(
            err.contains(needle) && !err.contains("panicked"),
            "{flag} {value}: {err}"
        );
    }
}

/// `afs experiment fig4.5 --seeds 1..6 --jobs 2 --json`: one report whose every check was run
/// at the six seeds, with its pass rate and distribution (median ≤ p90 ≤ worst for an "at
/// most" check), and the plot of the checks over the seeds; the same seeds one by one give the
/// same figures.
#[test]
fn a_seed_sweep_reports_each_checks_distribution() {
    let dir = std::env::temp_dir().join(format!("afs-sweep-{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_afs"))
        .args([
            "experiment",
            "fig4.5",
            "--seeds",
            "1..6",
            "--jobs",
            "2",
            "--json",
        ])
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: afs::tools::experiment::SweepReport = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((r.seeds, r.jobs), ([1, 6], 2));
    assert!(std::path::Path::new(&r.plot).is_file());
    let mut worst = Vec::new();
    for seed in 1..=6 {
        let o = experiments::fig4_5(&Options {
            seed,
            ..Options::default()
        })
        .unwrap();
        worst.push(o.checks);
    }
    for (i, c) in r.checks.iter().enumerate() {
        assert_eq!(c.runs, 6, "{c:?}");
        assert_eq!(c.passes, worst.iter().filter(|cs| cs[i].pass).count());
        assert!(c.median <= c.p90 && c.p90 <= c.worst, "{c:?}");
        let max = worst.iter().map(|cs| cs[i].value).fold(f64::MIN, f64::max);
        assert_eq!(c.worst, max, "{c:?}");
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// The insertion grid (`--grid`): every method at each of the 18 fits over the seeds, each
/// point's count the one the single runs give; its plot; refused (exit 2) on another
/// experiment or without `--seeds`.
#[test]
fn the_insertion_grid_runs_every_method_at_every_fit() {
    use afs_shared::insertion::controller::Method;
    let dir = std::env::temp_dir().join(format!("afs-grid-test-{}", std::process::id()));
    let out = afs()
        .args([
            "experiment",
            "insertion",
            "--grid",
            "--seeds",
            "1..2",
            "--jobs",
            "2",
        ])
        .args(["--json", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).expect(&err);
    assert_eq!(
        out.status.success(),
        r["passed"].as_bool().unwrap(),
        "{err}"
    );
    let points = r["points"].as_array().unwrap();
    assert_eq!(points.len(), 18 * 3);
    assert!(std::path::Path::new(r["plot"].as_str().unwrap()).is_file());
    // The tightest, roughest, sharp-edged fit: each method's count as the single runs give it.
    for p in points
        .iter()
        .filter(|p| p["clearance_ratio"] == 0.0005 && p["mu"] == 0.5)
    {
        let method = Method::parse(p["method"].as_str().unwrap()).unwrap();
        let mut opts = Options::default();
        opts.insertion.clearance_ratio = 0.0005;
        opts.insertion.mu = 0.5;
        opts.insertion.chamfer_mm = p["chamfer_mm"].as_f64().unwrap();
        opts.insertion.method = method;
        let inserted = (1..=2)
            .filter(|&seed| {
                let o = experiments::insertion(&Options {
                    seed,
                    ..opts.clone()
                })
                .unwrap();
                o.summary.run.inserted
            })
            .count();
        assert_eq!(p["runs"], 2);
        assert_eq!(p["inserted"].as_u64().unwrap() as usize, inserted, "{p}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    for args in [
        &["experiment", "fig4.5", "--grid", "--seeds", "1..2"][..],
        &["experiment", "insertion", "--grid"][..],
    ] {
        let out = afs().args(args).arg("--out").arg(&dir).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains("--grid") || err.contains("--seeds"),
            "{args:?}: {err}"
        );
    }
}
