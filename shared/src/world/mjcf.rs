//! The MJCF model afs writes for MuJoCo from the same set-up as its own plant
//! (docs/mujoco.md, *The generated model*): the thesis's arm (link lengths, masses and
//! inertias of [`ArmParams`]), a contact sphere at the tool tip, and the surface as boxes whose
//! top faces are the surface's segments on a mocap body placed at the surface frame, so that
//! moving the surface moves the body. A curved profile (the sinusoid of fig. 5.6) is one box
//! whose face the world keeps tangent to the curve at the point nearest the tool, every step:
//! one contact, at the true distance. A height field or chords would touch the sphere at two
//! or more places at once, each a full contact spring (MuJoCo's contacts do not share a
//! load): 6.0 N instead of the 2.5 N preload at fig. 5.6's start, measured.
//!
//! Contact: MuJoCo's soft constraint with solimp's dmin = dmax = d and solref's direct form
//! (−stiffness, −damping). At rest, the contact force is `aref / R` with
//! `aref = −(|s₀|/d) r` and `R = (1 − d)/d · w` (w: the tool body's translational
//! `body_invweight0`), so the contact is a spring of `|s₀| / ((1 − d) w)` N/m: setting
//! `s₀ = −k_e (1 − d) w` and `s₁ = −b (1 − d) w` gives the set-up's k_e and damping b
//! ([`direct_solref`]; the test in `mujoco.rs` measures it). `w` is known only once MuJoCo has
//! compiled the model: the loader compiles it once with `solref = None` (a stand-in) to read
//! `w`, then the model with the solref that gives k_e.
//!
//! Friction: MuJoCo's elliptic cone with μ = F_C / F_ref (eq. 4.5's kinetic term at its
//! reference normal force); `impratio` stiffens the friction rows against creep.

use super::MujocoParams;
use crate::arm::ArmParams;
use crate::config::SimConfig;
use crate::surface::{Shape, Surface};
use std::fmt::Write;

/// Out-of-plane half-size of the surface boxes (m).
const BOX_HALF_DEPTH_M: f64 = 0.05;
/// Half-thickness of the surface boxes (m).
const BOX_HALF_THICKNESS_M: f64 = 0.02;
/// How far a face's box runs on past a valley's vertex, under the next face (m). Boxes that
/// end at the vertex leave their end faces a fraction of the penetration from a tool pressed
/// into the valley; MuJoCo's sphere–box contact then pushes the sphere out through the nearest
/// face, the end, and a small tool squeezes between the boxes (docs/mujoco.md, *corners*).
const VALLEY_OVERLAP_M: f64 = 0.002;

/// Names the loader and the servo find in every model (generated or the user's).
pub mod names {
    /// The tool's site (its tip).
    pub const TOOL_SITE: &str = "tool";
    /// The tool's contact geom (generated models).
    pub const TOOL_GEOM: &str = "tool";
    /// The body holding the surface.
    pub const SURFACE_BODY: &str = "surface";
}

/// A link as one MuJoCo body: mass, centre of mass from its joint (m) and inertia about that
/// centre (kg·m²), the rotor's inertia and the point masses at its end folded in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyInertia {
    /// Total mass (kg).
    pub mass_kg: f64,
    /// Centre of mass along the link from its joint (m).
    pub com_m: f64,
    /// Inertia about the centre of mass, about z (kg·m²).
    pub inertia_kg_m2: f64,
}

/// Link 1 and link 2 as MuJoCo bodies. Link 1 carries the elbow mass at l1 and rotor 1;
/// link 2 the tip mass at l2 and rotor 2 (a direct-drive rotor turns with its link). Their
/// inertias about the joints equal the built-in model's I1 and I2 (docs/model.md).
pub fn link_bodies(p: &ArmParams) -> [BodyInertia; 2] {
    let body = |m: f64, c: f64, ic: f64, rotor: f64, end_mass: f64, l: f64| {
        let total = m + end_mass;
        let com = if total > 0.0 {
            (m * c + end_mass * l) / total
        } else {
            0.0
        };
        BodyInertia {
            mass_kg: total,
            com_m: com,
            inertia_kg_m2: ic + rotor + m * (c - com).powi(2) + end_mass * (l - com).powi(2),
        }
    };
    [
        body(
            p.link1_mass_kg,
            p.link1_com_m,
            p.link1_inertia_kg_m2,
            p.rotor1_inertia_kg_m2,
            p.elbow_mass_kg,
            p.link1_length_m,
        ),
        body(
            p.link2_mass_kg,
            p.link2_com_m,
            p.link2_inertia_kg_m2,
            p.rotor2_inertia_kg_m2,
            p.tip_mass_kg,
            p.link2_length_m,
        ),
    ]
}

