use super::*;

fn limits() -> GuardLimits {
    GuardLimits {
        contact_force_n: 30.0,
        workspace_m: [[-0.15, 0.15], [-0.1, 0.2], [-0.05, 0.05]],
    }
}

fn at(x: f64, y: f64, theta: f64, normal: f64) -> PlanarState {
    PlanarState {
        position_m: Vector2::new(x, y),
        theta_rad: theta,
        normal_m: normal,
        ..Default::default()
    }
}

#[test]
fn limits_that_are_not_a_box_or_a_force_are_refused_by_name() {
    for f in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let l = GuardLimits {
            contact_force_n: f,
            ..limits()
        };
        let e = Guard::new(l).unwrap_err();
        assert!(
            matches!(e, GuardError::Force(v) if v.to_bits() == f.to_bits()),
            "{e:?}"
        );
        assert!(e.to_string().contains("contact_force_n"), "{e}");
    }
    for (axis, bad) in [(0, [0.1, 0.1]), (1, [0.2, -0.1]), (2, [f64::NAN, 0.05])] {
        let mut l = limits();
        l.workspace_m[axis] = bad;
        let e = Guard::new(l).unwrap_err();
        let GuardError::Range { axis: a, .. } = e else {
            panic!("{e:?}");
        };
        assert_eq!(a, PlaneAxis::ALL[axis]);
        assert!(e.to_string().contains(a.name()), "{e}");
    }
    assert!(Guard::new(limits()).is_ok());
}

#[test]
fn inside_the_box_and_at_the_limit_it_lets_the_cycle_through() {
    let mut g = Guard::new(limits()).unwrap();
    // On every face, and a force exactly at the limit.
    for s in [
        at(0.0, 0.0, 0.3, 0.0),
        at(-0.15, 0.2, -1.0, 0.05),
        at(0.15, -0.1, 2.0, -0.05),
    ] {
        let f = Vector3::new(18.0, 0.0, 24.0);
        assert_eq!(f.norm(), 30.0);
        assert_eq!(g.check(&s, Some(&f)), None, "{s:?}");
        assert_eq!(g.check(&s, None), None);
    }
    assert_eq!(g.tripped(), None);
}

/// A tool whose first pose is outside the box (an arm started away from the task plane) trips
/// the guard and is held where it is, not pulled to the face, which may be far.
#[test]
fn a_tool_that_starts_outside_the_box_is_held_where_it_is() {
    let mut g = Guard::new(limits()).unwrap();
    let s = at(0.0, 0.0, 0.1, 0.32);
    let (trip, hold) = g.check(&s, None).expect("a trip");
    assert!(matches!(
        trip,
        Trip::Workspace {
            axis: PlaneAxis::Normal,
            ..
        }
    ));
    assert_eq!(hold, HoldPose::of(&s));
}

#[test]
fn leaving_the_box_holds_on_the_face_it_crossed() {
    for (s, axis, at_m) in [
        (at(0.16, 0.0, 0.1, 0.0), PlaneAxis::X, 0.16),
        (at(-0.2, 0.0, 0.1, 0.0), PlaneAxis::X, -0.2),
        (at(0.0, 0.25, 0.1, 0.0), PlaneAxis::Y, 0.25),
        (at(0.0, -0.11, 0.1, 0.0), PlaneAxis::Y, -0.11),
        (at(0.0, 0.0, 0.1, 0.051), PlaneAxis::Normal, 0.051),
        (at(0.0, 0.0, 0.1, -0.06), PlaneAxis::Normal, -0.06),
    ] {
        let mut g = Guard::new(limits()).unwrap();
        assert_eq!(g.check(&at(0.0, 0.0, 0.1, 0.0), None), None);
        let (trip, hold) = g.check(&s, Some(&Vector3::zeros())).expect("a trip");
        let range_m = limits().workspace_m[axis as usize];
        assert_eq!(
            trip,
            Trip::Workspace {
                axis,
                at_m,
                range_m
            }
        );
        // The crossed coordinate is held on the face; the others and θ where they were.
        let mut want = HoldPose::of(&s);
        *want.coordinate_mut(axis) = at_m.clamp(range_m[0], range_m[1]);
        assert_eq!(hold, want);
        assert!(trip.to_string().contains(axis.name()), "{trip}");
    }
    // Out on two axes: the first named, both clamped.
    let mut g = Guard::new(limits()).unwrap();
    assert_eq!(g.check(&at(0.0, 0.0, 0.1, 0.0), None), None);
    let (trip, hold) = g.check(&at(0.3, -0.3, 0.0, 0.0), None).unwrap();
    assert!(matches!(
        trip,
        Trip::Workspace {
            axis: PlaneAxis::X,
            ..
        }
    ));
    assert_eq!(hold.position_m, Vector2::new(0.15, -0.1));
}

