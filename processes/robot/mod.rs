//! The servo's FCI client on a Franka FR3 (issue 48, docs/franka.md, *The FCI loop*): franka-rs
//! connects, the arm's model comes from the robot (the URDF it serves), and each robot packet
//! is one [`ArmCycle`]: the packet's state and the model at it in, the torques out within the
//! cycle, clocked by the robot's packets and timed by the robot's own time field.
//!
//! [`hold`] holds the tool where it found it (the hold of `ArmCycle` without a servo), which is
//! what `afs bench robot` measures; the servo board drives the thesis's controller through the
//! same cycle from a [`Session`] (`boards/servo/robot.rs`).

use crate::stack::robot::RobotTable;
use afs_shared::reach::Pose;
use afs_shared::robot_cycle::{ArmCycle, ArmCycleParams, ArmState};
use afs_shared::robot_guard::HoldPose;
use afs_shared::task_plane::{
    Hold, Jacobian, Joints, MassMatrix, PlanarGains, PlanarState, TorqueLimits, planar_gains,
};
use anyhow::{Context, Result, anyhow};
use franka::model::{Frame, Model};
use franka::{ActiveTorqueControl, FrankaError, Robot, RobotState, Torques, motion_finished};
use hdrhistogram::Histogram;
use nalgebra::{Matrix3, Vector3};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// FCI's cycle (s).
pub const CYCLE_S: f64 = 1e-3;

/// The planar axes' bandwidth (Hz), held to the sampling's limit by `planar_gains`.
pub const PLANAR_BANDWIDTH_HZ: f64 = 10.0;

/// An FR3 reached over FCI, with its model and afs's tool.
pub struct Fr3 {
    robot: Robot,
    model: Model,
    /// Flange to tool tip, column-major.
    tool: [f64; 16],
    /// The tool's mass (kg) and its centre of mass in the flange frame (m): half way to the tip.
    load: (f64, [f64; 3]),
}

/// The identity, column-major.
const IDENTITY: [f64; 16] = [
    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
];

impl Fr3 {
    /// Connects to the robot of `table` ([`crate::stack::fci::connect`]: FCI version 10
    /// exactly, each failure one line), loads its model and tells it
    /// the tool's mass (`SetLoad`, the centre of mass half way to the tip, no inertia).
    ///
    /// # Errors
    /// The robot does not answer, refuses, or will not serve its model or take the load.
    pub fn connect(table: &RobotTable) -> Result<Self> {
        let robot = crate::stack::fci::connect(table)?;
        let model = robot
            .load_model()
            .map_err(|e| anyhow!("[robot] the robot did not serve its model: {e}"))?;
        let tool = table.tool.flange_to_tip;
        let com = [tool[12] / 2.0, tool[13] / 2.0, tool[14] / 2.0];
        let mass = table.tool.mass_kg;
        robot
            .set_load(mass, com, [0.0; 9])
            .map_err(|e| anyhow!("[robot] the robot refused the tool's load ({mass} kg): {e}"))?;
        Ok(Self {
            robot,
            model,
            tool,
            load: (mass, com),
        })
    }

    /// The robot, for its motions.
    #[must_use]
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// Starts torque control.
    ///
    /// # Errors
    /// The robot refused it (its reason named).
    pub fn torque_control(&self) -> Result<ActiveTorqueControl<'_>> {
        self.robot
            .start_torque_control()
            .map_err(|e| anyhow!("[robot] torque control refused: {e}"))
    }

    /// The arm's state and the model at it for one packet (the tool as afs's `[robot.tool]`,
    /// the load as set). Allocates nothing.
    #[must_use]
    pub fn arm_state(&self, s: &RobotState) -> ArmState {
        let m = &self.model;
        let (mass, com) = self.load;
        let (tool_rotation, tool_position_m) = tool_pose(m, &s.q, &self.tool);
        ArmState {
            q: Joints::from(s.q),
            dq: Joints::from(s.dq),
            last_command_nm: Joints::from(s.tau_J_d),
            tool_rotation,
            tool_position_m,
            jacobian: tool_jacobian(m, &s.q, &self.tool),
            mass: MassMatrix::from_column_slice(&m.mass_q(&s.q, &[0.0; 9], mass, &com)),
            coriolis: Joints::from(m.coriolis_q(
                &s.q,
                &s.dq,
                &[0.0; 9],
                mass,
                &com,
                &[0.0, 0.0, -9.81],
            )),
        }
    }
}

