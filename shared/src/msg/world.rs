//! The world snapshot the servo keeps in the supervisor's blackboard, for a restarted servo.

use super::insertion::InsertionState;
use super::samples::PlantSample;
use crate::plant::PlantState;
use crate::scenario::DriverMemo;
use crate::servo::ServoState;
use crate::watchdog::GateCounters;
use crate::world::{MUJOCO_STATE_LEN, MujocoState, WorldStateAny};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

wire_struct! {
    /// One contact slot's friction state (a part of [`WorldState`]).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::FrictionSlot")]
    pub struct FrictionSlot {
        /// The surface face in contact (u64::MAX: an empty slot).
        pub face: u64,
        /// Presliding (bristle) deflection (m).
        pub deflection_m: f64,
    }
}

wire_struct! {
    /// The simulated world's state (a part of [`WorldSnapshot`]).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::WorldState")]
    pub struct WorldState {
        /// Simulated time (s).
        pub time_s: f64,
        /// Joint angles (rad).
        pub q_rad: [f64; 2],
        /// Joint rates (rad/s).
        pub qd_rad_per_s: [f64; 2],
        /// The two contact slots' friction states (the built-in world).
        pub friction: [FrictionSlot; 2],
        /// Which world: 0 the built-in plant, 1 MuJoCo.
        pub kind: u32,
        /// How many of `mujoco` are used.
        pub mujoco_len: u32,
        /// MuJoCo's state (`mj_getState`: time, joints, warm start, surface pose).
        pub mujoco: [f64; MUJOCO_STATE_LEN],
    }
}

impl From<&WorldStateAny> for WorldState {
    fn from(st: &WorldStateAny) -> Self {
        match st {
            WorldStateAny::Builtin(p) => p.into(),
            WorldStateAny::Mujoco(m) => Self {
                time_s: m.values[0],
                kind: 1,
                mujoco_len: m.len as u32,
                mujoco: m.values,
                ..Default::default()
            },
        }
    }
}

impl From<&WorldState> for WorldStateAny {
    fn from(w: &WorldState) -> Self {
        if w.kind == 1 {
            WorldStateAny::Mujoco(MujocoState {
                len: (w.mujoco_len as usize).min(MUJOCO_STATE_LEN),
                values: w.mujoco,
            })
        } else {
            WorldStateAny::Builtin(w.into())
        }
    }
}

impl From<&PlantState> for WorldState {
    fn from(st: &PlantState) -> Self {
        let slot = |(face, deflection_m): (usize, f64)| FrictionSlot {
            face: u64::try_from(face).unwrap_or(u64::MAX),
            deflection_m,
        };
        Self {
            time_s: st.time_s,
            q_rad: st.q,
            qd_rad_per_s: st.qd,
            friction: st.friction.map(slot),
            ..Default::default()
        }
    }
}

impl From<&WorldState> for PlantState {
    fn from(w: &WorldState) -> Self {
        let slot = |s: FrictionSlot| {
            (
                usize::try_from(s.face).unwrap_or(usize::MAX),
                s.deflection_m,
            )
        };
        Self {
            time_s: w.time_s,
            q: w.q_rad,
            qd: w.qd_rad_per_s,
            friction: w.friction.map(slot),
        }
    }
}

wire_struct! {
    /// Where the scenario driver is (a part of [`WorldSnapshot`]).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::DriverMemoMsg")]
    pub struct DriverMemoMsg {
        /// The `friction-id` leg in progress (u32::MAX: none).
        pub leg: u32,
        /// Reserved (0).
        pub reserved: u32,
        /// When the leg started (s).
        pub leg_start_s: f64,
        /// Where it started on the surface (m).
        pub leg_start_u_m: f64,
    }
}

impl From<DriverMemo> for DriverMemoMsg {
    fn from(m: DriverMemo) -> Self {
        Self {
            leg: m.leg.unwrap_or(u32::MAX),
            reserved: 0,
            leg_start_s: m.leg_start_s,
            leg_start_u_m: m.leg_start_u,
        }
    }
}

impl From<&DriverMemoMsg> for DriverMemo {
    fn from(d: &DriverMemoMsg) -> Self {
        Self {
            leg: (d.leg != u32::MAX).then_some(d.leg),
            leg_start_s: d.leg_start_s,
            leg_start_u: d.leg_start_u_m,
        }
    }
}

wire_message! {
    version = 11;
    /// The world's state the servo keeps in the supervisor's blackboard so that a restarted
    /// servo resumes the world, its controller and its counts where they were (one entry per
    /// servo incarnation of [`service::WORLD`](super::service::WORLD)).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::WorldSnapshot.v11")]
    pub struct WorldSnapshot {
        /// The layout version, `Self::VERSION`; 0 means "no snapshot yet".
        pub version: u32,
        /// Reserved (0).
        pub reserved: u32,
        /// Servo tick the snapshot was taken at; the restarted servo continues at `seq + 1`.
        pub seq: u64,
        /// The simulated world.
        pub world: WorldState,
        /// The scenario driver.
        pub driver: DriverMemoMsg,
        /// The controller ([`crate::servo::ServoCore::state`]): a restarted servo carries on
        /// with it.
        pub controller: ServoState,
        /// The force gate's verdicts so far, over every servo incarnation of the run.
        pub gate: GateCounters,
        /// Of those, on the samples flagged as injected (`afs chaos`).
        pub injected: GateCounters,
        /// The insertion (`insertion` scenario; `active` 0 otherwise).
        pub insertion: InsertionState,
        /// The world sample of tick `seq`, exactly as published (written before it is sent): a
        /// restarted servo sends it again, so the tick reaches subscribers whether or not its
        /// predecessor died before sending it; a subscriber drops the identical repeat.
        pub plant: PlantSample,
    }
}
