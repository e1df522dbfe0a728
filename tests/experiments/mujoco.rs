//! The experiments on MuJoCo as the world (docs/mujoco.md), in lockstep: tracking and friction
//! suppression at 10 kHz, 1 kHz and 500 Hz, friction identification, §5.4's box, the peg, the
//! first touch, a user's own arm, and models refused by name. CPU only, so they run beside the
//! stack tests (.ci/test); the stacks on MuJoCo are tests/mujoco.rs.

use super::afs;
use super::common::{assert_refused, user_arm};
use afs_shared::check::{self, Check};
use afs_shared::config::SimConfig;
use afs_shared::experiments::{self, Options};
use afs_shared::insertion::drive::Drive;
use afs_shared::setups::{ROBOT_RATES_HZ, set_rate};
use afs_shared::world::WorldKind;

fn options(kind: WorldKind, rate_hz: f64) -> Options {
    let mut base = SimConfig::default();
    base.world.kind = kind;
    set_rate(&mut base, rate_hz).unwrap();
    Options {
        base,
        ..Default::default()
    }
}

fn passed(checks: &[Check], id: &str, what: &str) {
    let c = check::find(checks, id).unwrap_or_else(|| panic!("{what}: no check {id}"));
    assert!(c.pass, "{what}: {}", c.line());
}

/// fig. 5.6 (an unknown sinusoid tracked with the tangent estimator) passes every check, and
/// fig. 4.5's dither keeps the mean friction under 20 % of the undithered one, on both worlds
/// at 10 kHz, 1 kHz and 500 Hz. (fig. 4.5's comparison with eq. 4.5's cycle average is the
/// built-in law's; MuJoCo's differs, docs/mujoco.md.)
#[test]
fn tracking_and_suppression_hold_on_both_worlds_at_every_rate() {
    for kind in [WorldKind::Builtin, WorldKind::Mujoco] {
        for rate in ROBOT_RATES_HZ {
            let what = format!("{} at {rate} Hz", kind.name());
            let opts = options(kind, rate);
            let tracked = experiments::fig5_6(&opts).unwrap();
            for c in &tracked.checks {
                assert!(c.pass, "fig5.6 {what}: {}", c.line());
            }
            let suppressed = experiments::fig4_5(&opts).unwrap();
            passed(
                &suppressed.checks,
                "dithered_over_undithered_friction",
                &format!("fig4.5 {what}"),
            );
        }
    }
}

/// The MuJoCo world's contact is the set-up's: a friction coefficient from trials within 3 %
/// of MuJoCo's μ (fig. 4.6), whatever the rate.
#[test]
fn friction_coefficient_from_trials_on_mujoco() {
    for rate in [10_000.0, 500.0] {
        let out = experiments::fig4_6(&options(WorldKind::Mujoco, rate)).unwrap();
        for c in &out.checks {
            assert!(c.pass, "fig4.6 mujoco at {rate} Hz: {}", c.line());
        }
    }
}

/// §5.4's box in MuJoCo (fig. 5.9): rotated into the corner about the rotation centre its
/// dithers estimate, every check passes; an arm model is refused for it (exit 2).
#[test]
fn the_box_finds_its_rotation_centre_on_mujoco() {
    let out = experiments::fig5_9(&options(WorldKind::Mujoco, 10_000.0)).unwrap();
    for c in &out.checks {
        assert!(c.pass, "fig5.9 mujoco: {}", c.line());
    }
    let refused = afs()
        .args(["experiment", "fig5.9", "--mjcf"])
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/examples/mujoco/user-arm.xml"
        ))
        .output()
        .unwrap();
    assert_refused(&refused, &"fig5.9 --mjcf", "§5.4's box has no arm");
}

/// The insertion on MuJoCo's peg and hole (docs/insertion-mujoco.md): from seed 1's errors the
/// peg goes in on both drives with every check passing, and the report names MuJoCo; a model
/// of the user's own is refused for it (exit 2).
#[test]
fn the_peg_goes_in_on_mujoco() {
    for drive in [Drive::Ideal, Drive::Arm] {
        let mut opts = options(WorldKind::Mujoco, 10_000.0);
        opts.insertion.drive = drive;
        let out = experiments::insertion(&opts).unwrap();
        assert_eq!(out.summary.world, "mujoco");
        for c in &out.checks {
            assert!(
                c.pass,
                "insertion on mujoco, {}: {}",
                drive.name(),
                c.line()
            );
        }
    }
    let refused = afs()
        .args(["experiment", "insertion", "--mjcf"])
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/examples/mujoco/user-arm.xml"
        ))
        .output()
        .unwrap();
    assert_refused(
        &refused,
        &"insertion --mjcf",
        "afs's generated peg and hole",
    );
}

