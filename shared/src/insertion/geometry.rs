//! The peg and the hole (docs/insertion.md, *Geometry*): a rectangular peg of width d and
//! length L, and a part whose top face is y = 0 with a hole of width D = d/(1 − c) and depth H
//! centred on x = 0, its mouth optionally chamfered. Contacts are found at every vertex–edge
//! pair: each of the peg's four corners against the part's nearest edge when the corner is
//! inside the part, each of the part's convex corners (the chamfer's two edges, or the hole's
//! edges without one) against the peg's nearest side when the corner is inside the peg.

use crate::math::{Vec2, cross, perp};
use serde::{Deserialize, Serialize};

/// The peg, the hole and the chamfer.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PegHoleGeometry {
    /// Peg width d (m).
    pub peg_width_m: f64,
    /// Peg length L, tip to gripper (m).
    pub peg_length_m: f64,
    /// Clearance ratio c = (D − d)/D.
    pub clearance_ratio: f64,
    /// Hole depth H (m).
    pub hole_depth_m: f64,
    /// Chamfer leg along the face (m); 0: a sharp edge.
    pub chamfer_m: f64,
    /// Chamfer angle from the hole's axis (deg).
    pub chamfer_angle_deg: f64,
    /// Half-width of the part's face on each side of the hole's axis (m).
    pub face_half_width_m: f64,
}

impl Default for PegHoleGeometry {
    fn default() -> Self {
        Self {
            peg_width_m: 0.010,
            peg_length_m: 0.030,
            clearance_ratio: 0.002,
            hole_depth_m: 0.020,
            chamfer_m: 0.5e-3,
            chamfer_angle_deg: 45.0,
            face_half_width_m: 0.030,
        }
    }
}

/// Which of the part's edges a segment is (for the contact state).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Feature {
    /// The top face left (−x) or right of the hole.
    Face,
    /// A chamfer.
    Chamfer,
    /// A wall of the hole.
    Wall,
    /// The hole's bottom.
    Bottom,
}

/// Most segments of the part's profile.
pub const MAX_SEGMENTS: usize = 7;
/// Most convex corners of the part.
pub const MAX_CORNERS: usize = 4;

/// The part's profile, left to right (the part is on the right of each segment).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    /// Vertices.
    pub vertices: [Vec2; MAX_SEGMENTS + 1],
    /// Segment count.
    pub segments: usize,
    /// What each segment is, and on which side of the axis (−1, 0 for the bottom, +1).
    pub features: [(Feature, i8); MAX_SEGMENTS],
    /// The convex corners (the hole's edges).
    pub corners: [Vec2; MAX_CORNERS],
    /// Their number (4 with a chamfer, 2 without).
    pub corner_count: usize,
}

/// One contact: depth, outward normal of the body pressed on (the force on the peg is along
/// `normal` for a peg corner in the part, along −`normal` reversed for a part corner in the peg:
/// `normal` here is always the direction of the force on the peg), the point, and what touched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Penetration (m).
    pub depth_m: f64,
    /// Unit direction of the normal force on the peg.
    pub normal: Vec2,
    /// Contact point (m, world).
    pub point: Vec2,
    /// The part's feature touched, and its side (−1, 0, +1).
    pub feature: (Feature, i8),
    /// Slot: 0–3 the peg's corners, 4.. the part's corners.
    pub slot: usize,
    /// For a part corner on the peg's side: the distance from the peg's tip along its axis (m).
    pub along_peg_m: Option<f64>,
    /// What the contact state counts the contact as: `feature`, but for a part corner on the
    /// peg's tip the feature the peg rests on (the face at the hole's sharp edge, the chamfer
    /// at its bottom edge), which is not in the hole (docs/insertion.md, *The plant*).
    pub counted_as: Feature,
}

impl Default for Contact {
    /// No contact: the fill of a contact buffer.
    fn default() -> Self {
        Self {
            depth_m: 0.0,
            normal: Vec2::zeros(),
            point: Vec2::zeros(),
            feature: (Feature::Face, 0),
            slot: 0,
            along_peg_m: None,
            counted_as: Feature::Face,
        }
    }
}

impl PegHoleGeometry {
    /// Hole width D (m).
    pub fn hole_width_m(&self) -> f64 {
        self.peg_width_m / (1.0 - self.clearance_ratio)
    }

