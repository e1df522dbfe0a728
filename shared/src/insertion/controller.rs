//! The insertion controller (docs/insertion.md, *The controller*): a hybrid force/position
//! controller on the wrist's commanded pose, one call per servo tick, no allocation.
//!
//! Methods:
//! * `dither` (afs): approach; press with force control along the hole's axis; comply in θ
//!   (the moment about the tip nulled) and in x (the lateral force nulled), and walk x towards
//!   the side of the tip that the part does not support (the centre of pressure of the contact
//!   force, from the wrist's force/torque sensor, is on the supported side); in the hole, the
//!   same loops keep the wrench at the centre of Whitney's parallelogram (F_x = 0, M = 0) while
//!   the insertion force pushes, and a dither along the axis suppresses the friction.
//! * `no-dither`: the same without the dither.
//! * `search`: the industrial force-control packages' search: a constant insertion force, a
//!   lateral sweep of growing amplitude about the start, passive compliance only (the wrist's),
//!   no estimation.

use super::face::{FaceParams, FaceProbe, FaceState};
use crate::math::turn;
use serde::{Deserialize, Serialize};

/// Which controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Hybrid force/moment control, centre-of-pressure search, dither.
    #[default]
    Dither,
    /// The same without the dither.
    NoDither,
    /// Constant force and a lateral sweep, passive compliance.
    Search,
}

impl Method {
    /// Its command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Method::Dither => "dither",
            Method::NoDither => "no-dither",
            Method::Search => "search",
        }
    }

    /// The three, the dither method first.
    pub const ALL: [Method; 3] = [Method::Dither, Method::NoDither, Method::Search];

    /// From its command-line name.
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == s)
    }
}

/// The controller's phase.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Moving down to the part.
    #[default]
    Approach,
    /// Pressing on the part, finding the hole.
    Find,
    /// In the hole, held lightly while the moment and lateral loops align the peg with it.
    Align,
    /// In the hole, going in.
    Insert,
    /// At depth.
    Done,
}

/// Settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControllerParams {
    /// Approach speed (m/s).
    pub approach_m_per_s: f64,
    /// Contact force that ends the approach (N).
    pub contact_n: f64,
    /// Contact force below which the peg has lost its support (N), for at least (s).
    pub contact_lost_n: f64,
    /// How long the force must stay below `contact_lost_n` (s).
    pub contact_lost_s: f64,
    /// A lead of the commanded pose on the peg longer than this is cut when the contact is
    /// lost while finding the hole (m): across the axis to nothing, along it back to
    /// `lead_kept_m`.
    pub lead_snap_m: f64,
    /// The lead along the axis kept when the contact is lost (m): a peg that dropped into the
    /// hole stays pressed into it.
    pub lead_kept_m: f64,
    /// Force along the axis while finding the hole (N): light, so friction does not hold the
    /// walk.
    pub find_force_n: f64,
    /// Centre of pressure closer to the tip's centre than this: no side to walk to (m).
    pub centred_m: f64,
    /// Force along the axis while aligning in the hole (N).
    pub align_force_n: f64,
    /// Normalised moment |M|/(r F_y) below which the peg counts as aligned.
    pub aligned_moment: f64,
    /// For how long (s).
    pub aligned_s: f64,
    /// Longest alignment (s).
    pub align_timeout_s: f64,
    /// Peg width d, for the normalised moment (m).
    pub peg_width_m: f64,
    /// Insertion force F_z (N).
    pub insertion_force_n: f64,
    /// Force loop bandwidth along the axis (Hz).
    pub force_bandwidth_hz: f64,
    /// Lateral force loop bandwidth (Hz).
    pub lateral_bandwidth_hz: f64,
    /// Moment loop bandwidth (Hz).
    pub moment_bandwidth_hz: f64,
    /// Largest speed of the commanded pose along the axis and across it (m/s): an impact at v
    /// on the part's contact stiffness k_c is a force of about v √(k_c m).
    pub max_speed_m_per_s: f64,
    /// Largest rate of the commanded tilt (rad/s).
    pub max_tilt_rate_rad_per_s: f64,
    /// Least bound on the lead of the commanded pose on the peg while walking (m).
    pub walk_lead_m: f64,
    /// The lead's bound as a multiple of the lead that pulls the press's friction μ F.
    pub walk_lead_over_friction: f64,
    /// The friction coefficient μ as identified (friction-id, fig. 4.6).
    pub mu: f64,
    /// Lateral walk speed towards the unsupported side at full offset (m/s).
    pub walk_m_per_s: f64,
    /// Depth past which the peg is in the hole, for the search: its tip's centre this far below
    /// the chamfer (m).
    pub in_hole_m: f64,
    /// Depth past which the peg is in the bore, for the dither and no-dither methods: the tip
    /// face's higher corner (the peg tilted as measured) this far below the chamfer (m). The
    /// alignment must start before the two-point contact forms, l₂ = (D − d cos θ)/sin θ into
    /// the bore: 0.14 mm at c = 0.0005 and 2° (docs/insertion.md).
    pub in_bore_m: f64,
    /// Depth at which the insertion is done (m).
    pub target_depth_m: f64,
    /// Dither amplitude along the axis (m) and frequency (Hz).
    pub dither_m: f64,
    /// Dither frequency (Hz).
    pub dither_hz: f64,
    /// Search: sweep frequency (Hz), amplitude growth (m/s) and largest amplitude (m).
    pub search_hz: f64,
    /// Search amplitude growth (m/s).
    pub search_growth_m_per_s: f64,
    /// Search's largest amplitude (m).
    pub search_max_m: f64,
    /// Bandwidth of the loop that turns the peg square to the face as estimated, while
    /// finding the hole (Hz).
    pub tilt_bandwidth_hz: f64,
    /// The tilt against the face's normal the find phase turns the peg to, its sign the peg's
    /// (degrees; a peg exactly square goes counter-clockwise): a square peg walked off a
    /// sharp edge drops flat onto the far edge, a tilted one enters corner first. A peg tilted
    /// less is tilted up to it, not left as it is: at 0.26–0.42° the trailing corner, lower,
    /// dropped the peg onto the far edge over the force limit on the arm (docs/insertion.md,
    /// *The arm*). With the part's orientation unknown and the face's line not found, the
    /// tilt against the face is not known and a tilt under this one is left as it is.
    pub kept_tilt_deg: f64,
    /// The face's tangent estimate.
    pub face: FaceParams,
}

impl Default for ControllerParams {
    fn default() -> Self {
        Self {
            approach_m_per_s: 0.002,
            contact_n: 0.5,
            contact_lost_n: 0.2,
            contact_lost_s: 0.5e-3,
            lead_snap_m: 0.2e-3,
            lead_kept_m: 0.15e-3,
            find_force_n: 1.0,
            centred_m: 0.3e-3,
            align_force_n: 1.0,
            aligned_moment: 0.1,
            aligned_s: 0.1,
            align_timeout_s: 1.5,
            peg_width_m: 0.01,
            insertion_force_n: 5.0,
            force_bandwidth_hz: 5.0,
            lateral_bandwidth_hz: 3.0,
            moment_bandwidth_hz: 3.0,
            max_speed_m_per_s: 0.005,
            max_tilt_rate_rad_per_s: 0.05,
            walk_lead_m: 0.15e-3,
            walk_lead_over_friction: 1.5,
            mu: 0.3,
            walk_m_per_s: 0.002,
            in_hole_m: 0.5e-3,
            in_bore_m: 0.05e-3,
            target_depth_m: 0.015,
            dither_m: 0.1e-3,
            dither_hz: 20.0,
            search_hz: 0.3,
            search_growth_m_per_s: 1e-3,
            search_max_m: 3e-3,
            tilt_bandwidth_hz: 1.0,
            kept_tilt_deg: 0.5,
            face: FaceParams::default(),
        }
    }
}

