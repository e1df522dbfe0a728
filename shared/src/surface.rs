//! Environment geometry and the normal contact law (thesis §3.1, §5.3.1, fig. 5.4).
//!
//! A surface is a height profile `w = h(u)` in a local frame (origin, base angle): `u` runs
//! along the base tangent `t0`, `w` along the outward normal `n0 = perp(t0)`, and the material
//! fills `w < h(u)`. Shapes: a plane at any angle, a sinusoid (fig. 5.6), and a piecewise-linear
//! profile with corners (fig. 5.3).
//!
//! [`Surface::contacts`] returns up to two contact points for a point tool at `p`: the
//! penetration depth, the outward unit normal (the direction of the environment's push on the
//! tool) and the unit tangent. At a valley (inside) corner the tool can press on both faces; at
//! a peak it presses on the face it is nearest to.
//!
//! [`ContactLaw`] turns penetration into force: the interaction stiffness k_e in series with the
//! sensor's stiffness (thesis §4.5.1), plus a small normal damping; the force never pulls.

use crate::error::ConfigError;
pub use crate::error::SurfaceError;
use crate::math::{Vec2, perp, series_stiffness, unit};
use serde::{Deserialize, Serialize};

/// Placement of a surface's local frame in the world.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceFrame {
    /// Origin of the local frame (m, world).
    pub origin_m: [f64; 2],
    /// Angle of the base tangent t0 from the world X axis (rad). The material lies to the right
    /// of t0 (on the −perp(t0) side).
    pub angle_rad: f64,
}

/// The shape of a surface in its local frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Shape {
    /// `h(u) = 0`.
    Plane,
    /// `h(u) = amplitude · sin(2π u / wavelength)`.
    Sinusoid {
        /// Amplitude (m).
        amplitude_m: f64,
        /// Wavelength (m).
        wavelength_m: f64,
    },
    /// Piecewise-linear `h` through `vertices` (u, h) in m, u increasing; the first and last
    /// segments extend to infinity.
    Polyline {
        /// Vertices (u, h) in metres, at least two, strictly increasing u.
        vertices: Vec<[f64; 2]>,
    },
}

/// A surface: shape plus placement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Surface {
    /// Placement.
    pub frame: SurfaceFrame,
    /// Shape.
    pub shape: Shape,
}

/// The surface coordinate of the point of the sinusoid `h(s) = amplitude · sin(2π s /
/// wavelength)` nearest to the local point (u, w): Newton on
/// `g(s) = (s − u) + (h(s) − w) h'(s)` from s = u.
pub fn closest_on_sinusoid(u: f64, w: f64, amplitude_m: f64, wavelength_m: f64) -> f64 {
    let k = std::f64::consts::TAU / wavelength_m;
    let mut s = u;
    for _ in 0..8 {
        let hs = amplitude_m * (k * s).sin();
        let h1 = amplitude_m * k * (k * s).cos();
        let h2 = -amplitude_m * k * k * (k * s).sin();
        let g = (s - u) + (hs - w) * h1;
        let dg = 1.0 + h1 * h1 + (hs - w) * h2;
        if dg.abs() < 1e-12 {
            break;
        }
        let step = g / dg;
        s -= step;
        if step.abs() < 1e-13 {
            break;
        }
    }
    s
}

/// Largest polyline the contact query handles.
pub const MAX_VERTICES: usize = 64;

/// One contact point between the tool tip and the surface.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct ContactPoint {
    /// Penetration depth (m), > 0 in contact.
    pub depth_m: f64,
    /// Outward unit normal (world): the direction the environment pushes the tool.
    pub normal: Vec2,
    /// Unit tangent (world), `normal = perp(tangent)`.
    pub tangent: Vec2,
    /// Surface coordinate u of the contact (m), for the roughness map.
    pub u_m: f64,
    /// Which face (segment index; 0 for smooth shapes).
    pub feature: usize,
}

