//! The insertion scenario's messages: the peg's truth beside the controller's estimate every
//! servo tick ([`PegSample`]), and the insertion's whole state in the world snapshot
//! ([`InsertionState`]) for a restarted servo.

use super::samples::{PlantSample, ServoFlags, ServoSample};
use crate::insertion::controller::{ControllerState, Phase};
use crate::insertion::monitor::PegTick;
use crate::insertion::plant::{ContactState, PegPlantState, PegTruth};
use crate::insertion::rig::{InsertionRig, RigState};
use crate::math::Vec2;
use crate::sensor::Wrench;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

/// The wire code of a phase: 0 approach, 1 find, 2 align, 3 insert, 4 done.
pub fn phase_code(p: Phase) -> u32 {
    match p {
        Phase::Approach => 0,
        Phase::Find => 1,
        Phase::Align => 2,
        Phase::Insert => 3,
        Phase::Done => 4,
    }
}

/// The phase of a wire code (an unknown code is the approach).
pub fn phase_of(code: u32) -> Phase {
    match code {
        1 => Phase::Find,
        2 => Phase::Align,
        3 => Phase::Insert,
        4 => Phase::Done,
        _ => Phase::Approach,
    }
}

const STATES: [ContactState; 8] = [
    ContactState::Free,
    ContactState::Face,
    ContactState::Chamfer,
    ContactState::OnePoint,
    ContactState::TwoPoint,
    ContactState::Jammed,
    ContactState::Wedged,
    ContactState::Bottom,
];

/// The wire code of a contact state: 0 free, 1 face, 2 chamfer, 3 one-point, 4 two-point,
/// 5 jammed, 6 wedged, 7 bottom.
pub fn state_code(s: ContactState) -> u32 {
    STATES.iter().position(|x| *x == s).unwrap_or(0) as u32
}

/// The contact state of a wire code (an unknown code is free).
pub fn state_of(code: u32) -> ContactState {
    STATES.get(code as usize).copied().unwrap_or_default()
}

wire_struct! {
    /// The peg's true state at one instant (a part of [`PegSample`] and [`InsertionState`]).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::PegTruthMsg")]
    pub struct PegTruthMsg {
        /// The tip's pose: x, y (m) and tilt θ (rad, counter-clockwise from the hole's axis).
        pub pose: [f64; 3],
        /// Its rates (m/s, m/s, rad/s).
        pub velocity: [f64; 3],
        /// Contact force on the peg (N).
        pub force_n: [f64; 2],
        /// Its moment about the tip (N·m).
        pub moment_nm: f64,
        /// The force the wrist applies (N).
        pub applied_force_n: [f64; 2],
        /// Its moment about the tip (N·m).
        pub applied_moment_nm: f64,
        /// Depth of the tip below the face (m).
        pub depth_m: f64,
        /// In two-point contact, the hole edge's distance from the tip along the peg (m; 0 and
        /// `has_edge` 0 otherwise).
        pub edge_along_peg_m: f64,
        /// Contacts.
        pub contacts: u32,
        /// Contact state (`state_code`: 0 free … 7 bottom).
        pub state: u32,
        /// 1 when `edge_along_peg_m` holds.
        pub has_edge: u32,
        /// Reserved (0).
        pub reserved: u32,
    }
}

impl From<&PegTruth> for PegTruthMsg {
    fn from(t: &PegTruth) -> Self {
        Self {
            pose: t.pose,
            velocity: t.velocity,
            force_n: [t.force.x, t.force.y],
            moment_nm: t.moment_about_tip,
            applied_force_n: [t.applied_force.x, t.applied_force.y],
            applied_moment_nm: t.applied_moment_about_tip,
            depth_m: t.depth_m,
            edge_along_peg_m: t.edge_along_peg_m.unwrap_or(0.0),
            contacts: u32::try_from(t.contacts).unwrap_or(u32::MAX),
            state: state_code(t.state),
            has_edge: u32::from(t.edge_along_peg_m.is_some()),
            reserved: 0,
        }
    }
}