/// What the controller reads each tick: the wrist's force/torque sensor (contact force on the
/// peg, N, and its moment about the tip, N·m, world frame) and the tip's measured pose.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Input {
    /// Force (N).
    pub force: [f64; 2],
    /// Moment about the tip (N·m).
    pub moment_nm: f64,
    /// Tip pose (m, m, rad).
    pub tip: [f64; 3],
}

/// What changes in a [`Controller`] as it runs (the rest is its settings).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ControllerState {
    /// The phase.
    pub phase: Phase,
    /// The commanded pose without the dither.
    pub target: [f64; 3],
    /// Where the lateral search is centred (m).
    pub start_x: f64,
    /// Time since the start (s).
    pub t: f64,
    /// Time in the phase (s).
    pub phase_t: f64,
    /// How long the peg has stayed aligned (s).
    pub aligned_s: f64,
    /// How long the contact force has been below the loss threshold (s).
    pub lost_s: f64,
    /// The face's tangent estimate.
    pub face: FaceState,
}

/// The controller.
#[derive(Debug, Clone)]
pub struct Controller {
    params: ControllerParams,
    method: Method,
    /// Stiffness of the wrist (k_x, k_y, k_θ): the loops' gains are bandwidth / stiffness.
    wrist: [f64; 3],
    /// The part's face height, known to the robot (m), and the depth at which the peg is in
    /// the hole.
    face_y: f64,
    in_hole_depth_m: f64,
    phase: Phase,
    target: [f64; 3],
    start_x: f64,
    t: f64,
    phase_t: f64,
    /// How long the peg has stayed aligned (s).
    aligned_s: f64,
    /// How long the contact force has been below `contact_lost_n` (s).
    lost_s: f64,
    /// The face's tangent, the robot's belief (its frame's x axis) until the line the peg's
    /// corner slides along on the face has given it (with the part's frame unknown).
    face: FaceProbe,
}

impl Controller {
    /// A controller starting from the commanded tip pose `start`, for a wrist of stiffness
    /// `wrist` and a chamfer `chamfer_depth_m` deep.
    pub fn new(
        params: ControllerParams,
        method: Method,
        wrist: [f64; 3],
        start: [f64; 3],
        chamfer_depth_m: f64,
    ) -> Self {
        Self {
            params,
            method,
            wrist,
            face_y: 0.0,
            in_hole_depth_m: chamfer_depth_m
                + if method == Method::Search {
                    params.in_hole_m
                } else {
                    params.in_bore_m
                },
            phase: Phase::Approach,
            target: start,
            start_x: start[0],
            t: 0.0,
            phase_t: 0.0,
            lost_s: 0.0,
            aligned_s: 0.0,
            face: FaceProbe::new(params.face, params.peg_width_m, 0.0),
        }
    }

    /// The phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The commanded tip pose without the dither (m, m, rad): where the wrist holds the peg
    /// when the force data fails.
    pub fn target(&self) -> [f64; 3] {
        self.target
    }

    /// What changes as it runs, for a restarted servo ([`Controller::restore`]).
    pub fn state(&self) -> ControllerState {
        ControllerState {
            phase: self.phase,
            target: self.target,
            start_x: self.start_x,
            t: self.t,
            phase_t: self.phase_t,
            aligned_s: self.aligned_s,
            lost_s: self.lost_s,
            face: self.face.state(),
        }
    }

    /// Carries on from `s`.
    pub fn restore(&mut self, s: &ControllerState) {
        self.phase = s.phase;
        self.target = s.target;
        self.start_x = s.start_x;
        self.t = s.t;
        self.phase_t = s.phase_t;
        self.aligned_s = s.aligned_s;
        self.lost_s = s.lost_s;
        self.face.restore(&s.face);
    }

    /// Depth of the tip below the face (m).
    pub fn depth_m(&self, tip_y: f64) -> f64 {
        self.face_y - tip_y
    }

