//! A stack file's `[robot]` table (issue 48, docs/franka.md): the arm the servo will drive
//! over FCI, the thesis's plane in its base frame, the tool on its flange and the limits.
//! Checked when the file is read, each bad entry named in one line; the servo board reads it
//! again from the file the supervisor writes ([`read`]).

use afs_shared::reach::{fr3_limits, fr3_starts, reach};
use afs_shared::robot_guard::{Guard, GuardLimits};
use afs_shared::task_plane::{FrameError, Joints, TaskPlane, check_rotation};
use anyhow::{Result, anyhow, bail};
use franka::model::Model;
use nalgebra::{Matrix3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// The `[robot]` table.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RobotTable {
    /// The arm: `"franka"` (an FR3 over FCI, server version 10).
    pub kind: String,
    /// The robot's FCI address: an IP address or host name, with `:port` if not 1337.
    pub address: String,
    /// The thesis's plane in the robot's base frame.
    pub task_frame: TaskFrame,
    /// The tool on the flange.
    pub tool: Tool,
    /// Where the servo holds instead of going on.
    #[serde(default)]
    pub limits: Limits,
}

/// The task plane: its origin, its x axis and its normal in the robot's base frame (the y
/// axis is `normal × x`), and the tool's orientation in it at θ = 0.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TaskFrame {
    /// The plane's origin (m).
    pub origin_m: [f64; 3],
    /// The plane's x axis (a unit vector).
    pub x_axis: [f64; 3],
    /// The plane's normal (a unit vector, at right angles to the x axis).
    pub normal: [f64; 3],
    /// The tool's orientation in the plane's frame at θ = 0, row by row (default: the tool's
    /// z axis against the normal, as a flange pointing down onto a table: `Rx(π)`).
    #[serde(default = "pointing_into_the_plane")]
    pub tool_mount: [[f64; 3]; 3],
}

fn pointing_into_the_plane() -> [[f64; 3]; 3] {
    [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]
}

/// The tool: flange to tool tip as a homogeneous transform, column-major as libfranka's
/// `F_T_EE`, and its mass.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Tool {
    /// The 4×4 transform from the flange to the tool tip, column by column (m).
    pub flange_to_tip: [f64; 16],
    /// The tool's mass, the force sensor's included (kg).
    pub mass_kg: f64,
}

/// The limits that end in a hold.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Limits {
    /// The largest contact force the servo lets through before it holds (N).
    pub contact_force_n: f64,
    /// The workspace box in the plane: x, y and the normal offset, each `[low, high]` (m).
    pub workspace_m: [[f64; 2]; 3],
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            contact_force_n: 30.0,
            workspace_m: [[-0.15, 0.15], [-0.15, 0.15], [-0.05, 0.05]],
        }
    }
}

/// The FR3's payload (kg), Franka's datasheet.
pub const FR3_PAYLOAD_KG: f64 = 3.0;
/// The FR3's reach from its shoulder (m), Franka's datasheet: joint 2's axis is 0.333 m above
/// the base, and no point farther than this from it can be the tool's.
pub const FR3_REACH_M: f64 = 0.855;
const FR3_SHOULDER_M: [f64; 3] = [0.0, 0.0, 0.333];

impl RobotTable {
    /// Checks the table; each error names the entry and says what to give.
    ///
    /// # Errors
    /// The first bad entry.
    pub fn check(&self) -> Result<()> {
        if self.kind != "franka" {
            bail!(
                "[robot] kind = \"{}\": the only kind is \"franka\" (an FR3 over FCI)",
                self.kind
            );
        }
        check_address(&self.address)?;
        self.plane()?;
        let origin = Vector3::from(self.task_frame.origin_m);
        let shoulder = Vector3::from(FR3_SHOULDER_M);
        let reach = (origin - shoulder).norm();
        if reach > FR3_REACH_M {
            bail!(
                "[robot.task_frame] origin_m = {:?} is {reach:.3} m from the FR3's shoulder (0, 0, 0.333), out of its {FR3_REACH_M} m reach: put the plane within it",
                self.task_frame.origin_m
            );
        }
        self.check_tool()?;
        self.guard()?;
        Ok(())
    }

    /// The workspace box within the FR3's reach: its centre and its eight corners (x, y and
    /// the normal offset of `[robot.limits] workspace_m`, in the plane at θ = 0) are each a
    /// pose of the tool that the arm takes within its joint limits, by inverse kinematics on
    /// franka-rs's FR3 model with this tool ([`afs_shared::reach`]; docs/franka.md, *The task
    /// frame within reach*). Checked when a stack file is read, not by the servo, which reads
    /// the table again on every (re)start.
    ///
    /// # Errors
    /// The first point out of reach, with how far short the arm came.
    pub fn check_reach(&self) -> Result<()> {
        use crate::robot::{tool_jacobian, tool_pose};
        let plane = self.plane()?;
        let model = Model::from_urdf(franka::model::FR3_URDF)
            .map_err(|e| anyhow!("franka-rs's FR3 model does not load: {e}"))?;
        let tool = self.tool.flange_to_tip;
        let joints = |q: &Joints| -> [f64; 7] { std::array::from_fn(|i| q[i]) };
        let pose = |q: &Joints| tool_pose(&model, &joints(q), &tool);
        let jacobian = |q: &Joints| tool_jacobian(&model, &joints(q), &tool);
        let w = self.limits.workspace_m;
        let mut points = vec![w.map(|r| 0.5 * (r[0] + r[1]))];
        for x in w[0] {
            for y in w[1] {
                for z in w[2] {
                    points.push([x, y, z]);
                }
            }
        }
        let limits = fr3_limits();
        // The solution at the last point first: the box's poses lie close together.
        let mut starts = vec![fr3_starts()[0]];
        starts.extend(fr3_starts());
        for (k, [x, y, z]) in points.into_iter().enumerate() {
            let target = plane.pose(Vector2::new(x, y), 0.0, z);
            match reach(pose, jacobian, &target, &starts, &limits) {
                Ok(q) => starts[0] = q,
                Err(m) => bail!(
                    "[robot.task_frame] the FR3 cannot put the tool at x = {x} m, y = {y} m, {z} m off the plane, θ = 0 ({} of [robot.limits] workspace_m): it comes {m} within its joint limits; move origin_m towards the robot or shrink the workspace",
                    if k == 0 { "the centre" } else { "a corner" }
                ),
            }
        }
        Ok(())
    }

