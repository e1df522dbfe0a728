use super::*;
use crate::insertion::controller::{ControllerParams, Method};
use crate::math::Vec2;

/// A rig restored from another's state mid-insertion carries on bit for bit as that one
/// does: what a restarted servo relies on.
#[test]
fn a_restored_rig_carries_on_exactly() {
    for (drive, part_frame) in [
        (Drive::Ideal, PartFrame::Known),
        (Drive::Arm, PartFrame::Known),
        (Drive::Ideal, PartFrame::Unknown),
    ] {
        let o = InsertionOptions {
            drive,
            part_frame,
            ..InsertionOptions::default()
        };
        restored_rig_carries_on(&o, &WorldConfig::default());
    }
}

/// The same on MuJoCo's peg, its state taken through the world snapshot's message: MuJoCo's
/// joints, rates and warm start resume it exactly, and with the arm MuJoCo's arm (whose joints
/// and rates the drive's state carries) carries the peg and resumes too. A state of the other
/// world is refused.
#[cfg(feature = "mujoco")]
#[test]
fn a_restored_rig_on_mujoco_carries_on_exactly() {
    use crate::msg::InsertionState;
    let mujoco = mujoco_world();
    for drive in [Drive::Ideal, Drive::Arm] {
        let o = InsertionOptions {
            drive,
            ..InsertionOptions::default()
        };
        restored_rig_carries_on(&o, &mujoco);
        let rig = InsertionRig::on_world(&o, 3, &mujoco, 1e-4).unwrap();
        assert_eq!(
            rig.arm.as_ref().map(ArmDrive::on_mujoco),
            (drive == Drive::Arm).then_some(true)
        );
    }
    let o = InsertionOptions::default();
    let on_mujoco = InsertionRig::on_world(&o, 3, &mujoco, 1e-4).unwrap();
    let mut builtin = InsertionRig::new(&o, 3).unwrap();
    let wire = RigState::from(&InsertionState::from(&on_mujoco.state()));
    assert!(wire.mujoco.is_some());
    assert!(builtin.restore(&wire).is_err());
    let mut on_mujoco = on_mujoco;
    assert!(on_mujoco.restore(&builtin.state()).is_err());
}

/// MuJoCo's world of the insertion, on its defaults.
#[cfg(feature = "mujoco")]
fn mujoco_world() -> WorldConfig {
    WorldConfig {
        kind: crate::world::WorldKind::Mujoco,
        ..WorldConfig::default()
    }
}

fn restored_rig_carries_on(o: &InsertionOptions, world: &WorldConfig) {
    let o = *o;
    let dt = 1e-4;
    let mut a = InsertionRig::on_world(&o, 3, world, dt).unwrap();
    let reading = |r: &InsertionRig, k: u32| {
        let mut w = r.sensor_wrench();
        w.force += Vec2::new(0.01, -0.01) * f64::from(k % 7);
        w
    };
    let mut k = 0;
    while a.phase() != Phase::Insert {
        a.step(Some(reading(&a, k)), dt);
        k += 1;
        assert!(a.time_s() < 10.0, "never reached the insert phase");
    }
    let mut b = InsertionRig::on_world(&o, 3, world, dt).unwrap();
    b.restore(&RigState::from(&crate::msg::InsertionState::from(
        &a.state(),
    )))
    .unwrap();
    for j in 0..2000 {
        let valid = j % 300 > 10;
        let (ra, rb) = (reading(&a, k + j), reading(&b, k + j));
        a.step(valid.then_some(ra), dt);
        b.step(valid.then_some(rb), dt);
    }
    assert_eq!(a.state(), b.state());
    assert_eq!(a.truth(), b.truth());
    // A fresh rig is elsewhere: the check can tell.
    let fresh = InsertionRig::on_world(&o, 3, world, dt).unwrap();
    assert_ne!(fresh.state(), b.state());
}