    /// One tick of `dt`: the wrist's commanded pose and rate, both in the robot's frame, from
    /// `inp` in the robot's frame. The loops work in the part's frame as estimated (the robot's
    /// turned by the face's estimated tangent angle).
    pub fn step(&mut self, inp: &Input, dt: f64) -> ([f64; 3], [f64; 3]) {
        self.t += dt;
        self.phase_t += dt;
        let p = self.params;
        let pin = self.to_part(inp);
        let mut rate = [0.0; 3];
        match self.phase {
            Phase::Approach => {
                rate[1] = -p.approach_m_per_s;
                if inp.force[0].hypot(inp.force[1]) > p.contact_n {
                    // The wrist's lead on the peg would press on: start the force loop from
                    // where the peg is.
                    let along = self.robot_to_part_xy(&self.target);
                    let here = self.part_to_robot_xy([along[0], pin.tip[1]]);
                    self.target = [here[0], here[1], self.target[2]];
                    self.next(Phase::Find);
                } else if self.in_bore(&pin) {
                    // In the bore without a touch: the initial errors were inside the
                    // clearance. On from there as from the find phase.
                    self.next(self.after_find());
                }
            }
            Phase::Find | Phase::Align | Phase::Insert => rate = self.in_contact(inp, &pin, dt),
            Phase::Done => {}
        }
        let v = p.max_speed_m_per_s;
        rate[0] = rate[0].clamp(-v, v);
        rate[1] = rate[1].clamp(-v, v);
        rate[2] = rate[2].clamp(-p.max_tilt_rate_rad_per_s, p.max_tilt_rate_rad_per_s);
        let xy = self.part_to_robot_xy([rate[0], rate[1]]);
        let mut rate = [xy[0], xy[1], rate[2]];
        for (t, r) in self.target.iter_mut().zip(rate) {
            *t += r * dt;
        }
        let mut out = self.target;
        if self.method == Method::Dither
            && matches!(self.phase, Phase::Find | Phase::Align | Phase::Insert)
        {
            // Along the motion the friction resists: across the face while finding, along the
            // axis while inserting (thesis ch. 4: Aω above the nominal speed), both as the
            // face's tangent estimate turns them.
            let tau = std::f64::consts::TAU;
            let w = tau * p.dither_hz;
            let angle = if self.phase == Phase::Find {
                self.face.angle()
            } else {
                self.face.angle() + 0.5 * std::f64::consts::PI
            };
            let (s, c) = (w * self.phase_t).sin_cos();
            for (k, u) in [angle.cos(), angle.sin()].into_iter().enumerate() {
                out[k] += p.dither_m * s * u;
                rate[k] += p.dither_m * w * c * u;
            }
        }
        if self.method == Method::Search && self.phase != Phase::Approach {
            let a = (p.search_growth_m_per_s * self.phase_t).min(p.search_max_m);
            out[0] = self.start_x + a * (std::f64::consts::TAU * p.search_hz * self.t).sin();
        }
        (out, rate)
    }