/// Up to two simultaneous contacts (fixed size, no allocation).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Contacts {
    /// Number of valid entries in `points`.
    pub count: usize,
    /// Contact points; only the first `count` are valid.
    pub points: [ContactPoint; 2],
}

impl Contacts {
    fn push(&mut self, c: ContactPoint) {
        if self.count < 2 {
            self.points[self.count] = c;
            self.count += 1;
        } else {
            // Keep the two deepest.
            let (i, shallow) = if self.points[0].depth_m < self.points[1].depth_m {
                (0, self.points[0].depth_m)
            } else {
                (1, self.points[1].depth_m)
            };
            if c.depth_m > shallow {
                self.points[i] = c;
            }
        }
    }

    /// The valid contacts.
    pub fn as_slice(&self) -> &[ContactPoint] {
        &self.points[..self.count]
    }
}

impl Surface {
    /// A plane through `point` whose tangent makes `angle` (rad) with world X; material on the
    /// right of the tangent.
    pub fn plane(point: Vec2, angle: f64) -> Self {
        Self {
            frame: SurfaceFrame {
                origin_m: [point.x, point.y],
                angle_rad: angle,
            },
            shape: Shape::Plane,
        }
    }

    /// Checks the description.
    pub fn validate(&self) -> Result<(), SurfaceError> {
        let f = &self.frame;
        if !(f.origin_m[0].is_finite() && f.origin_m[1].is_finite()) {
            return Err(SurfaceError::NotFinite("frame.origin_m"));
        }
        if !f.angle_rad.is_finite() {
            return Err(SurfaceError::NotFinite("frame.angle_rad"));
        }
        match &self.shape {
            Shape::Plane => Ok(()),
            Shape::Sinusoid {
                amplitude_m,
                wavelength_m,
            } => {
                if !amplitude_m.is_finite() {
                    return Err(SurfaceError::NotFinite("amplitude_m"));
                }
                if !(wavelength_m.is_finite() && *wavelength_m > 0.0) {
                    return Err(SurfaceError::BadWavelength(*wavelength_m));
                }
                Ok(())
            }
            Shape::Polyline { vertices } => {
                if vertices.len() > MAX_VERTICES {
                    return Err(SurfaceError::TooManyVertices {
                        count: vertices.len(),
                        max: MAX_VERTICES,
                    });
                }
                if vertices.len() < 2 {
                    return Err(SurfaceError::BadPolyline(vertices.len()));
                }
                for (i, v) in vertices.iter().enumerate() {
                    if !(v[0].is_finite() && v[1].is_finite()) {
                        return Err(SurfaceError::NotFinite("vertices"));
                    }
                    if i > 0 && v[0] <= vertices[i - 1][0] {
                        return Err(SurfaceError::BadPolyline(i));
                    }
                }
                Ok(())
            }
        }
    }

    fn origin(&self) -> Vec2 {
        Vec2::new(self.frame.origin_m[0], self.frame.origin_m[1])
    }

    fn t0(&self) -> Vec2 {
        unit(self.frame.angle_rad)
    }

    /// Local coordinates (u, w) of a world point.
    pub fn to_local(&self, p: Vec2) -> (f64, f64) {
        let d = p - self.origin();
        let t0 = self.t0();
        (d.dot(&t0), d.dot(&perp(t0)))
    }

    /// World point of local coordinates (u, w).
    pub fn to_world(&self, u: f64, w: f64) -> Vec2 {
        let t0 = self.t0();
        self.origin() + t0 * u + perp(t0) * w
    }

    /// Height h(u) and slope h'(u) of the profile (m, dimensionless).
    pub fn height_slope(&self, u: f64) -> (f64, f64) {
        match &self.shape {
            Shape::Plane => (0.0, 0.0),
            Shape::Sinusoid {
                amplitude_m,
                wavelength_m,
            } => {
                let k = std::f64::consts::TAU / wavelength_m;
                (amplitude_m * (k * u).sin(), amplitude_m * k * (k * u).cos())
            }
            Shape::Polyline { vertices } => {
                let i = segment_index(vertices, u);
                let (a, b) = (vertices[i], vertices[i + 1]);
                let slope = (b[1] - a[1]) / (b[0] - a[0]);
                (a[1] + slope * (u - a[0]), slope)
            }
        }
    }

