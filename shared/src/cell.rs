//! The robot cell's part in the robot's base frame (issue 48, docs/franka-cell.md, *The cell*): the
//! scenario's surface placed in the task plane where the tool starts, and traced as the points
//! the simulated cell builds its wall through.
//!
//! afs's surface is the locus of the tool tip's centre (a point tool, docs/model.md); a cell
//! with a round tip of radius r sinks its wall's face by r along the normal.

use crate::config::SimConfig;
use crate::math::{Vec2, perp, unit};
use crate::scenario::Scenario;
use crate::surface::{Shape, Surface};
use crate::task_plane::TaskPlane;

/// How far the cell's wall reaches before the scenario's start and past its end (m).
pub const MARGIN_M: f64 = 0.03;
/// A scenario without an end along the surface is given this much wall past its start (m).
pub const OPEN_TRAVERSE_M: f64 = 0.1;

/// The scenario's surface moved so that a tool at `tool_m` (in the plane) is where the
/// scenario starts it: `start_gap_m` off the surface along its normal at `start_u_m`, or,
/// with no gap, pressed in by the preload over the servo's stiffness estimate.
#[must_use]
pub fn surface_through(cfg: &SimConfig, tool_m: Vec2) -> Surface {
    let s = &cfg.surface;
    let u = cfg.start_u_m;
    let normal = perp(unit(s.tangent_angle_at(u)));
    let off = if cfg.start_gap_m > 0.0 {
        cfg.start_gap_m
    } else {
        -cfg.servo.hybrid.preload_n / cfg.servo.hybrid.stiffness_estimate_n_per_m
    };
    let shift = tool_m - normal * off - s.point_at(u);
    let mut moved = s.clone();
    moved.frame.origin_m = [s.frame.origin_m[0] + shift.x, s.frame.origin_m[1] + shift.y];
    moved
}

/// The span of surface coordinates `(u0, u1)` the cell builds for `scenario`: [`MARGIN_M`]
/// before its start to [`MARGIN_M`] past its end, or [`OPEN_TRAVERSE_M`] past its start.
#[must_use]
pub fn span(scenario: &Scenario) -> (f64, f64) {
    let start = scenario.cfg.start_u_m;
    let end = scenario
        .end_u_m
        .unwrap_or(start + OPEN_TRAVERSE_M)
        .max(start);
    (start - MARGIN_M, end + MARGIN_M)
}

/// The surface from `u0` to `u1` as points of the base frame at most `step_m` apart along u,
/// a polyline's vertices among them (so that its corners stay sharp), in increasing u: the
/// material lies on the right of the direction of travel, about the plane's normal.
#[must_use]
pub fn trace(surface: &Surface, plane: &TaskPlane, u0: f64, u1: f64, step_m: f64) -> Vec<[f64; 3]> {
    let n = ((u1 - u0) / step_m).ceil().max(1.0) as usize;
    let mut us: Vec<f64> = (0..=n)
        .map(|i| u0 + (u1 - u0) * i as f64 / n as f64)
        .collect();
    if let Shape::Polyline { vertices } = &surface.shape {
        us.extend(vertices.iter().map(|v| v[0]).filter(|u| *u > u0 && *u < u1));
        us.sort_by(f64::total_cmp);
        us.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    }
    us.iter()
        .map(|u| {
            let p = surface.point_at(*u);
            let (_, base) = plane.pose(p, 0.0, 0.0);
            [base.x, base.y, base.z]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::SurfaceFrame;
    use nalgebra::{Matrix3, Vector3};

    fn sinusoid() -> SimConfig {
        SimConfig {
            surface: Surface {
                frame: SurfaceFrame {
                    origin_m: [0.4, -0.01],
                    angle_rad: 0.3,
                },
                shape: Shape::Sinusoid {
                    amplitude_m: 0.003,
                    wavelength_m: 0.12,
                },
            },
            start_u_m: -0.06,
            ..SimConfig::default()
        }
    }

    /// With a gap, the tool ends up that far from the surface point at the start, along the
    /// normal there, on the open side: the surface's own contact test finds it free by the gap.
    #[test]
    fn the_tool_starts_the_gap_off_the_surface() {
        let mut cfg = sinusoid();
        cfg.start_gap_m = 0.002;
        let tool = Vec2::new(0.01, -0.02);
        let s = surface_through(&cfg, tool);
        let on = s.point_at(cfg.start_u_m);
        let normal = perp(unit(s.tangent_angle_at(cfg.start_u_m)));
        assert!((tool - on - normal * 0.002).norm() < 1e-12);
        assert!(s.contacts(tool).as_slice().is_empty());
        // The shape and its angle are the scenario's: only the origin moved.
        assert_eq!(s.shape, cfg.surface.shape);
        assert_eq!(s.frame.angle_rad, cfg.surface.frame.angle_rad);
    }

    /// Without a gap, the tool is pressed in by preload / k̂: the contact's depth.
    #[test]
    fn without_a_gap_the_tool_starts_pressed_in_by_the_preload() {
        let cfg = sinusoid();
        let tool = Vec2::new(0.0, 0.0);
        let s = surface_through(&cfg, tool);
        let depth = cfg.servo.hybrid.preload_n / cfg.servo.hybrid.stiffness_estimate_n_per_m;
        let contacts = s.contacts(tool);
        let c = contacts.as_slice();
        assert_eq!(c.len(), 1);
        assert!(
            (c[0].depth_m - depth).abs() < 1e-9,
            "{} vs {depth}",
            c[0].depth_m
        );
    }

    /// The trace lies on the surface, mapped through the plane: each point is the plane's
    /// pose of `point_at(u)`, at most a step apart, from u0 to u1, with a polyline's corner
    /// among them.
    #[test]
    fn the_trace_is_the_surface_in_the_base_frame() {
        let r = Matrix3::from_columns(&[
            Vector3::x(),
            Vector3::new(0.0, -1.0, 0.0),
            Vector3::new(0.0, 0.0, -1.0),
        ]);
        let plane = TaskPlane::new(r, Vector3::new(0.554, 0.0, 0.465), Matrix3::identity())
            .expect("a rotation");
        let cfg = sinusoid();
        let pts = trace(&cfg.surface, &plane, -0.09, 0.09, 1e-3);
        assert_eq!(pts.len(), 181);
        let p = cfg.surface.point_at(-0.09);
        let first = pts[0];
        assert!((first[0] - (0.554 + p.x)).abs() < 1e-12);
        assert!((first[1] + p.y).abs() < 1e-12);
        assert!((first[2] - 0.465).abs() < 1e-12);
        let corner = Surface {
            frame: SurfaceFrame {
                origin_m: [0.0, 0.0],
                angle_rad: 0.0,
            },
            shape: Shape::Polyline {
                vertices: vec![[0.0, 0.0], [0.01234, 0.0], [0.03, 0.01]],
            },
        };
        let pts = trace(&corner, &plane, 0.0, 0.03, 1e-3);
        assert!(
            pts.iter()
                .any(|p| (p[0] - 0.56634).abs() < 1e-12 && p[1].abs() < 1e-12),
            "the corner at u = 12.34 mm is a point of the trace"
        );
        for w in pts.windows(2) {
            assert!(w[1][0] > w[0][0] && w[1][0] - w[0][0] <= 1e-3 + 1e-12);
        }
    }
}