/// The tool's pose in the base frame at joint positions `q` (rad), the tool `flange_to_tip`
/// given as libfranka's `F_T_EE` (column-major). Allocates nothing.
#[must_use]
pub fn tool_pose(model: &Model, q: &[f64; 7], flange_to_tip: &[f64; 16]) -> Pose {
    let p = model.pose_q(Frame::EndEffector, q, flange_to_tip, &IDENTITY);
    (
        Matrix3::from_fn(|i, j| p[j * 4 + i]),
        Vector3::new(p[12], p[13], p[14]),
    )
}

/// The zero Jacobian at the tool ([`tool_pose`]'s). Allocates nothing.
#[must_use]
pub fn tool_jacobian(model: &Model, q: &[f64; 7], flange_to_tip: &[f64; 16]) -> Jacobian {
    Jacobian::from_column_slice(&model.zero_jacobian_q(
        Frame::EndEffector,
        q,
        flange_to_tip,
        &IDENTITY,
    ))
}

/// The servo's exit status when the robot was lost ([`RobotLost`]): the supervisor ends the run,
/// naming it, instead of restarting the servo against a robot that is not there.
pub const ROBOT_LOST_EXIT: u8 = 3;

/// The robot stopped answering: no state within franka-rs's UDP timeout (1 s) during a motion,
/// or no answer to a restarted servo. What went wrong is in the words.
#[derive(Debug)]
pub struct RobotLost(pub String);

impl std::fmt::Display for RobotLost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the robot was lost: {}", self.0)
    }
}

impl std::error::Error for RobotLost {}

/// Whether `e`, or an error it wraps, is a [`RobotLost`].
#[must_use]
pub fn is_robot_lost(e: &anyhow::Error) -> bool {
    e.chain().any(|c| c.is::<RobotLost>())
}

/// The next packet of a torque-control loop: the robot's state and its time since the last
/// packet (s; more than a cycle when cycles were missed).
///
/// # Errors
/// The robot ended the motion (its reason named), or sent nothing for 1 s ([`RobotLost`]).
pub fn next_packet(control: &mut ActiveTorqueControl<'_>) -> Result<(RobotState, f64)> {
    control
        .read_once()
        .map(|(state, period)| (state, period.as_secs_f64()))
        .map_err(|e| match e {
            FrankaError::Network(why) => anyhow::Error::new(RobotLost(format!(
                "it sent no state for 1 s ({why}); check that it is on and that its network is up"
            ))),
            other => anyhow!("[robot] the motion ended: {other}"),
        })
}

/// What a hold measured.
#[derive(Debug)]
pub struct HoldRun {
    /// From a state received to its torque sent (ns).
    pub state_to_command_ns: Histogram<u64>,
    /// Cycles run (packets answered).
    pub cycles: u64,
    /// The robot's time over the run (s).
    pub robot_time_s: f64,
    /// Robot cycles with no command from afs: the robot's time steps beyond one cycle.
    pub missed_cycles: u64,
    /// The robot's command success rate at the end (0–1).
    pub command_success_rate: f64,
    /// The largest planar distance from the held pose (m).
    pub drift_m: f64,
    /// The largest |θ − θ₀| (rad).
    pub drift_rad: f64,
    /// Cycles in which the torque-rate limit cut a joint.
    pub rate_limited_cycles: u64,
    /// Why the guard tripped, if it did.
    pub trip: Option<String>,
    /// Wall time of the loop (s).
    pub wall_s: f64,
    /// Where the tool was held: x, y (m), θ (rad) and the normal offset (m) in the task plane.
    pub start: [f64; 4],
    /// What the real-time set-up of the loop's thread achieved.
    pub realtime: crate::rt::RtReport,
}

/// The loop's SCHED_FIFO priority: the servo board's. The loop waits on the robot's packets
/// (a blocking receive), so it never spins.
pub const PRIORITY: u8 = 80;

/// Holds the tool of `table` where it is for `seconds` of the robot's time (or until `stop`),
/// through [`ArmCycle::hold_at`], and leaves through FCI's own finish. The loop runs in a
/// thread of its own at SCHED_FIFO ([`PRIORITY`]) with its memory locked where the system
/// allows it; what it refused is in [`HoldRun::realtime`].
///
/// # Errors
/// The connection, or the robot ending the motion (its reason named).
pub fn hold(table: &RobotTable, seconds: f64, stop: &AtomicBool) -> Result<HoldRun> {
    std::thread::scope(|s| {
        std::thread::Builder::new()
            .name("afs-fci".into())
            .spawn_scoped(s, || {
                let rt = crate::rt::setup(PRIORITY, true, None);
                for w in &rt.warnings {
                    eprintln!("afs: warning: {w}");
                }
                let mut run = hold_here(table, seconds, stop)?;
                run.realtime = rt;
                Ok(run)
            })
            .context("starting the FCI loop's thread")?
            .join()
            .map_err(|_| anyhow!("the FCI loop's thread panicked"))?
    })
}