    /// World angle (rad) of the true surface tangent at surface coordinate u.
    pub fn tangent_angle_at(&self, u: f64) -> f64 {
        let (_, slope) = self.height_slope(u);
        self.frame.angle_rad + slope.atan()
    }

    /// The world point on the surface at coordinate u.
    pub fn point_at(&self, u: f64) -> Vec2 {
        let (h, _) = self.height_slope(u);
        self.to_world(u, h)
    }

    /// Contacts of a point tool at `p` (world). Allocation-free.
    pub fn contacts(&self, p: Vec2) -> Contacts {
        let mut out = Contacts::default();
        let (u, w) = self.to_local(p);
        let t0 = self.t0();
        let n0 = perp(t0);
        let local_to_world = |lt: (f64, f64)| -> Vec2 { t0 * lt.0 + n0 * lt.1 };
        match &self.shape {
            Shape::Plane => {
                if w < 0.0 {
                    out.push(ContactPoint {
                        depth_m: -w,
                        normal: n0,
                        tangent: t0,
                        u_m: u,
                        feature: 0,
                    });
                }
            }
            Shape::Sinusoid {
                amplitude_m,
                wavelength_m,
            } => {
                let k = std::f64::consts::TAU / wavelength_m;
                let h = |x: f64| amplitude_m * (k * x).sin();
                if w >= h(u) {
                    return out;
                }
                let s = closest_on_sinusoid(u, w, *amplitude_m, *wavelength_m);
                let hs = h(s);
                let slope = amplitude_m * k * (k * s).cos();
                let depth = ((s - u).powi(2) + (hs - w).powi(2)).sqrt();
                let norm = (1.0 + slope * slope).sqrt();
                let tangent = local_to_world((1.0 / norm, slope / norm));
                out.push(ContactPoint {
                    depth_m: depth,
                    normal: perp(tangent),
                    tangent,
                    u_m: s,
                    feature: 0,
                });
            }
            Shape::Polyline { vertices } => {
                let (hu, _) = self.height_slope(u);
                if w >= hu {
                    return out;
                }
                let n = vertices.len();
                // Each face the point presses on: penetration into its half-plane, with the point's
                // projection inside the face (extended by the penetration, which closes the gap
                // below a valley corner; end faces are infinite).
                let mut cand: [Option<ContactPoint>; MAX_VERTICES] = [None; MAX_VERTICES];
                for i in 0..n - 1 {
                    let a = vertices[i];
                    let b = vertices[i + 1];
                    let d = (b[0] - a[0], b[1] - a[1]);
                    let len = (d.0 * d.0 + d.1 * d.1).sqrt();
                    let dir = (d.0 / len, d.1 / len);
                    let nrm = (-dir.1, dir.0);
                    let rel = (u - a[0], w - a[1]);
                    let depth = -(rel.0 * nrm.0 + rel.1 * nrm.1);
                    if depth <= 0.0 {
                        continue;
                    }
                    let along = rel.0 * dir.0 + rel.1 * dir.1;
                    let lo = if i == 0 { f64::NEG_INFINITY } else { -depth };
                    let hi = if i + 2 == n {
                        f64::INFINITY
                    } else {
                        len + depth
                    };
                    if along < lo || along > hi {
                        continue;
                    }
                    let tangent = local_to_world(dir);
                    cand[i] = Some(ContactPoint {
                        depth_m: depth,
                        normal: perp(tangent),
                        tangent,
                        u_m: a[0] + along.clamp(0.0, len) * dir.0,
                        feature: i,
                    });
                }
                // At a peak (convex) corner the material is the intersection of the two half-planes:
                // the tool presses only on the face it is nearest to.
                for j in 1..n - 1 {
                    let (a, v, b) = (vertices[j - 1], vertices[j], vertices[j + 1]);
                    let turn = (v[0] - a[0]) * (b[1] - v[1]) - (v[1] - a[1]) * (b[0] - v[0]);
                    if turn < 0.0
                        && let (Some(l), Some(r)) = (cand[j - 1], cand[j])
                    {
                        if l.depth_m <= r.depth_m {
                            cand[j] = None;
                        } else {
                            cand[j - 1] = None;
                        }
                    }
                }
                for c in cand.iter().take(n - 1).flatten() {
                    out.push(*c);
                }
            }
        }
        out
    }
}

