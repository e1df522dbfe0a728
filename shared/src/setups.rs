//! Set-ups the scenarios and the experiments share: the corner profile.

use crate::sim::SimConfig;

/// The corner profile: faces of 20 mm at 0°, +10°, −5°, +15°, +5° (turns +10°, −15°, +20°,
/// −10°), centred on the arm's operating point.
pub(crate) fn corner_profile() -> Vec<[f64; 2]> {
    let slopes_deg = [0.0f64, 10.0, -5.0, 15.0, 5.0];
    let mut v = vec![[-0.05, 0.0]];
    for s in slopes_deg {
        let [u, h] = *v.last().unwrap_or(&[0.0, 0.0]);
        v.push([u + 0.02, h + 0.02 * s.to_radians().tan()]);
    }
    v
}

/// Puts `cfg` on the level corner profile at its surface origin, starting 2 mm past the first
/// vertex; returns the vertices and where runs end (2 mm before the last vertex).
pub(crate) fn on_corner_profile(cfg: &mut SimConfig) -> (Vec<[f64; 2]>, f64) {
    let vertices = corner_profile();
    cfg.surface = crate::surface::Surface {
        frame: crate::surface::SurfaceFrame {
            origin_m: cfg.surface.frame.origin_m,
            angle_rad: 0.0,
        },
        shape: crate::surface::Shape::Polyline {
            vertices: vertices.clone(),
        },
    };
    cfg.start_u_m = vertices[0][0] + 0.002;
    let end = vertices[vertices.len() - 1][0] - 0.002;
    (vertices, end)
}