/// A user's own arm (examples/mujoco/user-arm.xml: links of 0.45 m and 0.26 m, other masses):
/// afs reads its kinematics and mass matrix from the model and tracks fig. 5.6's sinusoid with
/// it (`afs experiment fig5.6 --mjcf`); tests/mujoco.rs runs the stack on it.
#[test]
fn a_users_arm_tracks_the_sinusoid() {
    let dir = std::env::temp_dir().join(format!("afs-user-arm-exp-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let model = dir.join("arm.xml");
    std::fs::write(&model, user_arm()).unwrap();
    let out = afs()
        .args(["experiment", "fig5.6", "--json", "--mjcf"])
        .arg(&model)
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The first touch on MuJoCo (docs/contact.md, *First touch*): from 1 mm off the surface the
/// servo's guarded approach touches a lighter user's arm with MuJoCo's default contact
/// (examples/mujoco/user-arm-default-contact.xml, whose contact the fit reads as about
/// 1.8e5 N/m) and the generated model's 1 MN/m contact, peaking under twice the preload, with no
/// bounce and the preload settled.
#[test]
fn the_first_touch_holds_on_mujocos_default_contact() {
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/mujoco/user-arm-default-contact.xml"
    );
    let mut users = options(WorldKind::Mujoco, 10_000.0);
    users.base.world.mjcf = Some(model.into());
    let mut steel = options(WorldKind::Mujoco, 10_000.0);
    steel.base.plant.contact.interaction_stiffness_n_per_m = 1e6;
    for (what, o) in [("the user's arm", users), ("1 MN/m", steel)] {
        let out = experiments::touch(&o).unwrap();
        for id in [
            "peak_over_preload",
            "ticks_without_contact_after_touch",
            "final_force_error",
            "tracking",
        ] {
            passed(&out.checks, id, what);
        }
        assert!(out.summary.stiffness_in_use_n_per_m > 5e4, "{what}");
    }
}

/// A model that lacks what afs needs is refused before anything runs, exit 2, with what is
/// missing named.
#[test]
fn a_model_without_what_afs_needs_is_refused_by_name() {
    let good = user_arm();
    let dir = std::env::temp_dir().join(format!("afs-bad-arm-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (broken, needle) in [
        (good.replace("<site name=\"tool\"", "<site name=\"tip_site\""), "site named `tool`"),
        (good.replace("<body name=\"surface\"", "<body name=\"table\""), "body named `surface`"),
        (good.replace(" mocap=\"true\"", ""), "not a mocap body"),
        (
            good.replace("damping=\"0.02\"", "damping=\"0.02\" armature=\"0.01\""),
            "joint armature",
        ),
        (
            good.replace(
                "<site name=\"tool\" pos=\"0.26 0 0\"/>",
                "<site name=\"tool\" pos=\"0.26 0 0\"/><body name=\"finger\"><joint type=\"hinge\" axis=\"0 0 1\"/><inertial pos=\"0 0 0\" mass=\"0.1\" diaginertia=\"1e-4 1e-4 1e-4\"/></body>",
            ),
            "exactly two hinge joints",
        ),
        (
            good.replace(
                "<body name=\"surface\" mocap=\"true\">",
                "<body name=\"m1\" mocap=\"true\"/><body name=\"m2\" mocap=\"true\"/>\
                 <body name=\"m3\" mocap=\"true\"/><body name=\"surface\" mocap=\"true\">",
            ),
            "resumable state has",
        ),
        ("<mujoco><worldbody>".to_string(), "not loaded"),
    ] {
        let model = dir.join("arm.xml");
        std::fs::write(&model, &broken).unwrap();
        let out = afs()
            .args(["experiment", "fig5.6", "--mjcf"])
            .arg(&model)
            .output()
            .unwrap();
        assert_refused(&out, &needle, needle);
        assert_eq!(out.status.code(), Some(2), "{needle}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