    /// The pressed phases' rates in the part's frame as estimated: the force loop along the
    /// axis, the walk (find) or the lateral and moment loops (align, insert), the guard on a
    /// lost contact, and the phase changes.
    fn in_contact(&mut self, inp: &Input, pin: &Input, dt: f64) -> [f64; 3] {
        let p = self.params;
        let tau = std::f64::consts::TAU;
        let mut rate = [0.0; 3];
        let find = self.phase == Phase::Find;
        let search = self.method == Method::Search;
        let force = match self.phase {
            Phase::Find => p.find_force_n,
            Phase::Align => p.align_force_n,
            _ => p.insertion_force_n,
        };
        rate[1] = -tau * p.force_bandwidth_hz / self.wrist[1] * (force - pin.force[1]);
        if self.phase == Phase::Insert && pin.force[1] < 0.5 * force {
            // The loop moves a peg that nothing resists at ω F/k: 78 mm/s on the default
            // 2 kN/m wrist (the speed limit applies), 1.6 mm/s on a 100 kN/m one, too slow
            // to reach the depth in time. Below half the insertion force the pose goes down
            // at least at the speed limit, as it does on a compliant wrist (docs/insertion.md,
            // *The wrist's stiffness*).
            rate[1] = rate[1].min(-p.max_speed_m_per_s);
        }
        if inp.force[0].hypot(inp.force[1]) < p.contact_lost_n {
            self.lost_s += dt;
        } else {
            self.lost_s = 0.0;
        }
        let lost = find && self.lost_s >= p.contact_lost_s;
        if find && !search && !lost && p.face.estimate {
            self.face.sample(inp.force, inp.moment_nm, inp.tip, dt);
        }
        if lost {
            // Guarded descent, while finding the hole: the wrist's lead on a peg that
            // dropped off an edge would fling it into the next contact. Once, where the loss
            // is found, take the lead across the axis off and cut the lead along it back to
            // `lead_kept_m`, then go on down at the approach speed. Not all of the press:
            // on an arm, taking it back lifts the flange fast enough to pull a peg that
            // dropped into the hole back out onto the edge. In the hole the peg is free
            // between the walls most of the time, and the insertion force's lead is what
            // pushes it on.
            if self.lost_s - dt < p.contact_lost_s {
                for (k, kept) in [(0, 0.0), (1, p.lead_kept_m)] {
                    let lead = self.target[k] - inp.tip[k];
                    // Only a lead worth the name: a peg hovering at the hole's mouth loses
                    // and finds contact every dither period.
                    if lead.abs() > p.lead_snap_m {
                        self.target[k] = inp.tip[k] + lead.clamp(-kept, kept);
                    }
                }
            }
            rate[1] = -p.approach_m_per_s;
        } else if !search {
            if find {
                rate[0] = self.find_rate(pin);
                // Square to the face but for `kept_tilt_deg` of the tilt against the face's
                // normal, on the side the peg leans: a corner leads into a sharp-edged hole.
                // Where that tilt is not known (the part's orientation unknown, the face's
                // line not found) the peg believed square is not turned off square.
                let kept = p.kept_tilt_deg.to_radians();
                let tilt = pin.tip[2];
                let keep = if !p.face.estimate || self.face.believed() {
                    kept.copysign(tilt)
                } else {
                    tilt.clamp(-kept, kept)
                };
                rate[2] = -tau * p.tilt_bandwidth_hz * (tilt - keep);
            } else {
                rate[0] = tau * p.lateral_bandwidth_hz / self.wrist[0] * pin.force[0];
                rate[2] = tau * p.moment_bandwidth_hz / self.wrist[2] * pin.moment_nm;
            }
        }
        let depth = self.depth_m(pin.tip[1]);
        if find && self.in_bore(pin) {
            self.next(self.after_find());
        }
        if self.phase == Phase::Align && self.straddles(pin) {
            self.next(Phase::Find);
        }
        if self.phase == Phase::Align && self.aligned(pin, dt) {
            self.next(Phase::Insert);
        }
        if depth >= p.target_depth_m {
            self.next(Phase::Done);
        }
        rate
    }

    /// The face's estimated tangent angle in the robot's frame (rad).
    pub fn face_angle(&self) -> f64 {
        self.face.angle()
    }

    /// `inp` in the part's frame as estimated: the robot's frame turned by the face's
    /// estimated tangent angle (about the robot's origin, the hole's nominal centre).
    pub fn to_part(&self, inp: &Input) -> Input {
        let f = self.robot_to_part_xy(&inp.force);
        let x = self.robot_to_part_xy(&inp.tip);
        Input {
            force: f,
            moment_nm: inp.moment_nm,
            tip: [x[0], x[1], inp.tip[2] - self.face.angle()],
        }
    }

    /// The first two entries of `v` (a vector in the robot's frame) in the part's frame.
    fn robot_to_part_xy(&self, v: &[f64]) -> [f64; 2] {
        turn([v[0], v[1]], -self.face.angle())
    }