impl From<&PegTruthMsg> for PegTruth {
    fn from(m: &PegTruthMsg) -> Self {
        Self {
            pose: m.pose,
            velocity: m.velocity,
            force: Vec2::new(m.force_n[0], m.force_n[1]),
            moment_about_tip: m.moment_nm,
            applied_force: Vec2::new(m.applied_force_n[0], m.applied_force_n[1]),
            applied_moment_about_tip: m.applied_moment_nm,
            contacts: m.contacts as usize,
            state: state_of(m.state),
            depth_m: m.depth_m,
            edge_along_peg_m: (m.has_edge != 0).then_some(m.edge_along_peg_m),
        }
    }
}

wire_flags! {
    /// [`PegSample::flags`].
    pub struct PegFlags {
        /// The controller had force data this tick.
        const FORCE_VALID = 1;
        /// Without it, the wrist held its pose (the safe state).
        const HELD = 2;
    }
}

wire_message! {
    version = 1;
    /// The insertion every servo tick (`insertion` scenario only): the peg's truth, the
    /// controller's phase, commanded pose and estimated contact state.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::PegSample")]
    pub struct PegSample {
        /// Layout version.
        pub version: u32,
        /// The controller's phase (0 approach, 1 find, 2 align, 3 insert, 4 done).
        pub phase: u32,
        /// The estimated contact state (codes as `truth.state`).
        pub estimated_state: u32,
        /// Flags.
        pub flags: PegFlags,
        /// The servo tick, as `PlantSample.seq`.
        pub seq: u64,
        /// The tick's time (ns, CLOCK_MONOTONIC).
        pub tick_ns: u64,
        /// When it was published (ns).
        pub publish_ns: u64,
        /// Simulated time at the end of the tick (s).
        pub time_s: f64,
        /// The commanded tip pose without the dither (m, m, rad).
        pub target: [f64; 3],
        /// The truth after the tick.
        pub truth: PegTruthMsg,
    }
}

impl PegSample {
    /// Tick `seq` of `rig` as the servo publishes it (`force_valid`: the controller had force
    /// data).
    pub fn of_rig(rig: &InsertionRig, seq: u64, tick_ns: u64, force_valid: bool) -> Self {
        let mut flags = PegFlags::empty();
        flags.set(PegFlags::FORCE_VALID, force_valid);
        flags.set(PegFlags::HELD, !force_valid);
        Self {
            version: Self::VERSION,
            phase: phase_code(rig.phase()),
            estimated_state: state_code(rig.estimated()),
            flags,
            seq,
            tick_ns,
            publish_ns: 0,
            time_s: rig.time_s(),
            target: rig.target(),
            truth: rig.truth().into(),
        }
    }

    /// What the insertion monitor reads.
    pub fn tick(&self) -> PegTick {
        PegTick {
            t: self.time_s,
            phase: phase_of(self.phase),
            estimated: state_of(self.estimated_state),
            truth: (&self.truth).into(),
        }
    }
}

impl PlantSample {
    /// The world sample of an insertion: the fields that mean the same for the peg (time, the
    /// tip and its velocity, the contact force and the wrench the wrist's sensor feels, with
    /// its moment about the tip; `normal_force_n` the contact force along the hole's axis,
    /// `depth_m` the tip's depth below the face); the arm's fields are 0 ([`PegSample`] has
    /// the rest).
    pub fn of_peg(rig: &InsertionRig, seq: u64, tick_ns: u64) -> Self {
        let t = rig.truth();
        let w = rig.sensor_wrench();
        Self {
            version: Self::VERSION,
            contact_count: u32::try_from(t.contacts).unwrap_or(u32::MAX),
            seq,
            tick_ns,
            time_s: rig.time_s(),
            tip_m: [t.pose[0], t.pose[1]],
            tip_velocity_m_per_s: [t.velocity[0], t.velocity[1]],
            contact_force_n: [t.force.x, t.force.y],
            sensor_force_n: [w.force.x, w.force.y],
            sensor_torque_nm: w.torque,
            normal_force_n: t.force.y,
            depth_m: t.depth_m,
            ..Default::default()
        }
    }
}