/// solref's direct form (−stiffness, −damping) that gives a contact of `stiffness` N/m and
/// `damping` N·s/m at impedance `d`, for a contact whose bodies' translational
/// `body_invweight0` sum to `invweight` (module docs).
pub fn direct_solref(stiffness: f64, damping: f64, d: f64, invweight: f64) -> [f64; 2] {
    [
        -stiffness * (1.0 - d) * invweight,
        -damping * (1.0 - d) * invweight,
    ]
}

/// The solver references (normal, friction) of a contact of static stiffness `stiffness`
/// (N/m) and damping `damping` (N·s/m) with the friction damping and impedance of `m`, on a
/// body whose `body_invweight0` is `invweight`: the generated box's and peg's contacts.
pub fn contact_solrefs(
    stiffness: f64,
    damping: f64,
    m: &MujocoParams,
    invweight: f64,
) -> [[f64; 2]; 2] {
    let (d, fd) = (m.impedance, m.friction_damping_n_s_per_m);
    [
        direct_solref(stiffness, damping, d, invweight),
        direct_solref(fd, fd, d, invweight),
    ]
}

/// The segments (u₀, h₀, u₁, h₁) of the surface profile over |u| ≤ half length: a plane's one,
/// a polyline's own (the end ones cut there). A curved profile is one plane too, which the
/// world keeps tangent to the curve at the point nearest the tool (module docs).
pub fn segments(surface: &Surface, p: &MujocoParams) -> Vec<[f64; 4]> {
    let half = p.surface_half_length_m;
    match &surface.shape {
        Shape::Plane | Shape::Sinusoid { .. } => vec![[-half, 0.0, half, 0.0]],
        Shape::Polyline { vertices } => {
            let last = vertices.len() - 1;
            let mut out = Vec::with_capacity(last);
            for i in 0..last {
                let (mut a, mut b) = (vertices[i], vertices[i + 1]);
                let slope = (b[1] - a[1]) / (b[0] - a[0]);
                if i == 0 && a[0] > -half {
                    a = [-half, a[1] + slope * (-half - a[0])];
                }
                if i == last - 1 && b[0] < half {
                    b = [half, a[1] + slope * (half - a[0])];
                }
                out.push([a[0], a[1], b[0], b[1]]);
            }
            out
        }
    }
}

/// The contact's solver references, both in the direct form: the normal's (−stiffness,
/// −damping) and the friction's (−, −tangential damping).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactSolref {
    /// Normal direction.
    pub normal: [f64; 2],
    /// Friction directions (`solreffriction`).
    pub friction: [f64; 2],
}

