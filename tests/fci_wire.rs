//! The Franka Control Interface's wire as franka-rs declares it, checked against Franka's own
//! client: `examples/python/fci_wire_check.py` builds a stub FR3 from the layout these tests
//! take from franka-rs (struct sizes, every RobotState field's offset, the FR3's URDF) and runs
//! pylibfranka against it (docs/franka.md, *How the layouts were checked*).
//!
//! Skipped, saying why, when pylibfranka is not installed or the stub cannot bind its
//! loopback address. `AFS_FCI_LAYOUT_OUT=FILE` keeps the layout for running the script by hand.

use franka::wire::robot::{
    Command as FciCommand, ControllerCommand, MoveRequest, RobotCommand, RobotState,
    SetCollisionBehaviorRequest, SetLoadRequest,
};
use serde_json::{Value, json};
use std::mem::{offset_of, size_of};
use std::path::Path;
use std::process::Command;

/// `(name, offset, kind, count)` of each RobotState field pylibfranka can read back, in wire
/// order (the accelerometers, which it does not expose, are left out).
macro_rules! state_fields {
    ($($name:ident: $kind:literal x $count:expr),* $(,)?) => {
        vec![$(json!({
            "name": stringify!($name),
            "offset": offset_of!(RobotState, $name),
            "kind": $kind,
            "count": $count,
        })),*]
    };
}

/// A setter's request as the check script reads it: its command number, its size and
/// `(name, offset, count)` of each field (f64 arrays), in wire order.
macro_rules! setter {
    ($command:expr, $request:ty { $($name:ident: $count:expr),* $(,)? }) => {
        json!({
            "command": $command as u32,
            "size": size_of::<$request>(),
            "fields": [$(json!({
                "name": stringify!($name),
                "offset": offset_of!($request, $name),
                "count": $count,
            })),*],
        })
    };
}

/// franka-rs 0.4.0's FCI v10 layout, as the check script reads it.
fn franka_rs_layout() -> Value {
    let errors = franka::wire::robot::ERROR_COUNT;
    let state = state_fields![
        message_id: "u64" x 1, O_T_EE: "f32" x 16, O_T_EE_d: "f32" x 16, F_T_EE: "f32" x 16,
        EE_T_K: "f32" x 16, F_T_NE: "f32" x 16, NE_T_EE: "f32" x 16, m_ee: "f32" x 1,
        I_ee: "f32" x 9, F_x_Cee: "f32" x 3, m_load: "f32" x 1, I_load: "f32" x 9,
        F_x_Cload: "f32" x 3, elbow: "f32" x 2, elbow_d: "f32" x 2, tau_J: "f32" x 7,
        tau_J_d: "f32" x 7, dtau_J: "f32" x 7, q: "f32" x 7, q_d: "f32" x 7, dq: "f32" x 7,
        dq_d: "f32" x 7, ddq_d: "f32" x 7, joint_contact: "f32" x 7,
        cartesian_contact: "f32" x 6, joint_collision: "f32" x 7,
        cartesian_collision: "f32" x 6, tau_ext_hat_filtered: "f32" x 7,
        O_F_ext_hat_K: "f32" x 6, K_F_ext_hat_K: "f32" x 6, O_dP_EE_d: "f32" x 6,
        O_ddP_O: "f32" x 3, elbow_c: "f32" x 2, delbow_c: "f32" x 2, ddelbow_c: "f32" x 2,
        O_T_EE_c: "f32" x 16, O_dP_EE_c: "f32" x 6, O_ddP_EE_c: "f32" x 6, theta: "f32" x 7,
        dtheta: "f32" x 7, motion_generator_mode: "u8" x 1, controller_mode: "u8" x 1,
        errors: "u8" x errors, reflex_reason: "u8" x errors, robot_mode: "u8" x 1,
        control_command_success_rate: "f32" x 1,
    ];
    let control = offset_of!(RobotCommand, control);
    json!({
        "state_size": size_of::<RobotState>(),
        "command_size": size_of::<RobotCommand>(),
        "move_size": size_of::<MoveRequest>(),
        "tau_offset": control + offset_of!(ControllerCommand, tau_J_d),
        "finished_offset": control + offset_of!(ControllerCommand, torque_command_finished),
        "urdf": franka::model::FR3_URDF,
        "state": state,
        "setters": {
            "collision": setter!(FciCommand::SetCollisionBehavior, SetCollisionBehaviorRequest {
                lower_torque_thresholds_acceleration: 7, upper_torque_thresholds_acceleration: 7,
                lower_torque_thresholds_nominal: 7, upper_torque_thresholds_nominal: 7,
                lower_force_thresholds_acceleration: 6, upper_force_thresholds_acceleration: 6,
                lower_force_thresholds_nominal: 6, upper_force_thresholds_nominal: 6,
            }),
            "load": setter!(FciCommand::SetLoad, SetLoadRequest {
                m_load: 1, F_x_Cload: 3, I_load: 9,
            }),
        },
    })
}

