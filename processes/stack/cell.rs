//! The simulated robot cell as a process of the graph (issue 48, docs/franka-cell.md, *The cell*):
//! a process named `cell` in a stack with a `[robot]` table is the robot itself
//! (`examples/python/fr3_cell.py`), started by the supervisor with the part it must build,
//! written to `cell.toml` in the run's directory: the scenario's surface placed where the tool
//! starts (`afs_shared::cell`), traced in the robot's base frame.

use super::StackFile;
use afs_shared::cell::{span, surface_through, trace};
use afs_shared::math::Vec2;
use afs_shared::scenario::Scenario;
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// The name of the process that is the simulated robot.
pub const CELL_PROCESS: &str = "cell";

/// The spacing of the traced surface's points (m): a sinusoid of fig. 5.6 turns by under 0.5°
/// between two of them.
pub const TRACE_STEP_M: f64 = 1e-3;

impl StackFile {
    /// Whether the graph starts the robot itself (a process named [`CELL_PROCESS`]).
    #[must_use]
    pub fn has_cell(&self) -> bool {
        self.robot.is_some() && self.process.iter().any(|p| p.name == CELL_PROCESS)
    }
}

/// Writes `dir/cell.toml` for the cell of `stack` running `scenario`, if the graph has one.
///
/// # Errors
/// The table does not give a plane, or the file cannot be written.
pub fn write(stack: &StackFile, scenario: &Scenario, dir: &Path) -> Result<Option<PathBuf>> {
    let Some(robot) = stack.robot.as_ref().filter(|_| stack.has_cell()) else {
        return Ok(None);
    };
    let plane = robot.plane()?;
    let surface = surface_through(&scenario.cfg, Vec2::zeros());
    let (u0, u1) = span(scenario);
    let points = trace(&surface, &plane, u0, u1, TRACE_STEP_M);
    let t = &robot.tool.flange_to_tip;
    let tool_length = (t[12] * t[12] + t[13] * t[13] + t[14] * t[14]).sqrt();
    let normal = plane.rotation().column(2);
    let mut text = String::from(
        "# The cell's part, written by `afs run` (docs/franka-cell.md, *The cell*): the surface the\n\
         # tool tip's centre meets, in the robot's base frame (m), in increasing u, the material\n\
         # on the right of the direction of travel about the plane's normal.\n",
    );
    text += &format!(
        "plane_normal = [{}, {}, {}]\ntool_length_m = {tool_length}\nsurface_m = [\n",
        normal[0], normal[1], normal[2]
    );
    for p in &points {
        text += &format!("  [{}, {}, {}],\n", p[0], p[1], p[2]);
    }
    text += "]\n";
    let f = dir.join("cell.toml");
    std::fs::write(&f, text).with_context(|| format!("writing {}", f.display()))?;
    Ok(Some(f))
}
