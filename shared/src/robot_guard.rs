//! The guard that ends a robot's run in a hold (issue 48, docs/franka.md *The guard*): every
//! cycle it checks the tool's planar state against the workspace box and the measured contact
//! force against its limit; the first cycle either is broken (or a value is not a number) it
//! trips, latched, and names why. From then on the servo commands the impedance hold at the
//! guard's hold pose instead of the thesis's controller, until it is released.
//!
//! The hold pose:
//! - a workspace trip: the tool's pose with each coordinate clamped into the box, so that the
//!   hold pulls the tool back to the box's face it crossed, not further out;
//! - a contact-force trip: the pose where it tripped; the force controller's push is gone, and
//!   the hold's spring is relaxed there, so the contact force falls to what the contact and the
//!   hold's compliance in series leave (below the limit for any hold softer than the contact);
//! - a value that is not a number: the last pose that was one (the pose of the cycle before).
//!
//! The box and the limit are the stack file's `[robot.limits]` (`contact_force_n`,
//! `workspace_m` in the plane's frame: x, y and the offset along the normal). A coordinate on
//! the box's face is inside it; a force at the limit is within it.

use crate::task_plane::PlanarState;
use nalgebra::{Vector2, Vector3};

/// The guard's limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardLimits {
    /// The largest contact force's magnitude let through (N).
    pub contact_force_n: f64,
    /// The workspace box in the plane's frame: x, y and the normal offset, each `[low, high]`
    /// (m).
    pub workspace_m: [[f64; 2]; 3],
}

/// One of the box's three axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlaneAxis {
    /// The plane's x axis.
    X,
    /// The plane's y axis.
    Y,
    /// The plane's normal.
    Normal,
}

impl PlaneAxis {
    const ALL: [Self; 3] = [Self::X, Self::Y, Self::Normal];

    /// The axis's name, as `[robot.limits]` documents it.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::X => "x",
            Self::Y => "y",
            Self::Normal => "normal",
        }
    }
}

/// Why the guard tripped.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Trip {
    /// The tool left the workspace box along `axis`.
    #[error(
        "the tool left the workspace: {} = {at_m:.4} m is outside [{}, {}] m ([robot.limits] workspace_m)",
        axis.name(), range_m[0], range_m[1]
    )]
    Workspace {
        /// The axis it crossed.
        axis: PlaneAxis,
        /// Where the tool was on it (m).
        at_m: f64,
        /// The box's range on it (m).
        range_m: [f64; 2],
    },
    /// The contact force's magnitude exceeded the limit.
    #[error(
        "the contact force {force_n:.2} N is over the limit of {limit_n} N ([robot.limits] contact_force_n)"
    )]
    ContactForce {
        /// The force's magnitude (N).
        force_n: f64,
        /// The limit (N).
        limit_n: f64,
    },
    /// A value the guard reads was not a number.
    #[error("the {what} is not a number: held at the last pose that was")]
    NotFinite {
        /// What it was: "tool's pose" or "contact force".
        what: &'static str,
    },
}

/// Limits the guard cannot work with.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum GuardError {
    /// The force limit is not a force above zero.
    #[error("contact_force_n = {0} must be a force above 0 N")]
    Force(f64),
    /// A range of the box is not two numbers, low before high.
    #[error("workspace_m's {} range [{}, {}] must be two numbers, low before high (m)", axis.name(), range_m[0], range_m[1])]
    Range {
        /// Its axis.
        axis: PlaneAxis,
        /// The range given (m).
        range_m: [f64; 2],
    },
}

/// Where the servo holds the tool: x and y (m), θ (rad) and the normal offset (m).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HoldPose {
    /// x and y in the plane (m).
    pub position_m: Vector2<f64>,
    /// The angle about the normal (rad).
    pub theta_rad: f64,
    /// The offset along the normal (m).
    pub normal_m: f64,
}

impl HoldPose {
    /// The pose of the tool's planar state `s`.
    #[must_use]
    pub fn of(s: &PlanarState) -> Self {
        Self {
            position_m: s.position_m,
            theta_rad: s.theta_rad,
            normal_m: s.normal_m,
        }
    }

    fn is_finite(&self) -> bool {
        self.position_m.iter().all(|v| v.is_finite())
            && self.theta_rad.is_finite()
            && self.normal_m.is_finite()
    }