/// The MJCF of the set-up with the contacts' solver references (None: a stand-in, module
/// docs).
pub fn generate(cfg: &SimConfig, solref: Option<ContactSolref>) -> String {
    let p = &cfg.plant;
    let m = &cfg.world.mujoco;
    let [b1, b2] = link_bodies(&p.arm);
    let mu = p.friction.kinetic_n / p.reference_normal_force_n;
    let d = m.impedance;
    let mut x = String::with_capacity(64 * 1024);
    // Writing to a String cannot fail.
    let _ = writeln!(
        x,
        "<mujoco model=\"afs\">\n  <compiler angle=\"radian\" inertiafromgeom=\"false\"/>\n  \
         <option timestep=\"{dt:e}\" gravity=\"0 0 0\" cone=\"{cone}\" impratio=\"{imp}\" \
         noslip_iterations=\"{noslip}\" \
         integrator=\"Euler\"/>\n  <default>\n    <geom contype=\"0\" conaffinity=\"0\"/>\n  \
         </default>\n  <worldbody>",
        dt = cfg.servo.dt(),
        imp = m.impratio,
        cone = if m.pyramidal { "pyramidal" } else { "elliptic" },
        noslip = m.noslip_iterations,
    );
    let sr = solref.unwrap_or(ContactSolref {
        normal: [-1.0, -1.0],
        friction: [-1.0, -1.0],
    });
    let [d1, d2] = p.arm.joint_damping_nms_per_rad;
    let inertial = |b: &BodyInertia| {
        // A planar arm turns about z only; x and y equal to z keep MuJoCo's triangle rule.
        let i = b.inertia_kg_m2.max(1e-9);
        format!(
            "<inertial pos=\"{} 0 0\" mass=\"{}\" diaginertia=\"{i} {i} {i}\"/>",
            b.com_m,
            b.mass_kg.max(1e-9)
        )
    };
    let _ = writeln!(
        x,
        "    <body name=\"link1\">\n      <joint name=\"joint1\" type=\"hinge\" axis=\"0 0 1\" \
         damping=\"{d1}\"/>\n      {}\n      <body name=\"link2\" pos=\"{l1} 0 0\">\n        \
         <joint name=\"joint2\" type=\"hinge\" axis=\"0 0 1\" damping=\"{d2}\"/>\n        {}\n        \
         <geom name=\"{tool}\" type=\"sphere\" size=\"{r}\" pos=\"{l2} 0 0\" />\n        \
         <site name=\"{tool}\" pos=\"{l2} 0 0\"/>\n      </body>\n    </body>",
        inertial(&b1),
        inertial(&b2),
        l1 = p.arm.link1_length_m,
        l2 = p.arm.link2_length_m,
        r = m.tool_radius_m,
        tool = names::TOOL_SITE,
    );
    let f = &cfg.surface.frame;
    let _ = writeln!(
        x,
        "    <body name=\"{}\" mocap=\"true\" pos=\"{} {} 0\" euler=\"0 0 {}\">",
        names::SURFACE_BODY,
        f.origin_m[0],
        f.origin_m[1],
        f.angle_rad
    );
    let segs = segments(&cfg.surface, m);
    let angles: Vec<f64> = segs
        .iter()
        .map(|s| (s[3] - s[1]).atan2(s[2] - s[0]))
        .collect();
    // A valley (the surface turns up) at a segment's start or end: its box runs on under the
    // next face.
    let valley = |a: usize, b: usize| angles[b] > angles[a];
    for (i, s) in segs.iter().enumerate() {
        let [u0, h0, u1, h1] = *s;
        let len = (u1 - u0).hypot(h1 - h0);
        let angle = angles[i];
        let before = if i > 0 && valley(i - 1, i) {
            VALLEY_OVERLAP_M
        } else {
            0.0
        };
        let after = if i + 1 < segs.len() && valley(i, i + 1) {
            VALLEY_OVERLAP_M
        } else {
            0.0
        };
        // The box's top face is the segment moved inward (−normal) by the tool's radius.
        let (tx, ty) = (angle.cos(), angle.sin());
        let (nx, ny) = (-ty, tx);
        let inset = m.tool_radius_m + BOX_HALF_THICKNESS_M;
        let along = 0.5 * (len + after - before);
        let cx = u0 + tx * along - nx * inset;
        let cy = h0 + ty * along - ny * inset;
        let _ = writeln!(
            x,
            "      <geom name=\"face{i}\" type=\"box\" size=\"{} {BOX_HALF_THICKNESS_M} \
             {BOX_HALF_DEPTH_M}\" pos=\"{cx} {cy} 0\" euler=\"0 0 {angle}\"/>",
            0.5 * (len + before + after)
        );
    }
    x.push_str("    </body>\n  </worldbody>\n  <contact>\n");
    // Explicit pairs: the tool against each face, with the friction's own reference.
    for i in 0..segs.len() {
        let _ = writeln!(
            x,
            "    <pair geom1=\"{}\" geom2=\"face{i}\" condim=\"3\" friction=\"{mu} {mu} 0 0 0\" \
             solref=\"{:e} {:e}\" solreffriction=\"{:e} {:e}\" solimp=\"{d} {d} 0.001 0.5 2\"/>",
            names::TOOL_GEOM,
            sr.normal[0],
            sr.normal[1],
            sr.friction[0],
            sr.friction[1],
        );
    }
    x.push_str("  </contact>\n</mujoco>\n");
    x
}