    /// A vector in the part's frame in the robot's.
    fn part_to_robot_xy(&self, v: [f64; 2]) -> [f64; 2] {
        turn(v, self.face.angle())
    }
    /// Far enough into the hole to leave the find phase: the search goes by its tip's centre,
    /// the others by the tip face's higher corner (the peg tilted by θ, and by the tilt
    /// against the hole the robot may not know: with the part's orientation unknown and the
    /// face's line not found, `prior_error_deg`). A peg that straddles the hole's edge, its
    /// lower corner in the hole and its higher one on the face or just above it, would
    /// otherwise pass for one in the bore (docs/insertion-frame.md).
    fn in_bore(&self, inp: &Input) -> bool {
        let f = &self.params.face;
        let unknown = if f.estimate && !self.face.believed() {
            f.prior_error_deg.to_radians().sin().abs()
        } else {
            0.0
        };
        let tilt = if self.method == Method::Search {
            0.0
        } else {
            inp.tip[2].sin().abs() + unknown
        };
        let upper = self.depth_m(inp.tip[1]) - 0.5 * self.params.peg_width_m * tilt;
        upper > self.in_hole_depth_m
    }

    /// In the align phase: the peg is back on the face, straddling the hole's edge. The part
    /// holds the tip face up (the force along the axis at least half the align force, the
    /// lateral force under half of it: not a chamfer's or a wall's push) at one of its ends
    /// (the centre of pressure, x_c = M/F_y, within a fifth of the half-width of a corner),
    /// and that end is not in the bore. A peg that dipped into the hole for a moment and came
    /// back up onto the edge would otherwise be aligned there: the moment loop turns it about
    /// its tip, the higher corner pivoting on the edge, further off square (arm, c = 0.002,
    /// μ = 0.1, no chamfer, seed 13: 1.4° to 8° in 3 s, docs/insertion-arm.md).
    fn straddles(&self, inp: &Input) -> bool {
        let p = &self.params;
        let [f_x, f_y] = inp.force;
        f_y >= 0.5 * p.align_force_n
            && f_x.abs() < 0.5 * f_y
            && (inp.moment_nm / f_y).abs() >= 0.8 * 0.5 * p.peg_width_m
            && !self.in_bore(inp)
    }

    /// The phase after the find phase: the search inserts, the others align first.
    fn after_find(&self) -> Phase {
        if self.method == Method::Search {
            Phase::Insert
        } else {
            Phase::Align
        }
    }

    /// In the find phase: the walk towards the unsupported side. The contact's centre of
    /// pressure on the tip face is x_c = M/F_y from the tip; the part supports the tip there,
    /// so the hole is on the other side.
    fn find_rate(&self, inp: &Input) -> f64 {
        let p = &self.params;
        if inp.force[1] < 0.5 * p.find_force_n {
            return 0.0;
        }
        let x_c = inp.moment_nm / inp.force[1];
        if x_c.abs() < p.centred_m {
            return 0.0;
        }
        // The commanded pose leads a peg that friction holds by at most the lead that pulls
        // `walk_lead_over_friction` times the press's friction (and at least `walk_lead_m`): a
        // longer lead is a spring that flings the peg when it slips, a shorter one cannot
        // move it.
        let dir = -x_c.signum();
        let lead =
            (p.walk_lead_over_friction * p.mu * p.find_force_n / self.wrist[0]).max(p.walk_lead_m);
        if dir * (self.robot_to_part_xy(&self.target)[0] - inp.tip[0]) > lead {
            return 0.0;
        }
        p.walk_m_per_s * dir
    }

    /// In the align phase: true once the moment about the tip has stayed below
    /// `aligned_moment` × r F_y (a tenth of Whitney's two-point side at λ = 1) for
    /// `aligned_s`, or after `align_timeout_s`.
    fn aligned(&mut self, inp: &Input, dt: f64) -> bool {
        let p = &self.params;
        let scale = 0.5 * p.peg_width_m * inp.force[1].abs().max(p.contact_lost_n);
        if inp.moment_nm.abs() < p.aligned_moment * scale {
            self.aligned_s += dt;
        } else {
            self.aligned_s = 0.0;
        }
        self.aligned_s >= p.aligned_s || self.phase_t >= p.align_timeout_s
    }

    fn next(&mut self, phase: Phase) {
        self.phase = phase;
        self.phase_t = 0.0;
    }
}

#[cfg(test)]
#[path = "controller_tests.rs"]
mod tests;