/// Runs the check on `layout` at the loopback `address`; None (with the reason printed) when
/// it skipped.
fn check(layout: &Value, address: &str, name: &str) -> Option<Value> {
    run_script(layout, address, name, &[])
}

/// Runs the check script with `extra` arguments; its JSON report, or None when it skipped.
fn run_script(layout: &Value, address: &str, name: &str, extra: &[String]) -> Option<Value> {
    let dir = std::env::temp_dir().join(format!("afs-fci-wire-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("layout.json");
    std::fs::write(&file, serde_json::to_vec(layout).unwrap()).unwrap();
    if let Ok(keep) = std::env::var("AFS_FCI_LAYOUT_OUT") {
        std::fs::copy(&file, keep).unwrap();
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/python/fci_wire_check.py");
    let out = Command::new("python3")
        .arg(script)
        .arg("--layout")
        .arg(&file)
        .args(["--address", address])
        .args(extra)
        .output()
        .expect("python3 is needed for this test");
    std::fs::remove_dir_all(&dir).unwrap();
    let report: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "the check printed no report ({e}): {}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    if let Some(why) = report["skipped"].as_str() {
        eprintln!("skipped: {why}");
        return None;
    }
    Some(report)
}

#[test]
fn franka_rs_speaks_the_wire_franka_s_own_client_speaks() {
    let Some(r) = check(&franka_rs_layout(), "127.0.0.61", "agrees") else {
        return;
    };
    for part in [
        "connect",
        "state",
        "move",
        "command",
        "error_recovery",
        "collision",
        "load",
    ] {
        assert_eq!(r[part]["agrees"], true, "{part}: {r:#}");
    }
    assert_eq!(r["connect"]["refusal_names_version_10"], true, "{r:#}");
    assert_eq!(r["state"]["fields_compared"], 40, "{r:#}");
    assert_eq!(r["command"]["tau_as_written"], 21, "{r:#}");
    assert_eq!(r["collision"]["fields_compared"], 8, "{r:#}");
    assert_eq!(r["load"]["fields_compared"], 3, "{r:#}");
    assert_eq!(r["agrees"], true);
}

#[test]
fn a_layout_off_by_one_field_is_caught() {
    let mut layout = franka_rs_layout();
    // tau_J_d one f64 earlier than franka-rs puts it, and q one f32 later: the torques no longer
    // arrive as written, and q no longer reads back.
    let tau = layout["tau_offset"].as_u64().unwrap();
    layout["tau_offset"] = json!(tau - 8);
    let q = layout["state"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .find(|f| f["name"] == "q")
        .unwrap();
    q["offset"] = json!(q["offset"].as_u64().unwrap() + 4);
    // The torque thresholds' upper and lower arrays swapped in SetCollisionBehavior.
    let fields = layout["setters"]["collision"]["fields"]
        .as_array_mut()
        .unwrap();
    let (lower, upper) = (fields[0]["offset"].clone(), fields[1]["offset"].clone());
    fields[0]["offset"] = upper;
    fields[1]["offset"] = lower;
    let Some(r) = check(&layout, "127.0.0.62", "off") else {
        return;
    };
    assert_eq!(r["command"]["agrees"], false, "{r:#}");
    assert_eq!(r["command"]["tau_as_written"], 0, "{r:#}");
    assert_eq!(r["state"]["agrees"], false, "{r:#}");
    assert!(
        r["state"]["mismatched"]
            .as_array()
            .unwrap()
            .iter()
            .any(|f| f == "q"),
        "{r:#}"
    );
    assert_eq!(r["collision"]["agrees"], false, "{r:#}");
    assert_eq!(
        r["collision"]["mismatched"],
        json!([
            "lower_torque_thresholds_acceleration",
            "upper_torque_thresholds_acceleration"
        ]),
        "{r:#}"
    );
    assert_eq!(r["agrees"], false);
}

/// The largest |a − b| over two equal-length slices.
fn max_difference(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The FR3's model afs will take its torques from, franka-rs's native one built from the URDF
/// the robot serves, is libfranka's: mass matrix, Coriolis vector, gravity and the end
/// effector's zero Jacobian, at three states (unloaded, identity tool frames), within 1e-6.
#[test]
fn franka_rs_s_fr3_model_is_libfranka_s() {
    use franka::model::{Frame, Model};
    let model = Model::from_urdf(franka::model::FR3_URDF).unwrap();
    let states: [[f64; 14]; 3] = [
        [
            0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785, 0.1, 0.2, -0.1, 0.3, 0.2, -0.2, 0.5,
        ],
        [
            0.5, 0.3, -0.4, -1.8, 0.6, 2.2, -0.9, -0.4, 0.7, 0.3, -0.5, 1.1, 0.9, -1.3,
        ],
        [
            -1.2, 1.1, 1.5, -0.6, -2.0, 3.5, 2.1, 1.0, -0.8, 0.6, 0.4, -1.5, 2.0, 0.8,
        ],
    ];
    for (i, state) in states.iter().enumerate() {
        let args: Vec<String> = std::iter::once("--model-at".to_string())
            .chain(state.iter().map(|x| x.to_string()))
            .collect();
        let Some(r) = run_script(
            &franka_rs_layout(),
            "127.0.0.63",
            &format!("model{i}"),
            &args,
        ) else {
            return;
        };
        assert!(r.get("exception").is_none(), "{r:#}");
        // The state went over the wire as f32: both models take what libfranka read.
        let q: [f64; 7] = floats(&r["q"]).try_into().unwrap();
        let dq: [f64; 7] = floats(&r["dq"]).try_into().unwrap();
        let gravity = [0.0, 0.0, f64::from(-9.81f32)];
        let identity = [
            1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ];
        let none = [0.0; 9];
        let origin = [0.0; 3];
        let ours = [
            ("mass", model.mass_q(&q, &none, 0.0, &origin).to_vec()),
            (
                "coriolis",
                model
                    .coriolis_q(&q, &dq, &none, 0.0, &origin, &gravity)
                    .to_vec(),
            ),
            (
                "gravity",
                model.gravity_q(&q, 0.0, &origin, &gravity).to_vec(),
            ),
            (
                "zero_jacobian_ee",
                model
                    .zero_jacobian_q(Frame::EndEffector, &q, &identity, &identity)
                    .to_vec(),
            ),
        ];
        for (name, value) in ours {
            let theirs = floats(&r[name]);
            let d = max_difference(&value, &theirs);
            assert!(
                d < 1e-6,
                "state {i}, {name}: differs by {d:e}\nfranka-rs {value:?}\nlibfranka {theirs:?}"
            );
        }
    }
}
