//! The insertion's settings, the `[insertion]` table of a set-up: the fit, the initial
//! errors, the method and its limits, what drives the flange and what the robot knows of the
//! part (docs/insertion.md).

use super::controller::{ControllerParams, Method};
use super::plant::PegParams;
use super::whitney::Fit;
use crate::error::ConfigError;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, Uniform};
use serde::{Deserialize, Serialize};

/// The insertion's settings: the `[insertion]` table of a set-up (`afs experiment --config`, a
/// stack file's `[sim.insertion]`), which `afs experiment insertion --clearance ...` overrides.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InsertionOptions {
    /// Clearance ratio c = (D − d)/D.
    pub clearance_ratio: f64,
    /// Friction coefficient μ at every contact.
    pub mu: f64,
    /// Chamfer leg (mm); 0: none.
    pub chamfer_mm: f64,
    /// Initial lateral error (mm); None: uniform in ±2 mm per seed.
    pub lateral_mm: Option<f64>,
    /// Initial angle error (deg); None: uniform in ±2° per seed.
    pub angle_deg: Option<f64>,
    /// The controller.
    pub method: Method,
    /// Time allowed (s).
    pub time_limit_s: f64,
    /// The force limit, as a multiple of the commanded insertion force.
    pub force_limit_factor: f64,
    /// What positions the wrist's flange: `ideal` (exactly where commanded) or `arm` (the
    /// three-joint arm under its joint servos).
    pub drive: Drive,
    /// What the robot knows of the part's orientation: `known` (a fixtured part: the peg's
    /// tilt is measured against the hole's axis) or `unknown` (the robot's frame is turned by
    /// the angle error, and the controller estimates the face's tangent).
    pub part_frame: PartFrame,
    /// The holding compliance: the wrist's translational stiffness k_x = k_y (N/m). A robot
    /// under impedance control is this wrist; its rotational stiffness k_θ scales with it
    /// (k_θ = k_x · 2.5e-3 m², the default's 5 N·m/rad at 2 kN/m) unless set below.
    pub wrist_stiffness_n_per_m: f64,
    /// The wrist's rotational stiffness k_θ (N·m/rad); None: scaled with k_x as above.
    pub wrist_rotational_stiffness_nm_per_rad: Option<f64>,
}

/// What the robot knows of the part's orientation (docs/insertion-frame.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PartFrame {
    /// Known: the robot's frame is the part's.
    #[default]
    Known,
    /// Unknown: the robot's frame is the part's turned by the seed's angle error.
    Unknown,
}

impl PartFrame {
    /// Its name in a set-up and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Known => "known",
            Self::Unknown => "unknown",
        }
    }

    /// The frame called `s`.
    pub fn parse(s: &str) -> Option<Self> {
        [Self::Known, Self::Unknown]
            .into_iter()
            .find(|d| d.name() == s)
    }
}

impl Default for InsertionOptions {
    fn default() -> Self {
        Self {
            clearance_ratio: 0.002,
            mu: 0.3,
            chamfer_mm: 0.5,
            lateral_mm: None,
            angle_deg: None,
            method: Method::Dither,
            time_limit_s: 10.0,
            force_limit_factor: 3.0,
            drive: Drive::Ideal,
            part_frame: PartFrame::Known,
            wrist_stiffness_n_per_m: DEFAULT_WRIST_N_PER_M,
            wrist_rotational_stiffness_nm_per_rad: None,
        }
    }
}

/// The default wrist's translational stiffness (N/m) and the length² that turns it into the
/// rotational one (m²): 2 kN/m and 5 N·m/rad, a servo wrist at the gripper.
const DEFAULT_WRIST_N_PER_M: f64 = 2e3;
const WRIST_ROTATION_M2: f64 = 5.0 / DEFAULT_WRIST_N_PER_M;