/// The part turned by the seed's angle error and the robot not told: where the peg's
/// corner walks far enough on the face (seed 10: 1.83° turned), the face's tangent is
/// found to a hundredth of a degree before the peg reaches the hole; where it is told
/// (`known`) there is nothing to find.
#[test]
fn an_unknown_parts_face_is_found_from_the_corner_it_walks_on() {
    for (part_frame, within_deg) in [(PartFrame::Unknown, 0.01), (PartFrame::Known, 0.0)] {
        let o = InsertionOptions {
            part_frame,
            ..InsertionOptions::default()
        };
        let mut r = InsertionRig::new(&o, 10).unwrap();
        assert!(r.initial_errors().1.to_degrees().abs() > 1.5);
        let before = r.face_error_rad();
        while matches!(r.phase(), Phase::Approach | Phase::Find) {
            let w = r.sensor_wrench();
            r.step(Some(w), 1e-4);
            assert!(r.time_s() < 10.0, "never left the find phase");
        }
        let after = r.face_error_rad().to_degrees();
        assert!(after.abs() <= within_deg, "{part_frame:?}: {after}°");
        if part_frame == PartFrame::Unknown {
            assert!((before - r.initial_errors().1).abs() < 1e-12, "{before}");
        }
    }
}

/// Without force data the controller stands still and the wrist (on either drive) holds
/// its pose.
#[test]
fn without_force_data_the_wrist_holds() {
    for drive in [Drive::Ideal, Drive::Arm] {
        let o = InsertionOptions {
            drive,
            ..InsertionOptions::default()
        };
        let mut r = InsertionRig::new(&o, 1).unwrap();
        let before = r.target();
        for _ in 0..5000 {
            r.step(None, 1e-4);
        }
        assert_eq!(r.target(), before);
        assert_eq!(r.phase(), Phase::Approach);
        let tip = r.truth().pose;
        assert!((tip[1] - before[1]).abs() < 1e-6, "{tip:?} vs {before:?}");
    }
}

/// A peg that enters the bore without a touch (its errors inside the clearance: seed 401
/// on the arm) is inserted to depth, not driven on at the approach speed until the hole's
/// bottom stops it 5 mm further down.
#[test]
fn a_peg_that_drops_in_untouched_stops_at_depth() {
    for drive in [Drive::Ideal, Drive::Arm] {
        let o = InsertionOptions {
            lateral_mm: Some(0.0),
            angle_deg: Some(0.0),
            drive,
            ..InsertionOptions::default()
        };
        let mut rig = InsertionRig::new(&o, 1).unwrap();
        let mut deepest = 0.0f64;
        while rig.time_s() < o.time_limit_s {
            rig.step(Some(rig.sensor_wrench()), 1e-4);
            deepest = deepest.max(rig.truth().depth_m);
        }
        assert_eq!(rig.phase(), Phase::Done, "{drive:?}");
        assert!(!rig.failed());
        let target = ControllerParams::default().target_depth_m;
        assert!(deepest < target + 0.5e-3, "{drive:?}: {deepest} m");
    }
}

/// At the tightest fit (c = 0.0005, wedging angle 0.1°) a peg tilted 1.4° goes in: the
/// alignment starts as the tip face's higher corner enters the bore, before the two-point
/// contact can form (0.2 mm in at that tilt). By the tip's centre 0.5 mm below the chamfer
/// it wedged there, as seeds 6, 7 and 8 of the sweep did.
#[test]
fn a_tilted_peg_is_aligned_before_it_can_wedge_in_a_tight_fit() {
    let o = InsertionOptions {
        clearance_ratio: 0.0005,
        lateral_mm: Some(0.8),
        angle_deg: Some(1.4),
        ..InsertionOptions::default()
    };
    let mut rig = InsertionRig::new(&o, 1).unwrap();
    let mut wedged = 0;
    while !rig.finished() && rig.time_s() < o.time_limit_s {
        rig.step(Some(rig.sensor_wrench()), 1e-4);
        wedged += u32::from(rig.truth().state == ContactState::Wedged);
    }
    assert_eq!(
        rig.phase(),
        Phase::Done,
        "{:?}, {wedged} ticks wedged",
        rig.truth()
    );
    assert!(!rig.failed());
}