    /// The guard of `[robot.limits]`: the workspace box and the contact-force limit that end
    /// in a hold (docs/franka.md, *The guard*).
    ///
    /// # Errors
    /// A limit that is not a force above zero, or a range that is not low before high.
    pub fn guard(&self) -> Result<Guard> {
        let l = &self.limits;
        Guard::new(GuardLimits {
            contact_force_n: l.contact_force_n,
            workspace_m: l.workspace_m,
        })
        .map_err(|e| anyhow!("[robot.limits] {e}"))
    }

    /// The task plane, its axes checked.
    ///
    /// # Errors
    /// An axis that is not a unit vector, axes not at right angles, or a mount that is not a
    /// rotation.
    pub fn plane(&self) -> Result<TaskPlane> {
        let f = &self.task_frame;
        let x = Vector3::from(f.x_axis);
        let n = Vector3::from(f.normal);
        for (name, v) in [("x_axis", x), ("normal", n)] {
            if !(v.iter().all(|c| c.is_finite()) && (v.norm() - 1.0).abs() < 1e-6) {
                bail!(
                    "[robot.task_frame] {name} = {:?} must be a unit vector (its length is {})",
                    v.as_slice(),
                    v.norm()
                );
            }
        }
        if x.dot(&n).abs() > 1e-6 {
            bail!(
                "[robot.task_frame] x_axis and normal must be at right angles (x·n = {:.2e})",
                x.dot(&n)
            );
        }
        let r = Matrix3::from_columns(&[x, n.cross(&x), n]);
        let mount = Matrix3::from_fn(|i, j| f.tool_mount[i][j]);
        TaskPlane::new(r, Vector3::from(f.origin_m), mount)
            .map_err(|e: FrameError| anyhow::anyhow!("[robot.task_frame] {e}"))
    }

    fn check_tool(&self) -> Result<()> {
        let t = &self.tool.flange_to_tip;
        let rotation = Matrix3::from_fn(|i, j| t[j * 4 + i]);
        if let Err(e) = check_rotation(&rotation, "tool transform's rotation") {
            bail!("[robot.tool] flange_to_tip is not a rigid transform: {e}");
        }
        let last_row = [t[3], t[7], t[11], t[15]];
        if last_row != [0.0, 0.0, 0.0, 1.0] {
            bail!(
                "[robot.tool] flange_to_tip's last row is {last_row:?}, not [0, 0, 0, 1]: give the 4×4 transform column by column, as libfranka's F_T_EE"
            );
        }
        if !t[12..15].iter().all(|v| v.is_finite() && v.abs() <= 0.5) {
            bail!(
                "[robot.tool] flange_to_tip's translation {:?} must be within 0.5 m of the flange (m)",
                &t[12..15]
            );
        }
        let m = self.tool.mass_kg;
        if !(m.is_finite() && (0.0..=FR3_PAYLOAD_KG).contains(&m)) {
            bail!("[robot.tool] mass_kg = {m} must be 0 to the FR3's payload, {FR3_PAYLOAD_KG} kg");
        }
        Ok(())
    }
}

/// The `[robot]` table of the file at `path` (a stack file, or the table alone), checked.
///
/// # Errors
/// The file cannot be read, has no `[robot]` table, or the table does not check.
pub fn read(path: &std::path::Path) -> Result<RobotTable> {
    #[derive(Deserialize)]
    struct WithRobot {
        robot: Option<RobotTable>,
    }
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow!("reading the robot's table {}: {e}", path.display()))?;
    let file: WithRobot = toml::from_str(&text)
        .map_err(|e| anyhow!("parsing the robot's table {}: {e}", path.display()))?;
    let table = file
        .robot
        .ok_or_else(|| anyhow!("{} has no [robot] table", path.display()))?;
    table.check()?;
    Ok(table)
}

/// An FCI address: a host (an IP address or a name) with an optional `:port` (1 to 65535).
#[doc(hidden)]
pub fn check_address(address: &str) -> Result<()> {
    let bad = || {
        anyhow::anyhow!(
            "[robot] address = \"{address}\" is not a host: give the robot's IP address or name, with :port if not 1337"
        )
    };
    if address.parse::<std::net::SocketAddr>().is_ok()
        || address.parse::<std::net::IpAddr>().is_ok()
    {
        return Ok(());
    }
    let (host, port) = match address.rsplit_once(':') {
        Some((h, p)) => (h, Some(p)),
        None => (address, None),
    };
    if let Some(p) = port
        && !p.parse::<u16>().is_ok_and(|p| p > 0)
    {
        return Err(bad());
    }
    let label_ok = |l: &str| {
        !l.is_empty()
            && l.len() <= 63
            && l.chars().all(|c| c.is_ascii_alphanumeric() || c == '-')
            && !l.starts_with('-')
            && !l.ends_with('-')
    };
    if host.is_empty() || host.len() > 253 || !host.split('.').all(label_ok) {
        return Err(bad());
    }
    Ok(())
}