    /// The part's profile.
    pub fn profile(&self) -> Profile {
        let half = 0.5 * self.hole_width_m();
        let (w, h) = if self.chamfer_m > 0.0 {
            let depth = self.chamfer_m / self.chamfer_angle_deg.to_radians().tan();
            (self.chamfer_m, depth)
        } else {
            (0.0, 0.0)
        };
        let (far, bottom) = (self.face_half_width_m, -self.hole_depth_m);
        let mut vertices = [Vec2::zeros(); MAX_SEGMENTS + 1];
        let mut features = [(Feature::Face, 0); MAX_SEGMENTS];
        let mut n = 0;
        let mut push = |v: Vec2, f: Option<(Feature, i8)>| {
            vertices[n] = v;
            if let Some(f) = f {
                features[n] = f;
            }
            n += 1;
        };
        push(Vec2::new(-far, 0.0), Some((Feature::Face, -1)));
        if w > 0.0 {
            push(Vec2::new(-half - w, 0.0), Some((Feature::Chamfer, -1)));
        }
        push(Vec2::new(-half, -h), Some((Feature::Wall, -1)));
        push(Vec2::new(-half, bottom), Some((Feature::Bottom, 0)));
        push(Vec2::new(half, bottom), Some((Feature::Wall, 1)));
        push(
            Vec2::new(half, -h),
            Some(if w > 0.0 {
                (Feature::Chamfer, 1)
            } else {
                (Feature::Face, 1)
            }),
        );
        if w > 0.0 {
            push(Vec2::new(half + w, 0.0), Some((Feature::Face, 1)));
        }
        push(Vec2::new(far, 0.0), None);
        let mut corners = [Vec2::zeros(); MAX_CORNERS];
        let corner_list: &[Vec2] = if w > 0.0 {
            &[
                Vec2::new(-half - w, 0.0),
                Vec2::new(-half, -h),
                Vec2::new(half, -h),
                Vec2::new(half + w, 0.0),
            ]
        } else {
            &[Vec2::new(-half, 0.0), Vec2::new(half, 0.0)]
        };
        corners[..corner_list.len()].copy_from_slice(corner_list);
        Profile {
            vertices,
            segments: n - 1,
            features,
            corners,
            corner_count: corner_list.len(),
        }
    }

    /// The peg's corners (tip left, tip right, top right, top left) at `pose` = (x, y, θ) of
    /// the tip's centre, θ counter-clockwise from the hole's axis.
    pub fn peg_corners(&self, pose: [f64; 3]) -> [Vec2; 4] {
        let (axis, side) = peg_axes(pose[2]);
        let tip = Vec2::new(pose[0], pose[1]);
        let (r, l) = (0.5 * self.peg_width_m, self.peg_length_m);
        [
            tip - side * r,
            tip + side * r,
            tip + side * r + axis * l,
            tip - side * r + axis * l,
        ]
    }
}

/// The peg's axis (tip to top) and its side direction (+x at θ = 0) at tilt θ.
pub fn peg_axes(theta: f64) -> (Vec2, Vec2) {
    let (s, c) = theta.sin_cos();
    (Vec2::new(-s, c), Vec2::new(c, s))
}

impl Profile {
    /// True when `p` is inside the part (below the face and not in the hole).
    pub fn inside(&self, p: Vec2) -> bool {
        if p.y >= 0.0 {
            return false;
        }
        // The air below the face: the hole (with its chamfer), between the profile's walls.
        let v = &self.vertices[..=self.segments];
        let bottom = v.iter().map(|q| q.y).fold(0.0, f64::min);
        if p.y <= bottom {
            return true;
        }
        // Left and right boundaries of the air at height p.y.
        let (mut left, mut right) = (f64::NEG_INFINITY, f64::INFINITY);
        for i in 0..self.segments {
            let (a, b) = (v[i], v[i + 1]);
            let (lo, hi) = (a.y.min(b.y), a.y.max(b.y));
            if a.y == b.y || p.y < lo || p.y > hi {
                continue;
            }
            let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
            if self.features[i].1 < 0 {
                left = left.max(x);
            } else {
                right = right.min(x);
            }
        }
        !(p.x > left && p.x < right)
    }

    /// The contact of a point `p` inside the part: the nearest of the part's segments, its
    /// depth and outward normal (None outside the part).
    pub fn nearest_edge(&self, p: Vec2) -> Option<(f64, Vec2, (Feature, i8))> {
        if !self.inside(p) {
            return None;
        }
        let mut best: Option<(f64, Vec2, (Feature, i8))> = None;
        for i in 0..self.segments {
            let (a, b) = (self.vertices[i], self.vertices[i + 1]);
            let d = b - a;
            let len = d.norm();
            let dir = d / len;
            let s = (p - a).dot(&dir).clamp(0.0, len);
            let dist = (p - (a + dir * s)).norm();
            if best.is_none_or(|(bd, _, _)| dist < bd) {
                best = Some((dist, perp(dir), self.features[i]));
            }
        }
        best
    }
}