/// A robot ready for torque control: the FR3, where its tool started, and the cycle with the
/// planar impedance that holds a pose (the guard's hold, and a hold without a servo).
pub struct Session {
    /// The arm.
    pub fr3: Fr3,
    /// The cycle on it.
    pub cycle: ArmCycle,
    /// The tool's planar state at the first packet.
    pub start: PlanarState,
    /// The tool's planar inertia there (kg, kg, kg·m²).
    pub inertia: Vector3<f64>,
    /// The planar impedance of the hold ([`PLANAR_BANDWIDTH_HZ`]).
    pub gains: PlanarGains,
}

impl Session {
    /// Connects ([`Fr3::connect`]), reads one state and builds the cycle of `table` there: the
    /// null space's posture is the arm's first pose.
    ///
    /// # Errors
    /// The connection, no state, an arm at a singularity, or a table that does not check.
    pub fn open(table: &RobotTable) -> Result<Self> {
        let fr3 = Fr3::connect(table)?;
        let first = fr3
            .robot
            .read_once()
            .map_err(|e| anyhow!("[robot] no state: {e}"))?;
        let arm0 = fr3.arm_state(&first);
        let plane = table.plane()?;
        let inertia = plane
            .planar_inertia(&arm0.jacobian, &arm0.mass)
            .context("the arm starts at a singularity: move it to a pose away from one")?;
        let gains = planar_gains(&inertia, PLANAR_BANDWIDTH_HZ, 1.0, CYCLE_S)
            .context("the arm's planar inertia is not finite and positive")?;
        let cycle = ArmCycle::new(
            plane,
            ArmCycleParams {
                hold: Hold::FR3,
                posture: arm0.q,
                limits: TorqueLimits::fr3(),
                normal_target_m: 0.0,
                guard_gains: gains,
            },
            table.guard()?,
        );
        let start = cycle.planar(&arm0);
        Ok(Self {
            fr3,
            cycle,
            start,
            inertia,
            gains,
        })
    }

    /// The pose the tool started at.
    #[must_use]
    pub fn start_pose(&self) -> HoldPose {
        HoldPose::of(&self.start)
    }
}

fn hold_here(table: &RobotTable, seconds: f64, stop: &AtomicBool) -> Result<HoldRun> {
    let mut session = Session::open(table)?;
    let pose = session.start_pose();
    let s0 = session.start;
    let mut run = HoldRun {
        state_to_command_ns: crate::hist::new()?,
        cycles: 0,
        robot_time_s: 0.0,
        missed_cycles: 0,
        command_success_rate: 0.0,
        drift_m: 0.0,
        drift_rad: 0.0,
        rate_limited_cycles: 0,
        trip: None,
        wall_s: 0.0,
        start: [s0.position_m.x, s0.position_m.y, s0.theta_rad, s0.normal_m],
        realtime: crate::rt::RtReport::default(),
    };
    let mut trip = None;
    let wall = Instant::now();
    let Session { fr3, cycle, .. } = &mut session;
    let mut control = fr3.torque_control()?;
    loop {
        let (state, period_s) = next_packet(&mut control)?;
        let received = Instant::now();
        let steps = (period_s / CYCLE_S).round() as u64;
        run.missed_cycles += steps.saturating_sub(1);
        run.robot_time_s += period_s;
        let arm = fr3.arm_state(&state);
        let out = cycle.hold_at(&arm, &pose, CYCLE_S);
        let last = run.robot_time_s >= seconds || stop.load(Ordering::Relaxed);
        let torques = Torques::new(out.torque.torque_nm.into());
        let sent = if last {
            control.write_once(&motion_finished(torques))
        } else {
            control.write_once(&torques)
        };
        crate::hist::record(
            &mut run.state_to_command_ns,
            received.elapsed().as_nanos() as u64,
        );
        sent.map_err(|e| anyhow!("[robot] the command was refused: {e}"))?;
        run.cycles += 1;
        run.command_success_rate = state.control_command_success_rate;
        run.drift_m = run
            .drift_m
            .max((out.planar.position_m - pose.position_m).norm());
        run.drift_rad = run
            .drift_rad
            .max((out.planar.theta_rad - pose.theta_rad).abs());
        run.rate_limited_cycles += u64::from(out.torque.rate_limited != 0);
        trip = trip.or(out.tripped.map(|(t, _)| t));
        if last {
            break;
        }
    }
    run.wall_s = wall.elapsed().as_secs_f64();
    run.trip = trip.map(|t| t.to_string());
    Ok(run)
}
