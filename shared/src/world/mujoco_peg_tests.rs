use super::*;
use crate::insertion::plant::{ContactState, PegPlant};

/// The default peg on MuJoCo at the servo's 10 kHz.
fn peg_at(tip: [f64; 3]) -> (MujocoPeg, PegPlant) {
    let p = PegParams::default();
    let m = MujocoPeg::new(p, &MujocoParams::default(), tip, 1e-4).unwrap();
    (m, PegPlant::new(p, tip))
}

/// Steps both plants `n` ticks with the wrist commanded to `target`.
fn hold(m: &mut MujocoPeg, b: &mut PegPlant, target: [f64; 3], n: usize) {
    struct At([f64; 3]);
    impl Flange for At {
        fn pose(&self) -> ([f64; 3], [f64; 3]) {
            (self.0, [0.0; 3])
        }
        fn react(&mut self, _: Vec2, _: f64, _: f64) {}
    }
    for _ in 0..n {
        m.step_with(&mut At(target), 1e-4);
        b.step(target, [0.0; 3], 1e-4);
    }
}

/// The part's solids are the profile's: each inset vertex is ρ from the two edges it joins.
#[test]
fn the_solids_sit_their_vertex_radius_inside_the_part() {
    for chamfer in [0.5e-3, 0.0] {
        let mut g = PegParams::default().geometry;
        g.chamfer_m = chamfer;
        let profile = g.profile();
        // The face's, the chamfer's and the walls' vertices are the solids'.
        let floor = -g.hole_depth_m;
        for v in profile.vertices[..=profile.segments]
            .iter()
            .filter(|v| v.y > floor)
        {
            assert!(solids(&profile).iter().any(|s| s.contains(v)), "{v:?}");
        }
        for solid in solids(&profile) {
            let r = VERTEX_RADIUS_M;
            let moved = inset(&solid, r);
            let n = solid.len();
            for i in 0..n {
                for (a, b) in [
                    (solid[(i + n - 1) % n], solid[i]),
                    (solid[i], solid[(i + 1) % n]),
                ] {
                    let d = (b - a).normalize();
                    let dist = cross(d, moved[i] - a);
                    assert!((dist - r).abs() < 1e-12, "{dist} at {:?}", solid[i]);
                }
            }
        }
    }
}

/// Pressed square on the face beside the hole, the peg settles where the wrist's force equals
/// both tip corners' springs in series with it: depth k_y Δ/(k_y + 2k_c) to 1 nm, the contact
/// force 2 k_c times it to 0.1 %, and the state the face, as on the built-in plant.
#[test]
fn pressed_on_the_face_each_corner_is_a_contact_of_the_set_ups_stiffness() {
    let start = [15e-3, 0.0, 0.0];
    let (mut m, mut b) = peg_at(start);
    let p = *m.params();
    let push = 1e-3;
    hold(&mut m, &mut b, [start[0], -push, 0.0], 5000);
    let (ky, kc) = (p.wrist_stiffness[1], p.contact_stiffness_n_per_m);
    let want = ky * push / (ky + 2.0 * kc);
    // MuJoCo keeps a mesh's vertices in single precision, about its centroid 13 mm off:
    // the face is where it should be to a nanometre.
    let depth = m.truth().depth_m;
    assert!((depth - want).abs() < 1e-9, "depth {depth} vs {want}");
    let t = m.truth();
    assert_eq!(t.state, ContactState::Face);
    assert_eq!(b.truth().state, ContactState::Face);
    let force = 2.0 * kc * want;
    assert!(
        (t.force.y - force).abs() < 1e-3 * force,
        "{:?} vs {force}",
        t.force
    );
    assert!(t.force.x.abs() < 1e-6 * force && t.moment_about_tip.abs() < 1e-6 * force);
}

/// In the hole and pushed across it at the wrist (30 mm up the peg), the peg tilts until its
/// tip's left corner is on the left wall and the hole's right edge on its side: jammed, as on
/// the built-in plant, with the edge at the same place along the peg and the same force to
/// 2 %; pushed down the left chamfer, it is on the chamfer, pushed up and to the right.
#[test]
fn in_the_hole_and_on_the_chamfer_it_has_the_built_in_plants_state() {
    let (mut m, mut b) = peg_at([0.0, -5e-3, 0.0]);
    hold(&mut m, &mut b, [1e-3, -5e-3, 0.0], 5000);
    let (tm, tb) = (m.truth(), b.truth());
    assert_eq!(tm.state, ContactState::Jammed);
    assert_eq!(tb.state, ContactState::Jammed);
    assert!(tm.force.x < -1.0, "{:?}", tm.force);
    assert!(
        (tm.force - tb.force).norm() < 2e-2 * tb.force.norm(),
        "{:?} vs {:?}",
        tm.force,
        tb.force
    );
    let (lm, lb) = (tm.edge_along_peg_m.unwrap(), tb.edge_along_peg_m.unwrap());
    assert!((lm - lb).abs() < 0.01 * lb, "{lm} vs {lb}");
    // The left chamfer runs from (−D/2 − w, 0) to (−D/2, −w): the tip's left corner on it.
    let half = 0.5 * m.params().geometry.hole_width_m();
    let x = -half - 0.4e-3 + 5e-3;
    let (mut m, mut b) = peg_at([x, 0.0, 0.0]);
    hold(&mut m, &mut b, [x, -0.6e-3, 0.0], 5000);
    assert_eq!(m.truth().state, ContactState::Chamfer);
    assert_eq!(b.truth().state, ContactState::Chamfer);
    let f = m.truth().force;
    assert!(f.x > 0.0 && f.y > 0.0, "{f:?}");
    assert!(
        (f - b.truth().force).norm() < 2e-2 * f.norm(),
        "{f:?} vs {:?}",
        b.truth().force
    );
}

/// Tilted 2° against the left wall and pushed down, the peg's tip's right corner and the
/// hole's left edge hold it in two-point contact, as on the built-in plant, with the edge at
/// the same place along the peg.
#[test]
fn tilted_in_the_bore_it_makes_the_built_in_plants_two_point_contact() {
    let theta = 2f64.to_radians();
    let (mut m, mut b) = peg_at([0.0, -2e-3, theta]);
    hold(&mut m, &mut b, [-1e-3, -3e-3, theta], 5000);
    let (tm, tb) = (m.truth(), b.truth());
    let two = |s: ContactState| {
        matches!(
            s,
            ContactState::TwoPoint | ContactState::Jammed | ContactState::Wedged
        )
    };
    assert!(
        two(tm.state) && two(tb.state),
        "{:?} vs {:?}",
        tm.state,
        tb.state
    );
    let (lm, lb) = (tm.edge_along_peg_m.unwrap(), tb.edge_along_peg_m.unwrap());
    assert!((lm - lb).abs() < 0.05 * lb, "{lm} vs {lb}");
}