    fn coordinate(&self, axis: PlaneAxis) -> f64 {
        match axis {
            PlaneAxis::X => self.position_m.x,
            PlaneAxis::Y => self.position_m.y,
            PlaneAxis::Normal => self.normal_m,
        }
    }

    fn coordinate_mut(&mut self, axis: PlaneAxis) -> &mut f64 {
        match axis {
            PlaneAxis::X => &mut self.position_m.x,
            PlaneAxis::Y => &mut self.position_m.y,
            PlaneAxis::Normal => &mut self.normal_m,
        }
    }
}

/// The guard: the limits, the last good pose, and the trip once there is one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Guard {
    limits: GuardLimits,
    last_good: Option<HoldPose>,
    tripped: Option<(Trip, HoldPose)>,
}

impl Guard {
    /// A guard with `limits`, not tripped.
    ///
    /// # Errors
    /// [`GuardError`] for a force limit that is not above zero, or a range of the box that is
    /// not two numbers, low before high.
    pub fn new(limits: GuardLimits) -> Result<Self, GuardError> {
        let f = limits.contact_force_n;
        if !(f.is_finite() && f > 0.0) {
            return Err(GuardError::Force(f));
        }
        for (axis, range_m) in PlaneAxis::ALL.into_iter().zip(limits.workspace_m) {
            let [lo, hi] = range_m;
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(GuardError::Range { axis, range_m });
            }
        }
        Ok(Self {
            limits,
            last_good: None,
            tripped: None,
        })
    }

    /// Checks one cycle: the tool's planar state, and the contact force (N, in any frame:
    /// only its magnitude counts) where the servo has a valid sample. Returns the trip and the
    /// hold pose if the guard has tripped, now or before (it stays tripped until
    /// [`release`](Self::release)).
    pub fn check(
        &mut self,
        state: &PlanarState,
        force_n: Option<&Vector3<f64>>,
    ) -> Option<(Trip, HoldPose)> {
        if self.tripped.is_some() {
            return self.tripped;
        }
        let pose = HoldPose::of(state);
        let trip = if !pose.is_finite() {
            let hold = self.last_good.unwrap_or_default();
            Some((
                Trip::NotFinite {
                    what: "tool's pose",
                },
                hold,
            ))
        } else if let Some(t) = self.workspace(&pose) {
            Some(t)
        } else {
            force_n.and_then(|f| self.force(f, pose))
        };
        if trip.is_none() {
            self.last_good = Some(pose);
        }
        self.tripped = trip;
        trip
    }

    fn workspace(&self, pose: &HoldPose) -> Option<(Trip, HoldPose)> {
        let axis = PlaneAxis::ALL.into_iter().find(|a| {
            let [lo, hi] = self.limits.workspace_m[*a as usize];
            !(lo..=hi).contains(&pose.coordinate(*a))
        })?;
        // A tool that crossed a face is held on it: at most a cycle's motion back. One that
        // was never inside (the first pose checked) is held where it is: the face may be far.
        let mut hold = *pose;
        if self.last_good.is_some() {
            for a in PlaneAxis::ALL {
                let [lo, hi] = self.limits.workspace_m[a as usize];
                let c = hold.coordinate_mut(a);
                *c = c.clamp(lo, hi);
            }
        }
        let trip = Trip::Workspace {
            axis,
            at_m: pose.coordinate(axis),
            range_m: self.limits.workspace_m[axis as usize],
        };
        Some((trip, hold))
    }

    fn force(&self, f: &Vector3<f64>, pose: HoldPose) -> Option<(Trip, HoldPose)> {
        if !f.iter().all(|v| v.is_finite()) {
            let hold = self.last_good.unwrap_or(pose);
            return Some((
                Trip::NotFinite {
                    what: "contact force",
                },
                hold,
            ));
        }
        let force_n = f.norm();
        let limit_n = self.limits.contact_force_n;
        (force_n > limit_n).then_some((Trip::ContactForce { force_n, limit_n }, pose))
    }

    /// The trip and the hold pose, if the guard has tripped.
    #[must_use]
    pub fn tripped(&self) -> Option<(Trip, HoldPose)> {
        self.tripped
    }

    /// Releases the hold: the next cycle is checked afresh.
    pub fn release(&mut self) {
        self.tripped = None;
    }
}

#[cfg(test)]
#[path = "robot_guard_tests.rs"]
mod tests;
