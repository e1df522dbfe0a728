//! MuJoCo as the world (docs/mujoco.md), across processes: the stack runs on MuJoCo against its
//! MuJoCo lockstep and a killed servo resumes MuJoCo's full state, so the agreement holds
//! across the kill; a user's own arm tracks in the stack; `afs bench world`'s smoke run. The
//! lockstep experiments on MuJoCo (tracking and suppression at every rate, the peg, the box,
//! the first touch) are tests/experiments/mujoco.rs: CPU only, they run beside these.
#![cfg(feature = "mujoco")]

use std::time::Duration;

mod common;
use common::*;

/// `afs run --config examples/stack-mujoco.toml`: the servo steps MuJoCo, the supervisor's
/// reference runs the same MuJoCo model in lockstep; the servo is killed mid-run and its
/// successor resumes MuJoCo's state (warm start included), so every tick arrives once and
/// the agreement check holds.
#[test]
fn the_stack_runs_on_mujoco_and_a_killed_servo_resumes_it() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("mj");
    let _clean = CleanPrefix(p.clone());
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/stack-mujoco.toml");
    let run = start_run(&p, &["--config", config, "--duration", "8"]);
    wait_running(&p, Duration::from_secs(60));
    std::thread::sleep(Duration::from_secs(2));
    kill_board_and_wait_restart(&p, "servo");
    let r = finish_passed(run.take(), "afs run");
    assert_eq!(process(&r, "servo").restarts, 1);
    assert_eq!(r.samples.plant_received, 80_001, "{:?}", r.samples);
    assert_eq!(r.samples.plant_lost, 0);
    assert!(check(&r, "lockstep_agreement").pass, "{:#?}", r.agreement);
    assert!(check(&r, "ticks_without_contact").pass);
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// A user's own arm (examples/mujoco/user-arm.xml: links of 0.45 m and 0.26 m, other masses):
/// the stack's surface tracking on the flat surface against its lockstep (its fig. 5.6 is
/// tests/experiments/mujoco.rs).
#[test]
fn a_users_arm_tracks_the_flat_surface() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = std::env::temp_dir().join(format!("afs-user-arm-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let model = dir.join("arm.xml");
    std::fs::write(&model, user_arm()).unwrap();
    let p = prefix("mjuser");
    let _clean = CleanPrefix(p.clone());
    // examples/stack.toml with the user's model as the world.
    let stack = stack_file(
        &dir,
        &format!(
            "[sim.world]\nkind = \"mujoco\"\nmjcf = {:?}\n",
            model.display().to_string()
        ),
    );
    let run = start_run(
        &p,
        &["--config", stack.to_str().unwrap(), "--duration", "5"],
    );
    let r = finish_passed(run.take(), "afs run");
    assert!(check(&r, "lockstep_agreement").pass, "{:#?}", r.agreement);
    assert!(check(&r, "ticks_without_contact").pass);
    assert!(r.stack.tracking.tangent_error_rms_deg < 1.0);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `afs bench world --duration 1`: a smoke run of the world part (its shape, not its speed):
/// both worlds' step series, both stacks' wake series, the three targets, both stacks passed.
#[test]
fn bench_world_reports_both_worlds() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("bw");
    let out_dir = std::env::temp_dir().join(format!("afs-bench-world-{p}"));
    let out = afs()
        .args([
            "bench",
            "world",
            "--duration",
            "1",
            "--json",
            "--prefix",
            &p,
            "--out",
        ])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: afs::tools::bench::BenchReport = serde_json::from_slice(&out.stdout).unwrap();
    let w = r.world.expect("the world part");
    for s in [
        "step_builtin",
        "step_mujoco",
        "servo_wake_builtin",
        "servo_wake_mujoco",
    ] {
        let q = w.part.series[s].summary_us.quantiles;
        assert!(q.p50 > 0.0 && q.p50 <= q.p99, "{s}: {q:?}");
    }
    let ids: Vec<&str> = w.part.targets.iter().map(|c| c.id.as_str()).collect();
    assert_eq!(
        ids,
        [
            "mj_step_p99_us",
            "lockstep_realtime_factor_mujoco",
            "servo_wake_p99_mujoco_over_builtin"
        ]
    );
    assert!(w.lockstep_realtime_factor_mujoco > 0.0);
    assert_eq!(w.stacks_passed, [true, true]);
    let _ = std::fs::remove_dir_all(&out_dir);
}