impl ServoSample {
    /// The controller sample of an insertion: time, the force data used (`reading`, tared;
    /// `normal_force_n` its force along the hole's axis) or the safe state without it, the
    /// commanded tip position as the set-point ([`PegSample`] has the rest).
    pub fn of_peg(rig: &InsertionRig, seq: u64, tick_ns: u64, reading: Option<Wrench>) -> Self {
        let target = rig.target();
        let mut s = Self {
            version: Self::VERSION,
            seq,
            tick_ns,
            time_s: rig.time_s(),
            wrench_seq: u64::MAX,
            set_point_m: [target[0], target[1]],
            ..Default::default()
        };
        match reading {
            Some(w) => {
                s.flags |= ServoFlags::FORCE_VALID;
                s.normal_force_n = w.force.y;
                s.tangential_force_n = w.force.x;
            }
            None => s.flags |= ServoFlags::SAFE,
        }
        s
    }
}

wire_struct! {
    /// The insertion's whole state (a part of [`WorldSnapshot`](super::WorldSnapshot)): the
    /// peg's plant, the controller and the estimator, for a restarted servo to carry on
    /// exactly where its predecessor was.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::InsertionState")]
    pub struct InsertionState {
        /// 1 when the snapshot holds an insertion (the `insertion` scenario), 0 otherwise.
        pub active: u32,
        /// The controller's phase (codes as `PegSample.phase`).
        pub phase: u32,
        /// Time since the start (s).
        pub time_s: f64,
        /// The peg's centre of mass (m) and θ (rad).
        pub q: [f64; 3],
        /// Their rates.
        pub v: [f64; 3],
        /// Each contact slot's bristle deflection (m): the peg's four corners, then the part's.
        pub deflection_m: [f64; 8],
        /// Each slot's normal force in the last sub-step (N).
        pub normal_force_n: [f64; 8],
        /// The feature each slot touches: −1 none, else 8 × feature (0 face, 1 chamfer,
        /// 2 wall, 3 bottom) + side + 4.
        pub touching: [i32; 8],
        /// The contact force (N) and its moment about the centre of mass (N·m), last sub-step.
        pub last_contact: [f64; 3],
        /// The wrist's, last sub-step.
        pub last_wrist: [f64; 3],
        /// The truth of the last step.
        pub truth: PegTruthMsg,
        /// The commanded pose without the dither.
        pub target: [f64; 3],
        /// Where the lateral search is centred (m).
        pub start_x_m: f64,
        /// The controller's time (s).
        pub controller_t_s: f64,
        /// Time in the phase (s).
        pub phase_t_s: f64,
        /// How long the peg has stayed aligned (s).
        pub aligned_s: f64,
        /// How long the contact force has been below the loss threshold (s).
        pub lost_s: f64,
        /// The estimator's filtered force (N) and moment (N·m).
        pub filtered: [f64; 3],
        /// The estimator's bounds on the face's slope in the robot's frame (lowest, highest;
        /// 0, 0 for a part whose orientation is known).
        pub face_slopes: [f64; 2],
        /// The tip's height at the last tick (m).
        pub prev_tip_y_m: f64,
        /// The largest contact force so far (N).
        pub peak_force_n: f64,
        /// The last estimated contact state.
        pub estimated_state: u32,
        /// 1 when the three-joint arm drives the flange (`drive = "arm"`), 0 otherwise.
        pub arm_driven: u32,
        /// The arm's joint angles (rad), rates (rad/s), its servos' integrals (rad·s), last
        /// commanded joint angles and rates, and the servo interpolator's tool pose (m, m, rad)
        /// and rate (m/s, m/s, rad/s), in that order; zero when the flange is ideal.
        pub arm: [[f64; 3]; 7],
        /// The face's tangent estimate (the part's orientation unknown, docs/insertion.md):
        /// its angle in the robot's frame (rad), the low-passed force (N) and moment (N·m),
        /// the corner points' sums n, Σx, Σy, Σx², Σxy, Σy², Σs, Σxs (m, m²) and their origin
        /// (m).
        pub face: [f64; 14],
        /// 1 once the face's points make a line, 0 before.
        pub face_believed: u32,
        /// The peg's world: 0 the built-in plant, 1 MuJoCo.
        pub world: u32,
        /// MuJoCo's state of its peg as `mj_getState` gives it (time, the three joints, their
        /// rates, the solver's warm start); zero on the built-in plant.
        pub mujoco: [f64; MUJOCO_PEG_STATE_LEN],
    }
}

