//! afs::stack::robot

use afs::stack::robot::*;
use nalgebra::Matrix3;

fn table() -> RobotTable {
    toml::from_str(
        r#"
        kind = "franka"
        address = "172.16.0.2"
        [task_frame]
        origin_m = [0.45, 0.0, 0.2]
        x_axis = [1.0, 0.0, 0.0]
        normal = [0.0, 0.0, 1.0]
        [tool]
        flange_to_tip = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0.1034, 1]
        mass_kg = 0.7
        "#,
    )
    .expect("the table parses")
}

fn refused(edit: impl FnOnce(&mut RobotTable)) -> String {
    let mut t = table();
    edit(&mut t);
    t.check().expect_err("refused").to_string()
}

#[test]
fn a_good_table_passes_and_gives_its_plane() {
    let t = table();
    t.check().unwrap();
    let p = t.plane().unwrap();
    assert_eq!(*p.rotation(), Matrix3::identity());
    for address in ["172.16.0.2:1337", "fr3.lab", "robot-1", "[::1]:1337", "::1"] {
        check_address(address).unwrap_or_else(|e| panic!("{address}: {e}"));
    }
}

type Edit = Box<dyn FnOnce(&mut RobotTable)>;

#[test]
fn each_bad_entry_is_named() {
    let cases: Vec<(Edit, &str)> = vec![
        (
            Box::new(|t| t.kind = "ur5".into()),
            "the only kind is \"franka\"",
        ),
        (
            Box::new(|t| t.address = "a b".into()),
            "address = \"a b\" is not a host",
        ),
        (Box::new(|t| t.address = "fr3:0".into()), "is not a host"),
        (
            Box::new(|t| t.address = "fr3:99999".into()),
            "is not a host",
        ),
        (
            Box::new(|t| t.task_frame.x_axis = [1.0, 0.1, 0.0]),
            "x_axis = [1.0, 0.1, 0.0] must be a unit vector",
        ),
        (
            Box::new(|t| t.task_frame.normal = [1.0, 0.0, 0.0]),
            "at right angles",
        ),
        (
            Box::new(|t| t.task_frame.normal = [0.0, 0.0, f64::NAN]),
            "normal",
        ),
        (
            Box::new(|t| t.task_frame.tool_mount[2][2] = 1.0),
            "the tool's mount is not a rotation",
        ),
        (
            Box::new(|t| t.task_frame.origin_m = [1.2, 0.0, 0.2]),
            "out of its 0.855 m reach",
        ),
        (
            Box::new(|t| t.tool.flange_to_tip[0] = 1.1),
            "flange_to_tip is not a rigid transform",
        ),
        (
            Box::new(|t| t.tool.flange_to_tip[10] = -1.0),
            "not a rigid transform",
        ),
        (
            Box::new(|t| t.tool.flange_to_tip[3] = 0.2),
            "last row is [0.2, 0.0, 0.0, 1.0]",
        ),
        (
            Box::new(|t| t.tool.flange_to_tip[14] = 2.0),
            "within 0.5 m of the flange",
        ),
        (Box::new(|t| t.tool.mass_kg = 4.0), "payload, 3 kg"),
        (
            Box::new(|t| t.limits.contact_force_n = 0.0),
            "contact_force_n = 0",
        ),
        (
            Box::new(|t| t.limits.workspace_m[2] = [0.1, -0.1]),
            "normal range [0.1, -0.1]",
        ),
    ];
    for (edit, want) in cases {
        let e = refused(edit);
        assert!(e.contains(want), "wanted {want:?} in: {e}");
    }
}

/// The workspace box within reach: the good table's and the FR3 cell's (examples/
/// stack-franka.toml) pass; a plane 0.25 m farther out, still within the datasheet's reach of
/// its origin, is refused at its far corner, with how far short the arm came; so is the
/// cell's plane with its box widened to the defaults (±0.15 m: the tool pointing down, 0.7 m
/// out, the arm is 26 mm short).
#[test]
fn a_workspace_out_of_the_arms_reach_is_refused_at_its_corner() {
    let t = table();
    t.check_reach().unwrap();
    let cell = read(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/stack-franka.toml"
    )))
    .unwrap();
    cell.check_reach().unwrap();

    let mut far = table();
    far.task_frame.origin_m = [0.70, 0.0, 0.2];
    far.check().unwrap();
    let e = far.check_reach().unwrap_err().to_string();
    assert!(
        e.contains("[robot.task_frame] the FR3 cannot put the tool at x = 0.15 m")
            && e.contains("a corner of [robot.limits] workspace_m")
            && e.contains("mm and")
            && e.contains("move origin_m towards the robot"),
        "{e}"
    );

    let mut wide = cell;
    wide.limits.workspace_m = [[-0.15, 0.15], [-0.15, 0.15], [-0.05, 0.05]];
    let e = wide.check_reach().unwrap_err().to_string();
    assert!(e.contains("x = 0.15 m, y = -0.15 m"), "{e}");
}