/// Every contact between the peg at `pose` and the part `profile`, written into `out`;
/// returns how many.
pub fn contacts(
    g: &PegHoleGeometry,
    profile: &Profile,
    pose: [f64; 3],
    out: &mut [Contact; 4 + MAX_CORNERS],
) -> usize {
    let mut n = 0;
    for (slot, c) in g.peg_corners(pose).iter().enumerate() {
        if let Some((depth, normal, feature)) = profile.nearest_edge(*c) {
            out[n] = Contact {
                depth_m: depth,
                normal,
                point: *c,
                feature,
                slot,
                along_peg_m: None,
                counted_as: feature.0,
            };
            n += 1;
        }
    }
    let (axis, side) = peg_axes(pose[2]);
    let tip = Vec2::new(pose[0], pose[1]);
    let (r, l) = (0.5 * g.peg_width_m, g.peg_length_m);
    for k in 0..profile.corner_count {
        let v = profile.corners[k];
        let (u, w) = ((v - tip).dot(&side), (v - tip).dot(&axis));
        if u.abs() >= r || w <= 0.0 || w >= l {
            continue;
        }
        // The nearest of the peg's sides: left, right (the tip and the top are ends).
        let on_side = r - u.abs() <= w.min(l - w);
        let (depth, normal) = if on_side {
            (r - u.abs(), side * -u.signum())
        } else if w < l - w {
            (w, axis)
        } else {
            (l - w, -axis)
        };
        let side_sign = if v.x < 0.0 { -1 } else { 1 };
        // The chamfer's top edge under the peg is the face's edge (the peg rests on the face);
        // the chamfer's bottom edge, or the hole's edge without one, is the hole's.
        let top_edge = profile.corner_count == 2 || k == 0 || k == 3;
        let feature = if profile.corner_count == 4 && top_edge {
            Feature::Face
        } else {
            Feature::Wall
        };
        // Under the peg's tip the corner is where the peg rests, above the bore: the face's
        // edge (the sharp edge, the chamfer's top) or the chamfer's bottom edge.
        let counted_as = match (on_side, top_edge) {
            (true, _) => feature,
            (false, true) => Feature::Face,
            (false, false) => Feature::Chamfer,
        };
        out[n] = Contact {
            depth_m: depth,
            normal,
            point: v,
            feature: (feature, side_sign),
            slot: 4 + k,
            along_peg_m: Some(w),
            counted_as,
        };
        n += 1;
    }
    n
}