use crate::insertion::drive::ArmDriveState;
use crate::insertion::estimate::EstimatorState;
use crate::insertion::face::FaceState;
use crate::insertion::world::MUJOCO_PEG_STATE_LEN;

fn face_words(f: &FaceState) -> [f64; 14] {
    let mut w = [0.0; 14];
    w[0] = f.angle_rad;
    w[1..4].copy_from_slice(&f.wrench);
    w[4..12].copy_from_slice(&f.sums);
    w[12..14].copy_from_slice(&f.origin);
    w
}

fn face_of(w: &[f64; 14], believed: u32) -> FaceState {
    let mut f = FaceState {
        angle_rad: w[0],
        believed: believed != 0,
        ..FaceState::default()
    };
    f.wrench.copy_from_slice(&w[1..4]);
    f.sums.copy_from_slice(&w[4..12]);
    f.origin.copy_from_slice(&w[12..14]);
    f
}
use crate::insertion::geometry::Feature;

const FEATURES: [Feature; 4] = [
    Feature::Face,
    Feature::Chamfer,
    Feature::Wall,
    Feature::Bottom,
];

fn touching_code(t: Option<(Feature, i8)>) -> i32 {
    t.map_or(-1, |(f, side)| {
        let f = FEATURES.iter().position(|x| *x == f).unwrap_or(0) as i32;
        8 * f + i32::from(side) + 4
    })
}

fn touching_of(code: i32) -> Option<(Feature, i8)> {
    (code >= 0).then(|| {
        let f = FEATURES[(code / 8).clamp(0, 3) as usize];
        (f, (code % 8 - 4) as i8)
    })
}

impl From<&RigState> for InsertionState {
    fn from(s: &RigState) -> Self {
        let (p, c, a) = (&s.plant, &s.controller, &s.arm);
        Self {
            active: 1,
            phase: phase_code(c.phase),
            time_s: s.time_s,
            q: p.q,
            v: p.v,
            deflection_m: p.deflection_m,
            normal_force_n: p.normal_n,
            touching: p.touching.map(touching_code),
            last_contact: [p.last_contact.0.x, p.last_contact.0.y, p.last_contact.1],
            last_wrist: [p.last_wrist.0.x, p.last_wrist.0.y, p.last_wrist.1],
            truth: (&p.truth).into(),
            target: c.target,
            start_x_m: c.start_x,
            controller_t_s: c.t,
            phase_t_s: c.phase_t,
            aligned_s: c.aligned_s,
            lost_s: c.lost_s,
            filtered: [
                s.estimator.filtered.0[0],
                s.estimator.filtered.0[1],
                s.estimator.filtered.1,
            ],
            face_slopes: s.estimator.face_slopes,
            prev_tip_y_m: s.prev_tip_y_m,
            peak_force_n: s.peak_force_n,
            estimated_state: state_code(s.estimated),
            arm_driven: u32::from(s.arm != ArmDriveState::default()),
            arm: [a.q, a.v, a.integral, a.q_d, a.v_d, a.pose_d, a.rate_d],
            face: face_words(&c.face),
            face_believed: u32::from(c.face.believed),
            world: u32::from(s.mujoco.is_some()),
            mujoco: s.mujoco.unwrap_or_default(),
        }
    }
}