fn segment_index(vertices: &[[f64; 2]], u: f64) -> usize {
    let n = vertices.len();
    let mut i = 0;
    while i + 2 < n && u > vertices[i + 1][0] {
        i += 1;
    }
    i
}

/// Normal contact law: penetration → push.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContactLaw {
    /// Interaction stiffness k_e of the part contact (N/m); thesis default 10e3.
    pub interaction_stiffness_n_per_m: f64,
    /// Force-sensor stiffness in series (N/m); thesis 8.8e6.
    pub sensor_stiffness_n_per_m: f64,
    /// Normal damping (N·s/m); small (the thesis neglects it), only while pressing.
    pub damping_n_s_per_m: f64,
}

impl Default for ContactLaw {
    fn default() -> Self {
        Self {
            interaction_stiffness_n_per_m: 10e3,
            sensor_stiffness_n_per_m: 8.8e6,
            damping_n_s_per_m: 50.0,
        }
    }
}

impl ContactLaw {
    /// Series stiffness of contact and sensor (N/m).
    pub fn stiffness(&self) -> f64 {
        series_stiffness(
            self.interaction_stiffness_n_per_m,
            self.sensor_stiffness_n_per_m,
        )
    }

    /// Normal push (N, ≥ 0) for penetration `depth` (m) and penetration rate `depth_rate` (m/s).
    pub fn normal_force(&self, depth: f64, depth_rate: f64) -> f64 {
        if depth <= 0.0 {
            return 0.0;
        }
        (self.stiffness() * depth + self.damping_n_s_per_m * depth_rate).max(0.0)
    }

    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (name, v) in [
            (
                "interaction_stiffness_n_per_m",
                self.interaction_stiffness_n_per_m,
            ),
            ("sensor_stiffness_n_per_m", self.sensor_stiffness_n_per_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ConfigError::setting(
                    format!("contact.{name}"),
                    v,
                    "must be a positive number",
                ));
            }
        }
        if !(self.damping_n_s_per_m.is_finite() && self.damping_n_s_per_m >= 0.0) {
            return Err(ConfigError::setting(
                "contact.damping_n_s_per_m",
                self.damping_n_s_per_m,
                "must be ≥ 0",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tilted_plane_depth_and_normal() {
        let ang = 0.3;
        let s = Surface::plane(Vec2::new(0.1, 0.2), ang);
        let p = s.to_world(0.05, -0.001);
        let c = s.contacts(p);
        assert_eq!(c.count, 1);
        let cp = c.points[0];
        assert!((cp.depth_m - 0.001).abs() < 1e-15);
        assert!((cp.normal - perp(unit(ang))).norm() < 1e-15);
        assert!((cp.tangent - unit(ang)).norm() < 1e-15);
        assert_eq!(s.contacts(s.to_world(0.0, 1e-6)).count, 0);
    }

    /// The sinusoid's depth is the true distance to the curve (checked by dense sampling).
    #[test]
    fn sinusoid_depth_is_distance_to_curve() {
        let s = Surface {
            frame: SurfaceFrame {
                origin_m: [0.0, 0.0],
                angle_rad: 0.2,
            },
            shape: Shape::Sinusoid {
                amplitude_m: 0.01,
                wavelength_m: 0.1,
            },
        };
        for &u in &[0.0, 0.013, 0.025, 0.06, 0.081] {
            let (h, _) = s.height_slope(u);
            let p = s.to_world(u, h - 0.0007);
            let c = s.contacts(p);
            assert_eq!(c.count, 1);
            let mut best = f64::INFINITY;
            for k in 0..200_001 {
                let x = u - 0.01 + 0.02 * k as f64 / 200_000.0;
                best = best.min((s.point_at(x) - p).norm());
            }
            assert!(
                (c.points[0].depth_m - best).abs() < 1e-9,
                "u={u}: {} vs {best}",
                c.points[0].depth_m
            );
            // The normal points from the tool towards the nearest surface point.
            let foot = s.point_at(c.points[0].u_m);
            assert!(((foot - p).normalize() - c.points[0].normal).norm() < 1e-6);
        }
    }

    fn valley() -> Surface {
        Surface {
            frame: SurfaceFrame {
                origin_m: [0.0, 0.0],
                angle_rad: 0.0,
            },
            shape: Shape::Polyline {
                vertices: vec![[-0.1, 0.0], [0.0, 0.0], [0.05, 0.05]],
            },
        }
    }

    #[test]
    fn valley_corner_gives_two_contacts() {
        let s = valley();
        let c = s.contacts(Vec2::new(-0.0002, -0.0005));
        // Flat face at depth 0.5 mm; the 45° face: distance to y = x line.
        assert_eq!(c.count, 1, "not yet touching the rising face: {c:?}");
        let c = s.contacts(Vec2::new(0.0003, 0.0001));
        assert_eq!(c.count, 1);
        assert_eq!(c.points[0].feature, 1);
        let c = s.contacts(Vec2::new(0.0001, -0.0002));
        assert_eq!(c.count, 2, "{c:?}");
        let depths: Vec<f64> = c.as_slice().iter().map(|p| p.depth_m).collect();
        assert!(depths.iter().any(|d| (d - 0.0002).abs() < 1e-12));
        assert!(
            depths
                .iter()
                .any(|d| (d - 0.0003 / 2f64.sqrt()).abs() < 1e-12)
        );
    }

    #[test]
    fn peak_corner_presses_on_nearest_face_only() {
        let s = Surface {
            frame: SurfaceFrame {
                origin_m: [0.0, 0.0],
                angle_rad: 0.0,
            },
            shape: Shape::Polyline {
                vertices: vec![[-0.1, -0.1], [0.0, 0.0], [0.1, -0.1]],
            },
        };
        let c = s.contacts(Vec2::new(0.0002, -0.0005));
        assert_eq!(c.count, 1);
        assert_eq!(c.points[0].feature, 1);
        assert_eq!(s.contacts(Vec2::new(0.0, 0.0001)).count, 0);
    }

    #[test]
    fn bad_surfaces_are_rejected() {
        let s = Surface {
            frame: SurfaceFrame {
                origin_m: [0.0, 0.0],
                angle_rad: 0.0,
            },
            shape: Shape::Polyline {
                vertices: vec![[0.0, 0.0], [0.0, 1.0]],
            },
        };
        assert_eq!(s.validate(), Err(SurfaceError::BadPolyline(1)));
        let s = Surface {
            frame: SurfaceFrame {
                origin_m: [f64::NAN, 0.0],
                angle_rad: 0.0,
            },
            shape: Shape::Plane,
        };
        assert!(s.validate().is_err());
    }

    #[test]
    fn contact_law_series_stiffness_and_no_pull() {
        let law = ContactLaw::default();
        let k = 1.0 / (1.0 / 10e3 + 1.0 / 8.8e6);
        assert!((law.normal_force(1e-3, 0.0) - k * 1e-3).abs() < 1e-9);
        assert_eq!(law.normal_force(-1e-3, 0.0), 0.0);
        assert_eq!(law.normal_force(1e-6, -10.0), 0.0);
    }
}
