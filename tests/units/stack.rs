//! afs::stack

use afs::stack::*;
use afs_shared::config::SimConfig;
use std::path::{Path, PathBuf};

fn file(name: &str, text: &str) -> PathBuf {
    let f = std::env::temp_dir().join(format!("afs-setup-{}-{name}", std::process::id()));
    std::fs::write(&f, text).unwrap();
    f
}

/// One file for both: `afs experiment --config` reads a stack file's `[sim]` table (the
/// example without feedforward), a file without `[sim]` is the default set-up, and a
/// set-up table outside `[sim]` (the old bare format) is refused with the fix.
#[test]
fn an_experiment_reads_a_stack_files_set_up() {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/no-feedforward.toml");
    assert!(!setup_of(&example).unwrap().servo.inertia_feedforward);
    let stack = file("stack.toml", DEFAULT_STACK);
    assert_eq!(setup_of(&stack).unwrap(), SimConfig::default());
    let bare = file("bare.toml", "[servo]\ninertia_feedforward = false\n");
    let e = format!("{:#}", setup_of(&bare).unwrap_err());
    assert!(
        e.contains("`servo` belongs under [sim]") && e.contains("[sim.servo]"),
        "{e}"
    );
    let odd = file("odd.toml", "sim = 3\n");
    assert!(format!("{:#}", setup_of(&odd).unwrap_err()).contains("must be a table"));
    let typo = file("typo.toml", "[sim.servo]\ninertia_feedfoward = false\n");
    assert!(format!("{:#}", setup_of(&typo).unwrap_err()).contains("inertia_feedfoward"));
    for f in [stack, bare, odd, typo] {
        let _ = std::fs::remove_file(f);
    }
}

/// `--rate-hz`, `--plant` and `--mjcf` of `afs run` land on the keys of `[sim]` that
/// `afs experiment`'s flags set, beside what the stack file has there; a rate that is no
/// rate and a model that is not there are refused.
#[test]
fn the_run_flags_set_the_stack_files_set_up() {
    let model = file("arm.xml", "<mujoco/>");
    let mut sim: Option<toml::Table> = Some(toml::from_str("[servo]\nkp = 1.0\n").unwrap());
    SimOverrides {
        rate_hz: Some(1000.0),
        plant: None,
        mjcf: Some(model.clone()),
    }
    .apply(&mut sim)
    .unwrap();
    let sim = sim.unwrap();
    assert_eq!(sim["servo"]["rate_hz"].as_float(), Some(1000.0));
    assert_eq!(sim["servo"]["kp"].as_float(), Some(1.0));
    assert_eq!(sim["world"]["kind"].as_str(), Some("mujoco"));
    assert!(sim["world"]["mjcf"].as_str().unwrap().starts_with('/'));
    let mut none = None;
    SimOverrides {
        plant: Some("builtin".into()),
        ..Default::default()
    }
    .apply(&mut none)
    .unwrap();
    assert_eq!(none.unwrap()["world"]["kind"].as_str(), Some("builtin"));
    for bad in [
        SimOverrides {
            rate_hz: Some(0.0),
            ..Default::default()
        },
        SimOverrides {
            mjcf: Some("/nonexistent/arm.xml".into()),
            ..Default::default()
        },
    ] {
        assert!(bad.apply(&mut None).is_err(), "{bad:?}");
    }
    let _ = std::fs::remove_file(model);
}