impl From<&InsertionState> for RigState {
    fn from(m: &InsertionState) -> Self {
        let wrench = |w: [f64; 3]| (Vec2::new(w[0], w[1]), w[2]);
        Self {
            time_s: m.time_s,
            plant: PegPlantState {
                q: m.q,
                v: m.v,
                deflection_m: m.deflection_m,
                touching: m.touching.map(touching_of),
                normal_n: m.normal_force_n,
                last_contact: wrench(m.last_contact),
                last_wrist: wrench(m.last_wrist),
                truth: (&m.truth).into(),
            },
            controller: ControllerState {
                phase: phase_of(m.phase),
                target: m.target,
                start_x: m.start_x_m,
                t: m.controller_t_s,
                phase_t: m.phase_t_s,
                aligned_s: m.aligned_s,
                lost_s: m.lost_s,
                face: face_of(&m.face, m.face_believed),
            },
            estimator: EstimatorState {
                filtered: ([m.filtered[0], m.filtered[1]], m.filtered[2]),
                face_slopes: m.face_slopes,
            },
            estimated: state_of(m.estimated_state),
            prev_tip_y_m: m.prev_tip_y_m,
            peak_force_n: m.peak_force_n,
            arm: ArmDriveState {
                q: m.arm[0],
                v: m.arm[1],
                integral: m.arm[2],
                q_d: m.arm[3],
                v_d: m.arm[4],
                pose_d: m.arm[5],
                rate_d: m.arm[6],
            },
            mujoco: (m.world == 1).then_some(m.mujoco),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::insertion::drive::Drive;
    use crate::insertion::rig::{InsertionOptions, InsertionRig, PartFrame};

    /// Every code goes there and back; a rig's state mid-insertion survives the wire bit for
    /// bit.
    #[test]
    fn the_insertion_state_crosses_the_wire_exactly() {
        for s in STATES {
            assert_eq!(state_of(state_code(s)), s);
        }
        for p in [
            Phase::Approach,
            Phase::Find,
            Phase::Align,
            Phase::Insert,
            Phase::Done,
        ] {
            assert_eq!(phase_of(phase_code(p)), p);
        }
        for f in FEATURES {
            for side in [-1i8, 0, 1] {
                assert_eq!(touching_of(touching_code(Some((f, side)))), Some((f, side)));
            }
        }
        assert_eq!(touching_of(touching_code(None)), None);
        for (drive, part_frame) in [
            (Drive::Ideal, PartFrame::Known),
            (Drive::Arm, PartFrame::Known),
            (Drive::Ideal, PartFrame::Unknown),
        ] {
            let o = InsertionOptions {
                drive,
                part_frame,
                ..InsertionOptions::default()
            };
            // Seed 10 walks far enough on the face for the face's line to be believed.
            let mut rig = InsertionRig::new(&o, 10).unwrap();
            let unknown = part_frame == PartFrame::Unknown;
            while rig.truth().contacts < 2 || unknown && !rig.state().controller.face.believed {
                let w = rig.sensor_wrench();
                rig.step(Some(w), 1e-4);
                assert!(rig.time_s() < 10.0);
            }
            let s = rig.state();
            let m = InsertionState::from(&s);
            assert_eq!(m.arm_driven, u32::from(drive == Drive::Arm), "{drive:?}");
            // The estimator's face slopes, narrowed from the prior's ±tan 2°, cross too.
            let [lo, hi] = s.estimator.face_slopes;
            assert_eq!(unknown, hi - lo > 0.0 && hi - lo < 0.01, "{lo} {hi}");
            assert_eq!(RigState::from(&m), s);
        }
    }
}
