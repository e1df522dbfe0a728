//! The insertion controller's unit tests.

use super::*;

const WRIST: [f64; 3] = [2e3, 2e3, 5.0];

fn at(force: [f64; 2], moment_nm: f64, tip: [f64; 3]) -> Input {
    Input {
        force,
        moment_nm,
        tip,
    }
}

fn started(method: Method) -> Controller {
    started_with(ControllerParams::default(), method)
}

fn started_with(params: ControllerParams, method: Method) -> Controller {
    let mut c = Controller::new(params, method, WRIST, [0.0, 1e-3, 0.0], 0.5e-3);
    // Contact: the approach ends where the peg is, without the wrist's lead.
    let (target, _) = c.step(&at([0.0, 0.6], 0.0, [0.0, -1e-5, 0.0]), 1e-4);
    assert_eq!(c.phase(), Phase::Find);
    assert!((target[1] + 1e-5).abs() < 1e-6, "{target:?}");
    c
}

#[test]
fn methods_parse_by_name() {
    for m in Method::ALL {
        assert_eq!(Method::parse(m.name()), Some(m));
    }
    assert_eq!(Method::parse("spiral"), None);
}

/// Pressed on the part with the centre of pressure 3 mm to the right of the tip, the peg
/// walks left (towards the unsupported side), at the walk speed; 3 mm to the left, right.
#[test]
fn the_walk_goes_away_from_the_support() {
    for (x_c, sign) in [(3e-3, -1.0), (-3e-3, 1.0)] {
        let mut c = started(Method::NoDither);
        let f = 2.0;
        let before = c.target;
        c.step(&at([0.0, f], x_c * f, [0.0, -1e-5, 0.0]), 1e-3);
        let moved = c.target[0] - before[0];
        let want = sign * ControllerParams::default().walk_m_per_s * 1e-3;
        assert!((moved - want).abs() < 1e-12, "{x_c}: {moved} vs {want}");
    }
}

/// Pressed on the face tilted 1° either way (the part's frame known), the peg is turned square
/// to the face at the tilt loop's rate, capped at the largest tilt rate, all but the kept
/// 0.5° of the tilt; within the kept tilt it is turned out to it on the side it leans, and a
/// square peg counter-clockwise.
#[test]
fn finding_the_hole_squares_the_peg_to_the_face() {
    let p = ControllerParams::default();
    let kept = p.kept_tilt_deg;
    for (tilt_deg, want) in [
        (1.0f64, -p.max_tilt_rate_rad_per_s),
        (-1.0, p.max_tilt_rate_rad_per_s),
        (
            kept + 0.1,
            -std::f64::consts::TAU * p.tilt_bandwidth_hz * 0.1f64.to_radians(),
        ),
        (
            0.8 * kept,
            std::f64::consts::TAU * p.tilt_bandwidth_hz * (0.2 * kept).to_radians(),
        ),
        (
            -0.8 * kept,
            -std::f64::consts::TAU * p.tilt_bandwidth_hz * (0.2 * kept).to_radians(),
        ),
        (
            0.0,
            (std::f64::consts::TAU * p.tilt_bandwidth_hz * kept.to_radians())
                .min(p.max_tilt_rate_rad_per_s),
        ),
    ] {
        assert_turned(started(Method::NoDither), tilt_deg, want);
    }
}

/// Pressed on the face at `tilt_deg` in the find phase, `c` turns the peg at `want` (rad/s).
fn assert_turned(mut c: Controller, tilt_deg: f64, want: f64) {
    let before = c.target[2];
    c.step(
        &at([0.0, 1.0], 0.0, [0.0, -1e-5, tilt_deg.to_radians()]),
        1e-3,
    );
    let turned = (c.target[2] - before) / 1e-3;
    assert!(
        (turned - want).abs() < 1e-12,
        "{tilt_deg}°: {turned} vs {want}"
    );
}