/// docs/insertion-mujoco.md, *Measured*: without the dither, the find phase's walk on MuJoCo's
/// face at seed 1 (the true wrench, no sensor noise) stalls at μ = 0.3: its lead at the tip
/// is capped at 1.5 μ F_find / k_x, the flange turned past the peg takes part of the pull off,
/// and F_x/F_y stays under MuJoCo's cone, whose static friction is its kinetic μ. At μ = 0.5
/// the same walk breaks away and the peg reaches the hole. Prints the figures the page quotes
/// (`cargo test -p afs-shared --features mujoco --lib no_dither -- --nocapture`).
#[cfg(feature = "mujoco")]
#[test]
fn no_dither_stalls_on_mujocos_face_at_mu_0_3_and_walks_at_0_5() {
    let mujoco = mujoco_world();
    let dt = 1e-4;
    for mu in [0.3, 0.5] {
        let o = InsertionOptions {
            mu,
            method: Method::NoDither,
            ..InsertionOptions::default()
        };
        let mut rig = InsertionRig::on_world(&o, 1, &mujoco, dt).unwrap();
        while rig.time_s() < 5.0 && rig.phase() != Phase::Align {
            rig.step(Some(rig.sensor_wrench()), dt);
        }
        let w = rig.sensor_wrench();
        let ratio = w.force.x.abs() / w.force.y;
        let turn = (rig.target()[2] - rig.truth().pose[2]).to_degrees();
        println!(
            "mu {mu}: {:?} at {:.3} s, F_x {:.3} N, F_y {:.3} N, F_x/F_y {ratio:.3}, \
             flange turned {turn:.3} deg past the peg",
            rig.phase(),
            rig.time_s(),
            w.force.x,
            w.force.y,
        );
        if mu < 0.4 {
            assert_eq!(
                rig.phase(),
                Phase::Find,
                "the walk did not stall at μ = {mu}"
            );
            assert!(
                ratio < mu && ratio > 0.9 * mu,
                "F_x/F_y {ratio} at μ = {mu}"
            );
        } else {
            assert_eq!(rig.phase(), Phase::Align, "the walk stalled at μ = {mu}");
        }
    }
}

/// The wrist's stiffness is a setting (the holding compliance, docs/insertion.md *The
/// wrist's stiffness*): it reaches the plant's wrist and the controller's gains, k_θ scales
/// with it unless set, and a stiffness that is not a positive number is refused by name.
#[test]
fn the_wrist_stiffness_is_a_setting_the_rig_uses() {
    let o = InsertionOptions {
        wrist_stiffness_n_per_m: 2e4,
        ..InsertionOptions::default()
    };
    assert_eq!(o.peg_params().wrist_stiffness, [2e4, 2e4, 50.0]);
    let set = InsertionOptions {
        wrist_rotational_stiffness_nm_per_rad: Some(7.0),
        ..o
    };
    assert_eq!(set.peg_params().wrist_stiffness, [2e4, 2e4, 7.0]);
    // The rig runs on it: a stiffer wrist presses the peg onto the face with the same
    // commanded force but less deflection, so the first second differs from the default's.
    let run = |o: &InsertionOptions| {
        let mut rig = InsertionRig::new(o, 1).unwrap();
        while rig.time_s() < 0.6 {
            let w = rig.sensor_wrench();
            rig.step(Some(w), 1e-4);
        }
        rig.truth().pose
    };
    assert_ne!(run(&o), run(&InsertionOptions::default()));
    for bad in [0.0, -1.0, f64::NAN, 1e9] {
        let o = InsertionOptions {
            wrist_stiffness_n_per_m: bad,
            ..InsertionOptions::default()
        };
        let e = o.validate().unwrap_err().to_string();
        assert!(e.contains("insertion.wrist_stiffness_n_per_m"), "{e}");
        let o = InsertionOptions {
            wrist_rotational_stiffness_nm_per_rad: Some(bad),
            ..InsertionOptions::default()
        };
        assert!(o.validate().is_err(), "k_θ = {bad} was accepted");
    }
}

/// A stiff holding compliance (100 kN/m) still inserts in the time allowed: below half the
/// insertion force the commanded pose goes down at least at the speed limit, where the force
/// loop alone moves a free peg at ω F/k = 1.6 mm/s (docs/insertion.md, *The wrist's
/// stiffness*). Without that floor no seed of 100 inserted.
#[test]
fn a_stiff_wrist_inserts_in_the_time_allowed() {
    use crate::experiments::{Options, insertion};
    for seed in 1..=3 {
        let o = Options {
            seed,
            insertion: InsertionOptions {
                wrist_stiffness_n_per_m: 1e5,
                ..InsertionOptions::default()
            },
            ..Options::default()
        };
        let out = insertion(&o).unwrap();
        let inserted = crate::check::find(&out.checks, "inserted").unwrap();
        assert!(inserted.pass, "seed {seed}: {}", inserted.line());
    }
}