#[test]
fn a_force_over_the_limit_holds_where_it_tripped_until_released() {
    let mut g = Guard::new(limits()).unwrap();
    let s = at(0.01, 0.02, 0.4, -0.001);
    assert_eq!(g.check(&s, Some(&Vector3::new(0.0, 0.0, 29.9))), None);
    let over = Vector3::new(3.0, 0.0, 30.0);
    let (trip, hold) = g.check(&s, Some(&over)).expect("a trip");
    assert_eq!(
        trip,
        Trip::ContactForce {
            force_n: over.norm(),
            limit_n: 30.0
        }
    );
    assert_eq!(hold, HoldPose::of(&s));
    assert!(trip.to_string().contains("contact_force_n"), "{trip}");
    // Latched: a good cycle after it changes nothing, until the release.
    let later = at(0.0, 0.0, 0.0, 0.0);
    assert_eq!(g.check(&later, Some(&Vector3::zeros())), Some((trip, hold)));
    assert_eq!(g.tripped(), Some((trip, hold)));
    g.release();
    assert_eq!(g.check(&later, Some(&Vector3::zeros())), None);
}

#[test]
fn a_value_that_is_not_a_number_holds_the_last_pose_that_was() {
    let good = at(0.01, 0.02, 0.4, -0.001);
    for (bad, force, what) in [
        (at(f64::NAN, 0.0, 0.0, 0.0), None, "tool's pose"),
        (at(0.0, 0.0, f64::INFINITY, 0.0), None, "tool's pose"),
        (at(0.0, 0.0, 0.0, f64::NAN), None, "tool's pose"),
        (
            at(0.0, 0.0, 0.0, 0.0),
            Some(Vector3::new(0.0, f64::NAN, 1.0)),
            "contact force",
        ),
    ] {
        let mut g = Guard::new(limits()).unwrap();
        assert_eq!(g.check(&good, None), None);
        let (trip, hold) = g.check(&bad, force.as_ref()).expect("a trip");
        assert_eq!(trip, Trip::NotFinite { what });
        assert_eq!(hold, HoldPose::of(&good));
        assert!(trip.to_string().contains(what));
    }
    // Not a number on the first cycle: held at the plane's origin.
    let mut g = Guard::new(limits()).unwrap();
    let (_, hold) = g.check(&at(f64::NAN, 0.0, 0.0, 0.0), None).unwrap();
    assert_eq!(hold, HoldPose::default());
}

/// The contact-force hold, closed form (module docs): a tool of mass m pressed into a contact
/// of stiffness k_e at x_c by a force that ramps up until the guard trips at F₀, then held by
/// the impedance k_h, d at the pose where it tripped, settles where the hold's spring and the
/// contact balance: `k_h (x₀ − x) = k_e (x − x_c)`, a contact force of `F₀ k_h / (k_h + k_e)`.
#[test]
fn the_contact_force_hold_relaxes_the_force_by_the_stiffnesses_in_series() {
    let (m, k_e, x_c, dt): (f64, f64, f64, f64) = (2.0, 1e5, 0.01, 1e-4);
    for k_h in [2e3_f64, 2e4, 1e5] {
        let d = 2.0 * (m * (k_h + k_e)).sqrt();
        let mut g = Guard::new(limits()).unwrap();
        let (mut x, mut v, mut t): (f64, f64, f64) = (x_c, 0.0, 0.0);
        let mut tripped_at = None;
        for _ in 0..200_000 {
            let contact = k_e * (x - x_c).max(0.0);
            let s = at(x, 0.0, 0.0, 0.0);
            let f = Vector3::new(contact, 0.0, 0.0);
            let push = match g.check(&s, Some(&f)) {
                None => 10.0 + 100.0 * t - d * v,
                Some((_, hold)) => {
                    tripped_at.get_or_insert(contact);
                    -k_h * (x - hold.position_m.x) - d * v
                }
            };
            v += (push - contact) / m * dt;
            x += v * dt;
            t += dt;
        }
        let f0 = tripped_at.expect("a trip");
        assert!(f0 > 30.0 && f0 < 30.5, "{f0}");
        let settled = k_e * (x - x_c).max(0.0);
        let want = f0 * k_h / (k_h + k_e);
        assert!(
            (settled - want).abs() < 1e-3 * want,
            "k_h {k_h}: {settled} vs {want}"
        );
    }
}