/// With the part's orientation unknown and the face's line not yet found, a peg within the
/// kept tilt of the face it believes is left as it is (its tilt against the true face is not
/// known), and one tilted more is still squared down to it.
#[test]
fn a_peg_whose_tilt_is_not_known_is_not_tilted_out() {
    let mut p = ControllerParams::default();
    p.face.estimate = true;
    let kept = p.kept_tilt_deg;
    for (tilt_deg, want) in [
        (0.8 * kept, 0.0),
        (0.0, 0.0),
        (1.0, -p.max_tilt_rate_rad_per_s),
    ] {
        assert_turned(started_with(p, Method::NoDither), tilt_deg, want);
    }
}

/// Contact lost for longer than `contact_lost_s`: once, the lead across the axis comes off
/// (the commanded pose jumps to the peg) and the lead along it is cut back to `lead_kept_m`,
/// then the commanded pose goes down at the approach speed.
#[test]
fn a_lost_contact_cuts_the_lead_back_once() {
    let mut c = started(Method::Dither);
    let p = ControllerParams::default();
    c.target = [1e-3, -2e-3, 0.0];
    let tip = [0.0, -0.4e-3, 0.0];
    let dt = 1e-4;
    let ticks = (p.contact_lost_s / dt).round() as usize;
    for _ in 0..ticks - 1 {
        c.step(&at([0.0, 0.0], 0.0, tip), dt);
    }
    assert!(c.target[1] < -1e-3, "not yet: {:?}", c.target);
    c.step(&at([0.0, 0.0], 0.0, tip), dt);
    assert!((c.target[0] - tip[0]).abs() < 1e-12);
    assert!(
        (c.target[1] - (tip[1] - p.lead_kept_m - p.approach_m_per_s * dt)).abs() < 1e-12,
        "{:?}",
        c.target
    );
    c.step(&at([0.0, 0.0], 0.0, tip), dt);
    let want = tip[1] - p.lead_kept_m - 2.0 * p.approach_m_per_s * dt;
    assert!((c.target[1] - want).abs() < 1e-12);
}

/// Past the chamfer the peg is in the hole: the dither method aligns before it inserts,
/// the search goes straight in.
#[test]
fn in_the_hole_dither_aligns_and_search_inserts() {
    let deep = [0.0, -1.2e-3, 0.0];
    let mut c = started(Method::Dither);
    c.step(&at([0.0, 2.0], 0.0, deep), 1e-4);
    assert_eq!(c.phase(), Phase::Align);
    // Aligned: a moment below a tenth of r F_y for 0.1 s.
    for _ in 0..1001 {
        c.step(&at([0.0, 1.0], 1e-4, deep), 1e-4);
    }
    assert_eq!(c.phase(), Phase::Insert);
    let mut s = started(Method::Search);
    s.step(&at([0.0, 2.0], 0.0, deep), 1e-4);
    assert_eq!(s.phase(), Phase::Insert);
}

/// In the align phase, a peg whose tip face's higher end rests on the part (the centre of
/// pressure 4.5 mm out, the lateral force small) with that end not in the bore is back on the
/// face: it finds the hole again. The same wrench with the peg in the bore (a two-point
/// contact's couple can put the centre of pressure there), or a chamfer's push (the lateral
/// force as large as the axial), leaves it aligning.
#[test]
fn a_peg_back_on_the_edge_finds_the_hole_again() {
    let p = ControllerParams::default();
    let deep = [0.0, -1.2e-3, 0.0];
    // The chamfer 0.5 mm deep; tilted 1.4°, the tip's centre 0.6 mm down: its higher corner
    // 0.12 mm above the centre, 0.48 mm down, above the chamfer's bottom.
    let on_edge = [0.0, -0.6e-3, 1.4f64.to_radians()];
    let f = 1.0;
    for (force, tip, want) in [
        ([0.05, f], on_edge, Phase::Find),
        ([0.05, f], deep, Phase::Align),
        ([0.8, f], on_edge, Phase::Align),
        ([0.05, f], [0.0, -0.65e-3, 0.0], Phase::Align),
    ] {
        let mut c = started(Method::Dither);
        c.step(&at([0.0, 2.0], 0.0, deep), 1e-4);
        assert_eq!(c.phase(), Phase::Align);
        c.step(&at(force, 0.9 * 0.5 * p.peg_width_m * f, tip), 1e-4);
        assert_eq!(c.phase(), want, "{force:?} at {tip:?}");
    }
}