/// The moment arm of a force `f` at `point` about `centre` (N·m).
pub fn moment_about(centre: Vec2, point: Vec2, f: Vec2) -> f64 {
    cross(point - centre, f)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_has_the_holes_width_and_chamfer() {
        let g = PegHoleGeometry::default();
        let p = g.profile();
        assert_eq!((p.segments, p.corner_count), (7, 4));
        let d = g.hole_width_m();
        assert!((d - 0.01 / 0.998).abs() < 1e-15);
        assert!((p.vertices[2].x + 0.5 * d).abs() < 1e-15);
        assert!(
            (p.vertices[2].y + 0.5e-3).abs() < 1e-12,
            "45°: as deep as wide"
        );
        let sharp = PegHoleGeometry {
            chamfer_m: 0.0,
            ..g
        }
        .profile();
        assert_eq!((sharp.segments, sharp.corner_count), (5, 2));
    }

    /// Inside the part: below the face away from the hole, in the walls; not in the hole,
    /// the chamfer's opening or above the face.
    #[test]
    fn inside_is_the_part() {
        let p = PegHoleGeometry::default().profile();
        for (pt, inside) in [
            ([0.0, -0.005], false),
            ([0.0, 0.001], false),
            ([-0.0052, -0.0001], false), // in the chamfer's opening
            ([-0.0052, -0.002], true),   // in the left wall below the chamfer
            ([0.02, -0.001], true),
            ([0.0, -0.025], true), // below the bottom
            ([0.00501, -0.01], false),
            ([0.00502, -0.01], true),
        ] {
            assert_eq!(p.inside(Vec2::new(pt[0], pt[1])), inside, "{pt:?}");
        }
    }

    /// A peg corner 3 µm into the right wall touches the wall, normal −x, depth 3 µm; a corner
    /// 3 µm into the face touches the face.
    #[test]
    fn a_corner_in_the_part_touches_its_nearest_edge() {
        let p = PegHoleGeometry::default().profile();
        let half = 0.5 * PegHoleGeometry::default().hole_width_m();
        let (d, n, f) = p.nearest_edge(Vec2::new(half + 3e-6, -0.01)).unwrap();
        assert!((d - 3e-6).abs() < 1e-12 && (n - Vec2::new(-1.0, 0.0)).norm() < 1e-12);
        assert_eq!(f, (Feature::Wall, 1));
        let (d, n, f) = p.nearest_edge(Vec2::new(0.01, -3e-6)).unwrap();
        assert!((d - 3e-6).abs() < 1e-12 && (n - Vec2::new(0.0, 1.0)).norm() < 1e-12);
        assert_eq!(f, (Feature::Face, 1));
    }

    /// A peg tilted in the hole against the left edge: the hole's edge is inside the peg's
    /// left side, pushing the peg to +x, at its depth along the peg.
    #[test]
    fn a_part_corner_in_the_peg_touches_its_nearest_side() {
        let g = PegHoleGeometry {
            chamfer_m: 0.0,
            ..PegHoleGeometry::default()
        };
        let profile = g.profile();
        let half = 0.5 * g.hole_width_m();
        // Tip 5 mm deep, shifted so the left side passes 2 µm left of the edge (−half, 0).
        let pose = [-half + 0.005 - 2e-6, -0.005, 0.0];
        let mut out = [Contact::default(); 4 + MAX_CORNERS];
        let n = contacts(&g, &profile, pose, &mut out);
        let edge: Vec<_> = out[..n].iter().filter(|c| c.slot >= 4).collect();
        assert_eq!(edge.len(), 1, "{:?}", &out[..n]);
        assert!((edge[0].depth_m - 2e-6).abs() < 1e-12);
        assert!((edge[0].normal - Vec2::new(1.0, 0.0)).norm() < 1e-12);
        assert!((edge[0].along_peg_m.unwrap() - 0.005).abs() < 1e-12);
    }

    /// The hole's sharp edge under the peg's tip is where the peg rests on the face (counted
    /// as the face), on the peg's side it is in the hole (the wall); the chamfer's bottom edge
    /// under the tip is the chamfer. The feature the bristle follows stays the corner's.
    #[test]
    fn a_part_corner_under_the_tip_is_what_the_peg_rests_on() {
        let g = PegHoleGeometry {
            chamfer_m: 0.0,
            ..PegHoleGeometry::default()
        };
        let half = 0.5 * g.hole_width_m();
        let edge = |g: &PegHoleGeometry, pose: [f64; 3]| {
            let mut out = [Contact::default(); 4 + MAX_CORNERS];
            let n = contacts(g, &g.profile(), pose, &mut out);
            let edge: Vec<_> = out[..n].iter().filter(|c| c.slot >= 4).copied().collect();
            assert_eq!(edge.len(), 1, "{:?}", &out[..n]);
            edge[0]
        };
        // The tip 2 mm left of the centre, 2 µm below the face: the left edge is under it.
        let under = edge(&g, [-0.002, -2e-6, 0.0]);
        assert!((under.normal - Vec2::new(0.0, 1.0)).norm() < 1e-12);
        assert_eq!(under.feature, (Feature::Wall, -1));
        assert_eq!(under.counted_as, Feature::Face);
        // The tip 5 mm in, the left side 2 µm over the edge: in the hole.
        let beside = edge(&g, [-half + 0.005 - 2e-6, -0.005, 0.0]);
        assert_eq!(beside.counted_as, Feature::Wall);
        // A shallow chamfer (85° from the axis: 44 µm deep) and the peg tilted 20° to lie on
        // its bottom edge, 4 mm in from the peg's left corner, which is above the face.
        let g = PegHoleGeometry {
            chamfer_angle_deg: 85.0,
            ..PegHoleGeometry::default()
        };
        let h = g.chamfer_m / g.chamfer_angle_deg.to_radians().tan();
        let theta = -20f64.to_radians();
        let (axis, side) = peg_axes(theta);
        let tip = Vec2::new(-half, -h) + side * 0.004 - axis * 2e-6;
        let bottom = edge(&g, [tip.x, tip.y, theta]);
        assert!((bottom.normal - axis).norm() < 1e-12);
        assert_eq!(
            (bottom.feature, bottom.counted_as),
            ((Feature::Wall, -1), Feature::Chamfer)
        );
    }
}