impl InsertionOptions {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ConfigError> {
        // (name, value, upper bound, whether 0 is allowed): a chamfer may be 0 (a sharp edge);
        // a clearance, a friction or a time may not.
        let rules = [
            ("insertion.clearance", self.clearance_ratio, 0.5, false),
            ("insertion.mu", self.mu, 2.0, false),
            ("insertion.chamfer_mm", self.chamfer_mm, 3.0, true),
            ("insertion.time_limit_s", self.time_limit_s, 600.0, false),
            (
                "insertion.wrist_stiffness_n_per_m",
                self.wrist_stiffness_n_per_m,
                1e7,
                false,
            ),
            (
                "insertion.wrist_rotational_stiffness_nm_per_rad",
                self.wrist_rotational_stiffness_nm_per_rad.unwrap_or(1.0),
                1e5,
                false,
            ),
        ];
        for (name, v, max, zero_ok) in rules {
            if !(v.is_finite() && (v > 0.0 || zero_ok && v == 0.0) && v < max) {
                let zero = if zero_ok { " or 0" } else { "" };
                return Err(ConfigError::rule(
                    name,
                    format!("is {v}; it must be in (0, {max}){zero}"),
                ));
            }
        }
        for (name, v, limit) in [
            ("insertion.lateral_mm", self.lateral_mm, 4.0),
            ("insertion.angle_deg", self.angle_deg, 10.0),
        ] {
            if let Some(v) = v
                && !(v.is_finite() && v.abs() <= limit)
            {
                return Err(ConfigError::rule(
                    name,
                    format!("is {v}; it must be within ±{limit}"),
                ));
            }
        }
        Ok(())
    }

    /// The peg and hole with these settings' fit, chamfer and friction.
    pub fn peg_params(&self) -> PegParams {
        let mut params = PegParams::default();
        params.geometry.clearance_ratio = self.clearance_ratio;
        params.geometry.chamfer_m = self.chamfer_mm * 1e-3;
        params.friction = params.friction.scaled(self.mu / params.mu());
        let k = self.wrist_stiffness_n_per_m;
        let k_theta = self
            .wrist_rotational_stiffness_nm_per_rad
            .unwrap_or(k * WRIST_ROTATION_M2);
        params.wrist_stiffness = [k, k, k_theta];
        params
    }

    /// The controller's settings: it knows μ as friction identification gives it, and
    /// estimates the face's tangent when it does not know the part's orientation.
    pub fn controller_params(&self) -> ControllerParams {
        let mut p = ControllerParams {
            mu: self.mu,
            ..ControllerParams::default()
        };
        p.face.estimate = self.part_frame == PartFrame::Unknown;
        if p.face.estimate {
            p.face.prior_error_deg = self.angle_error_bound_rad().to_degrees();
        }
        p
    }

    /// The contact force that ends an insertion as failed (N).
    pub fn force_limit_n(&self) -> f64 {
        self.force_limit_factor * self.controller_params().insertion_force_n
    }

    /// Whitney's fit of the peg in the hole.
    pub fn fit(&self) -> Fit {
        let g = self.peg_params().geometry;
        Fit {
            peg_width_m: g.peg_width_m,
            clearance_ratio: g.clearance_ratio,
            friction: self.mu,
        }
    }

    /// The largest initial angle error (rad): the one set, or 2°.
    pub fn angle_error_bound_rad(&self) -> f64 {
        self.angle_deg.map_or(2.0, f64::abs).to_radians()
    }

    /// The initial errors of `seed` (m, rad): uniform ±2 mm, ±2° unless set.
    pub fn initial_errors(&self, seed: u64) -> (f64, f64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x1a5e_7100);
        let u = Uniform::new_inclusive(-1.0f64, 1.0).expect("valid range");
        let (a, b) = (u.sample(&mut rng), u.sample(&mut rng));
        (
            self.lateral_mm.unwrap_or(2.0 * a) * 1e-3,
            self.angle_deg.unwrap_or(2.0 * b).to_radians(),
        )
    }
}

/// What positions the wrist's flange.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Drive {
    /// An ideal position-controlled arm: the flange is exactly where the controller commands.
    #[default]
    Ideal,
    /// The three-joint arm with its dynamics under its joint servos.
    Arm,
}

impl Drive {
    /// Its name in a set-up and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ideal => "ideal",
            Self::Arm => "arm",
        }
    }

    /// The drive called `s`.
    pub fn parse(s: &str) -> Option<Self> {
        [Self::Ideal, Self::Arm].into_iter().find(|d| d.name() == s)
    }
}
