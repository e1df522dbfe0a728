//! Whether a seven-joint arm can put its tool at a pose: inverse kinematics by damped least
//! squares within the joint limits (issue 48, docs/franka.md, *The task frame within reach*).
//! The arm's kinematics come in as two functions, the tool's pose and the zero Jacobian at it,
//! so the same solver runs on franka-rs's FR3 model (`afs::stack::robot`) and, in the tests
//! here, on a chain written out from its Denavit-Hartenberg table.
//!
//! One step from joint positions q, with the pose error `e = (p* − p, φ)` (φ the rotation
//! vector of `R* Rᵀ`, in the base frame as the Jacobian's angular rows):
//! `Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e`, scaled to at most [`MAX_STEP_RAD`] and clamped to the
//! limits. The damping λ keeps the step bounded near a singularity, where the plain
//! pseudo-inverse's is not; a local method, so a miss from one start is not a proof: the
//! caller tries several ([`reach`]).

use crate::task_plane::{Jacobian, Joints};
use nalgebra::{Matrix3, Matrix6, Rotation3, Vector3, Vector6};

/// A pose in the base frame: the rotation and the position (m).
pub type Pose = (Matrix3<f64>, Vector3<f64>);

/// The largest position error taken as reached (m).
pub const POSITION_TOLERANCE_M: f64 = 1e-4;
/// The largest orientation error taken as reached (rad).
pub const ROTATION_TOLERANCE_RAD: f64 = 1e-3;
/// The damping λ of the least squares (m or rad).
pub const DAMPING: f64 = 0.05;
/// The largest joint step of one iteration (rad, the step's largest entry).
pub const MAX_STEP_RAD: f64 = 0.2;
/// Iterations before a start is given up.
pub const MAX_ITERATIONS: usize = 400;

/// Joint position limits (rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    /// The lowest position of each joint.
    pub lower: Joints,
    /// The highest.
    pub upper: Joints,
}

/// The FR3's joint position limits (rad), Franka's datasheet.
#[must_use]
pub fn fr3_limits() -> JointLimits {
    JointLimits {
        lower: Joints::from([-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159]),
        upper: Joints::from([2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159]),
    }
}

/// The FR3's starts for [`reach`]: its "ready" pose (libfranka's examples' start) and the same
/// turned about the base and with the elbow folded more and less.
#[must_use]
pub fn fr3_starts() -> [Joints; 5] {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};
    let ready = [
        0.0,
        -FRAC_PI_4,
        0.0,
        -3.0 * FRAC_PI_4,
        0.0,
        FRAC_PI_2,
        FRAC_PI_4,
    ];
    let with = |i: usize, v: f64| {
        let mut q = ready;
        q[i] = v;
        Joints::from(q)
    };
    [
        Joints::from(ready),
        with(0, FRAC_PI_2),
        with(0, -FRAC_PI_2),
        with(3, -2.0),
        with(3, -1.2),
    ]
}

/// How close a start came to a pose it did not reach.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Missed {
    /// Its position error at the end (m).
    pub position_m: f64,
    /// Its orientation error at the end (rad).
    pub rotation_rad: f64,
}

impl std::fmt::Display for Missed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:.1} mm and {:.2}° short",
            self.position_m * 1e3,
            self.rotation_rad.to_degrees()
        )
    }
}

/// The pose error `(p* − p, φ)`, φ the rotation vector of `R* Rᵀ`.
fn pose_error((rt, pt): &Pose, (r, p): &Pose) -> Vector6<f64> {
    let dp = pt - p;
    // A product of rotations: a rotation to rounding.
    let phi = Rotation3::from_matrix_unchecked(rt * r.transpose()).scaled_axis();
    Vector6::new(dp.x, dp.y, dp.z, phi.x, phi.y, phi.z)
}

/// Joint positions within `limits` that put the tool at `target` (rotation, position in the
/// base frame), from `start`; the closest miss otherwise.
///
/// # Errors
/// [`Missed`] when [`MAX_ITERATIONS`] do not bring the error within the tolerances (or the
/// kinematics return something not finite).
pub fn solve(
    pose: impl Fn(&Joints) -> Pose,
    jacobian: impl Fn(&Joints) -> Jacobian,
    target: &Pose,
    start: &Joints,
    limits: &JointLimits,
) -> Result<Joints, Missed> {
    let mut q = start.zip_zip_map(&limits.lower, &limits.upper, |v, lo, hi| v.clamp(lo, hi));
    let mut best = Missed {
        position_m: f64::INFINITY,
        rotation_rad: f64::INFINITY,
    };
    for _ in 0..MAX_ITERATIONS {
        let e = pose_error(target, &pose(&q));
        let miss = Missed {
            position_m: e.fixed_rows::<3>(0).norm(),
            rotation_rad: e.fixed_rows::<3>(3).norm(),
        };
        if !(miss.position_m.is_finite() && miss.rotation_rad.is_finite()) {
            return Err(best);
        }
        if miss.position_m <= POSITION_TOLERANCE_M && miss.rotation_rad <= ROTATION_TOLERANCE_RAD {
            return Ok(q);
        }
        if miss.position_m + miss.rotation_rad < best.position_m + best.rotation_rad {
            best = miss;
        }
        let j = jacobian(&q);
        let jjt = j * j.transpose() + Matrix6::identity() * (DAMPING * DAMPING);
        let Some(y) = jjt.cholesky().map(|c| c.solve(&e)) else {
            return Err(best);
        };
        let mut dq = j.transpose() * y;
        let largest = dq.amax();
        if largest > MAX_STEP_RAD {
            dq *= MAX_STEP_RAD / largest;
        }
        q = (q + dq).zip_zip_map(&limits.lower, &limits.upper, |v, lo, hi| v.clamp(lo, hi));
    }
    Err(best)
}

/// [`solve`] from each of `starts` in turn: the first solution, or the closest miss of all.
///
/// # Errors
/// [`Missed`] when no start reaches the target.
pub fn reach(
    pose: impl Fn(&Joints) -> Pose,
    jacobian: impl Fn(&Joints) -> Jacobian,
    target: &Pose,
    starts: &[Joints],
    limits: &JointLimits,
) -> Result<Joints, Missed> {
    let mut best = Missed {
        position_m: f64::INFINITY,
        rotation_rad: f64::INFINITY,
    };
    for s in starts {
        match solve(&pose, &jacobian, target, s, limits) {
            Ok(q) => return Ok(q),
            Err(m) if m.position_m + m.rotation_rad < best.position_m + best.rotation_rad => {
                best = m;
            }
            Err(_) => {}
        }
    }
    Err(best)
}

#[cfg(test)]
#[path = "reach_tests.rs"]
mod tests;