/// The three-joint arm of [`Scara`](crate::insertion::scara::Scara) as MJCF, for checking
/// MuJoCo's dynamics of it against the closed form (docs/insertion-arm.md): links 1 and
/// 2 as [`link_bodies`] makes them, the wrist link a third body on a hinge at link 2's end with
/// its mass at `com_m` and its inertia, the site `tool` at its tool point; each joint's
/// viscous damping `damping_nms_per_rad` (N·m·s/rad). No gravity, no contact: the peg rides in
/// the wrist's compliance, outside this model ([`MujocoArm`](crate::world::MujocoArm)).
pub fn scara(
    arm: &ArmParams,
    wrist: &crate::insertion::scara::WristParams,
    damping_nms_per_rad: [f64; 3],
    dt: f64,
) -> String {
    let [b1, b2] = link_bodies(arm);
    let body = |(name, pos, b, damping): (&str, f64, &BodyInertia, f64)| {
        let i = b.inertia_kg_m2.max(1e-9);
        format!(
            "<body name=\"{name}\" pos=\"{pos} 0 0\"><joint name=\"{name}\" type=\"hinge\" \
             axis=\"0 0 1\" damping=\"{damping:e}\"/><inertial pos=\"{} 0 0\" mass=\"{}\" \
             diaginertia=\"{i} {i} {i}\"/>",
            b.com_m,
            b.mass_kg.max(1e-9)
        )
    };
    let [d1, d2, d3] = damping_nms_per_rad;
    let w = BodyInertia {
        mass_kg: wrist.mass_kg,
        com_m: wrist.com_m,
        inertia_kg_m2: wrist.inertia_kg_m2,
    };
    format!(
        "<mujoco model=\"afs-scara\">\n  <compiler angle=\"radian\" inertiafromgeom=\"false\"/>\n  \
         <option timestep=\"{dt:e}\" gravity=\"0 0 0\" integrator=\"Euler\">\
         <flag contact=\"disable\" constraint=\"disable\"/></option>\n  <worldbody>\n    \
         {}{}{}<site name=\"{}\" pos=\"{} 0 0\"/></body></body></body>\n  </worldbody>\n</mujoco>\n",
        body(("link1", 0.0, &b1, d1)),
        body(("link2", arm.link1_length_m, &b2, d2)),
        body(("wrist", arm.link2_length_m, &w, d3)),
        names::TOOL_SITE,
        wrist.length_m,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arm::Arm;

    /// The two bodies have the built-in model's inertias about the joints (parallel axes).
    #[test]
    fn link_bodies_match_the_arm_model() {
        let p = ArmParams::default();
        let [b1, b2] = link_bodies(&p);
        let i1 = b1.inertia_kg_m2 + b1.mass_kg * b1.com_m.powi(2);
        let i2 = b2.inertia_kg_m2 + b2.mass_kg * b2.com_m.powi(2);
        let arm = Arm::new(p);
        // M22 = I2; M11 at q2 = π/2 (cos q2 = 0) = I1 + m2' l1² + I2.
        let m = arm.mass_matrix(nalgebra::Vector2::new(0.0, std::f64::consts::FRAC_PI_2));
        assert!((m[(1, 1)] - i2).abs() < 1e-12, "{} vs {i2}", m[(1, 1)]);
        let m11 = i1 + b2.mass_kg * p.link1_length_m.powi(2) + i2;
        assert!((m[(0, 0)] - m11).abs() < 1e-12, "{} vs {m11}", m[(0, 0)]);
        // β = l1 × first moment of link 2 and tip: M12 at q2 = 0 is I2 + β.
        let m0 = arm.mass_matrix(nalgebra::Vector2::zeros());
        let beta = p.link1_length_m * b2.mass_kg * b2.com_m;
        assert!((m0[(0, 1)] - (i2 + beta)).abs() < 1e-12);
    }

    #[test]
    fn direct_solref_scales_with_the_regularisation() {
        let [s0, s1] = direct_solref(1e4, 50.0, 0.9, 0.0628);
        assert!((s0 + 1e4 * 0.1 * 0.0628).abs() < 1e-9);
        assert!((s1 + 50.0 * 0.1 * 0.0628).abs() < 1e-12);
    }

    /// A polyline keeps its corners and has its end segments cut at the surface's ends.
    #[test]
    fn polyline_keeps_its_corners() {
        let mut cfg = SimConfig::default();
        cfg.surface.shape = Shape::Polyline {
            vertices: vec![[-0.05, 0.0], [0.0, 0.01], [0.05, 0.0]],
        };
        let segs = segments(&cfg.surface, &cfg.world.mujoco);
        assert_eq!(segs.len(), 2);
        assert_eq!(segs[0][2..], [0.0, 0.01]);
        assert!((segs[0][0] + 0.25).abs() < 1e-12 && (segs[0][1] + 0.04).abs() < 1e-12);
        assert!((segs[1][2] - 0.25).abs() < 1e-12 && (segs[1][3] + 0.04).abs() < 1e-12);
        let xml = generate(&cfg, None);
        assert_eq!(xml.matches("type=\"box\"").count(), 2);
        assert!(xml.contains("name=\"tool\""));
    }
}
