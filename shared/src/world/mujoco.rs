//! MuJoCo as the world (docs/mujoco.md): the generated model of the set-up ([`super::mjcf`]),
//! one `mj_step` per servo tick, joint torques in through `qfrc_applied`, and the truth read
//! back: joints, the tool site, and the contact wrench on the tool from MuJoCo's own contact
//! forces. Allocation-free per step.

use super::mjcf::{self, names};
use super::mujoco_body::{contacts_on, load};
use super::{MUJOCO_STATE_LEN, MujocoState};
use crate::arm::Arm;
use crate::config::SimConfig;
use crate::error::ConfigError;
use crate::math::Vec2;
use crate::plant::{PlantParams, PlantTruth, sensor_wrench};
use crate::surface::{Shape, Surface, closest_on_sinusoid};
use mujoco_rs::mujoco_c::mjtState;
use mujoco_rs::prelude::MjtObjBase as mjtObj;
use mujoco_rs::prelude::{MjData, MjModel};
use nalgebra::Vector2;
use std::sync::Arc;

/// What a restarted servo needs to resume MuJoCo exactly: time, joints, the warm start of the
/// constraint solver, and the surface's pose.
const STATE_SPEC: u32 = mjtState::mjSTATE_TIME as u32
    | mjtState::mjSTATE_QPOS as u32
    | mjtState::mjSTATE_QVEL as u32
    | mjtState::mjSTATE_ACT as u32
    | mjtState::mjSTATE_WARMSTART as u32
    | mjtState::mjSTATE_MOCAP_POS as u32
    | mjtState::mjSTATE_MOCAP_QUAT as u32;

/// The sliding speed over which the applied Stribeck term changes sign (m/s): a smooth
/// sign(v), so that the applied force does not chatter around v = 0.
const SIGN_SMOOTHING_M_PER_S: f64 = 1e-4;

/// The MuJoCo world.
#[derive(Clone)]
pub struct MujocoWorld {
    data: MjData<Arc<MjModel>>,
    arm: Arm,
    params: PlantParams,
    surface: Surface,
    tool_body: usize,
    tool_site: usize,
    /// The surface body's mocap index (moves with [`MujocoWorld::set_surface`]).
    mocap: usize,
    /// qpos and qvel addresses of joint 1 and joint 2.
    qadr: [usize; 2],
    vadr: [usize; 2],
    truth: PlantTruth,
    applied_friction: bool,
    /// The Stribeck and viscous force applied on the tool in the step under way (N, world):
    /// friction at the contact, so the sensor feels it with MuJoCo's own contact force.
    applied_force: Vec2,
}

impl std::fmt::Debug for MujocoWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MujocoWorld")
            .field("time_s", &self.time())
            .field("arm", &self.arm.params)
            .finish_non_exhaustive()
    }
}

/// MuJoCo's warnings so far in this process (e.g. "Linesearch objective is not convex").
static WARNINGS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// How many warnings MuJoCo has given in this process: counted, not printed, so that MuJoCo
/// neither writes MUJOCO_LOG.TXT into the user's folder nor logs from the servo's fast loop.
pub fn warnings() -> u64 {
    WARNINGS.load(std::sync::atomic::Ordering::Relaxed)
}

fn count_warning(m: &mujoco_rs::prelude::MjLogMessage) {
    if is_warning(m) {
        WARNINGS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }
}

/// A warning or an error; MuJoCo also logs information (each model's compile time).
fn is_warning(m: &mujoco_rs::prelude::MjLogMessage) -> bool {
    m.level() as i32 >= mujoco_rs::mujoco_c::mjtLogLevel::mjLOG_WARNING as i32
}

/// Routes MuJoCo's messages to [`count_warning`], once per process, before any model exists.
pub(super) fn install_log_handler() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // SAFETY: every MuJoCo world is built through `MujocoWorld::new`, which calls this
        // first; `Once` makes the other threads wait, so no thread uses MuJoCo meanwhile.
        unsafe { mujoco_rs::prelude::set_log_handler(count_warning) };
    });
}

/// `seconds` as a MuJoCo model's step or period (`what`), refused unless a positive time.
pub(super) fn positive_time(what: &str, seconds: f64) -> Result<(), ConfigError> {
    if seconds.is_finite() && seconds > 0.0 {
        Ok(())
    } else {
        Err(ConfigError::rule(
            what,
            format!("is {seconds} s; give a positive time"),
        ))
    }
}

fn id(model: &MjModel, kind: mjtObj, name: &str, what: &str) -> Result<usize, ConfigError> {
    model.name_to_id(kind, name).ok_or_else(|| {
        ConfigError::rule(
            "world.mjcf",
            format!("has no {what} named `{name}`; afs needs a site `tool` and a body `surface`"),
        )
    })
}

/// The generated model of `cfg`, its contact stiffness set to k_e (module docs of `mjcf`).
fn generated_model(cfg: &SimConfig) -> Result<MjModel, ConfigError> {
    let probe = load(&mjcf::generate(cfg, None))?;
    let site = id(&probe, mjtObj::mjOBJ_SITE, names::TOOL_SITE, "site")?;
    let tool = probe.site_bodyid()[site] as usize;
    let surface = id(&probe, mjtObj::mjOBJ_BODY, names::SURFACE_BODY, "body")?;
    let w = probe.body_invweight0()[tool][0] + probe.body_invweight0()[surface][0];
    let c = &cfg.plant.contact;
    let d = cfg.world.mujoco.impedance;
    let fd = cfg.world.mujoco.friction_damping_n_s_per_m;
    let solref = mjcf::ContactSolref {
        normal: mjcf::direct_solref(c.stiffness(), c.damping_n_s_per_m, d, w),
        friction: mjcf::direct_solref(fd, fd, d, w),
    };
    load(&mjcf::generate(cfg, Some(solref)))
}

impl MujocoWorld {
    /// The world of `cfg` with the arm at rest at `q`.
    pub fn new(cfg: &SimConfig, q: Vector2<f64>) -> Result<Self, ConfigError> {
        install_log_handler();
        let (model, joints) = match &cfg.world.mjcf {
            // The set-up was resolved (`world::resolve`): its arm is the model's.
            Some(path) => (super::user::load(path, cfg.servo.dt())?, [0, 1]),
            None => {
                let model = generated_model(cfg)?;
                let j1 = id(&model, mjtObj::mjOBJ_JOINT, "joint1", "joint")?;
                let j2 = id(&model, mjtObj::mjOBJ_JOINT, "joint2", "joint")?;
                (model, [j1, j2])
            }
        };
        let tool_site = id(&model, mjtObj::mjOBJ_SITE, names::TOOL_SITE, "site")?;
        let tool_body = model.site_bodyid()[tool_site] as usize;
        let surface_body = id(&model, mjtObj::mjOBJ_BODY, names::SURFACE_BODY, "body")?;
        let mocap = usize::try_from(model.body_mocapid()[surface_body]).map_err(|_| {
            ConfigError::rule("world.mjcf", "the body `surface` must be a mocap body")
        })?;
        let state = model.state_size(STATE_SPEC);
        if state > MUJOCO_STATE_LEN {
            return Err(ConfigError::rule(
                "world.mjcf",
                format!(
                    "its resumable state has {state} values (time, joints, activations, warm \
                     start, mocap poses); a world snapshot holds {MUJOCO_STATE_LEN}: drop the \
                     activations or mocap bodies afs does not place"
                ),
            ));
        }
        let qadr = joints.map(|j| model.jnt_qposadr()[j] as usize);
        let vadr = joints.map(|j| model.jnt_dofadr()[j] as usize);
        let mut world = Self {
            data: MjData::new(Arc::new(model)),
            arm: Arm::new(cfg.plant.arm),
            params: cfg.plant.clone(),
            surface: cfg.surface.clone(),
            tool_body,
            tool_site,
            mocap,
            qadr,
            vadr,
            truth: PlantTruth::default(),
            applied_friction: cfg.world.mujoco.applied_friction,
            applied_force: Vec2::zeros(),
        };
        world.set_joints(q, Vector2::zeros());
        Ok(world)
    }

    fn set_joints(&mut self, q: Vector2<f64>, qd: Vector2<f64>) {
        self.place_surface(q);
        for k in 0..2 {
            self.data.qpos_mut()[self.qadr[k]] = q[k];
            self.data.qvel_mut()[self.vadr[k]] = qd[k];
        }
        self.data.forward();
        self.truth = self.observe(q, qd, Vector2::zeros());
    }

    /// The arm model.
    pub fn arm(&self) -> &Arm {
        &self.arm
    }

    /// The parameters of the set-up.
    pub fn params(&self) -> &PlantParams {
        &self.params
    }

    /// The surface.
    pub fn surface(&self) -> &Surface {
        &self.surface
    }

    /// Moves the surface to `surface`'s frame (the shape stays the model's).
    pub fn set_surface(&mut self, surface: Surface) {
        self.surface.frame = surface.frame;
        let q = self.joints().0;
        self.place_surface(q);
    }

    /// Puts the surface body (mocap) where the surface is for the tool at `q`: at the surface
    /// frame, or, for a curved profile, with its face tangent to the curve at the point
    /// nearest the tool tip (module docs of `mjcf`).
    fn place_surface(&mut self, q: Vector2<f64>) {
        let (point, angle) = match self.surface.shape {
            Shape::Sinusoid {
                amplitude_m,
                wavelength_m,
            } => {
                let (u, w) = self.surface.to_local(self.arm.forward(q));
                let s = closest_on_sinusoid(u, w, amplitude_m, wavelength_m);
                (self.surface.point_at(s), self.surface.tangent_angle_at(s))
            }
            _ => {
                let f = self.surface.frame;
                (Vec2::new(f.origin_m[0], f.origin_m[1]), f.angle_rad)
            }
        };
        let (s, c) = (0.5 * angle).sin_cos();
        self.data.mocap_pos_mut()[self.mocap] = [point.x, point.y, 0.0];
        self.data.mocap_quat_mut()[self.mocap] = [c, 0.0, 0.0, s];
    }

    /// Truth at the start of the last step.
    pub fn truth(&self) -> &PlantTruth {
        &self.truth
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        self.data.ffi().time
    }

    /// Joint angles and rates.
    pub fn joints(&self) -> (Vector2<f64>, Vector2<f64>) {
        let (qpos, qvel) = (self.data.qpos(), self.data.qvel());
        (
            Vector2::new(qpos[self.qadr[0]], qpos[self.qadr[1]]),
            Vector2::new(qvel[self.vadr[0]], qvel[self.vadr[1]]),
        )
    }

    /// One `mj_step` (the model's timestep is the servo period) under joint torques `tau`.
    pub fn step(&mut self, tau: Vector2<f64>) {
        // The truth is the state the step started from, with the forces computed in it.
        let (q, qd) = self.joints();
        let mut applied = tau;
        if self.applied_friction {
            self.applied_force = self.extra_friction_force();
            applied += self.arm.jacobian(q).transpose() * self.applied_force;
        }
        for k in 0..2 {
            self.data.qfrc_applied_mut()[self.vadr[k]] = applied[k];
        }
        if matches!(self.surface.shape, Shape::Sinusoid { .. }) {
            self.place_surface(q);
        }
        let time_s = self.time();
        self.data.step();
        self.truth = self.observe(q, qd, tau);
        self.truth.time_s = time_s;
    }

    /// Eq. 4.5's Stribeck and viscous terms at the present sliding velocity and normal force,
    /// as a force on the tool (world): what `applied_friction` adds to MuJoCo's Coulomb cone.
    fn extra_friction_force(&self) -> Vec2 {
        let t = &self.truth;
        if t.contact_count == 0 || t.normal_force_n <= 0.0 {
            return Vec2::zeros();
        }
        let law = self
            .params
            .friction
            .scaled(t.normal_force_n / self.params.reference_normal_force_n);
        let v = t.sliding_velocity_m_per_s;
        let stribeck = law.stribeck_n
            * (-(v / law.stribeck_velocity_m_per_s).powi(2)).exp()
            * (v / SIGN_SMOOTHING_M_PER_S).tanh();
        let resist = stribeck + law.viscous_n_s_per_m * v;
        -crate::math::unit(t.tangent_angle_rad) * resist
    }

    /// The truth from MuJoCo's data: the tool site, the contact forces on the tool's body,
    /// the surface's geometry at the tip, and the sensor wrench (shared formula).
    fn observe(&self, q: Vector2<f64>, qd: Vector2<f64>, tau: Vector2<f64>) -> PlantTruth {
        let site = self.data.site_xpos()[self.tool_site];
        let tip = Vec2::new(site[0], site[1]);
        let pose = self.arm.pose(q);
        let jac = self.arm.jacobian_at(&pose);
        let vel = jac * qd;
        let qacc = self.data.qacc();
        let acc = Vector2::new(qacc[self.vadr[0]], qacc[self.vadr[1]]);
        let tip_acceleration = jac * acc + self.arm.jacobian_dot_at(&pose, qd) * qd;
        let (mut force, normal_sum, count, depth) = self.contact_force();
        if count > 0 {
            force += self.applied_force;
        }
        let (u, _) = self.surface.to_local(tip);
        let tangent_angle = self.surface.tangent_angle_at(u);
        let tangent = crate::math::unit(tangent_angle);
        PlantTruth {
            time_s: self.time(),
            q,
            qd,
            tip,
            tip_velocity: vel,
            tip_acceleration,
            contact_force: force,
            contact_count: count,
            normal_force_n: normal_sum,
            friction_force_n: if count > 0 { force.dot(&tangent) } else { 0.0 },
            sliding_velocity_m_per_s: vel.dot(&tangent),
            depth_m: depth,
            surface_u_m: u,
            tangent_angle_rad: tangent_angle,
            roughness_factor: 1.0,
            sensor_wrench: sensor_wrench(
                (pose.s12, pose.c12),
                self.params.tool_mass_kg,
                self.params.tool_length_m,
                force,
                tip_acceleration,
            ),
            torque: tau,
        }
    }

    /// Sum of the contact forces on the tool's body (world, N), of their normal parts, the
    /// number of contacts (at most 2 counted) and the deepest penetration (m).
    fn contact_force(&self) -> (Vec2, f64, usize, f64) {
        let mut force = Vec2::zeros();
        let (mut normal, mut count, mut depth) = (0.0, 0, 0.0_f64);
        for c in contacts_on(&self.data, self.tool_body) {
            force += c.normal + c.friction;
            normal += c.normal_n;
            count = (count + 1).min(2);
            depth = depth.max(c.depth_m);
        }
        (force, normal, count, depth)
    }

    /// MuJoCo's state (time, joints, warm start, surface pose).
    pub fn state(&self) -> MujocoState {
        let mut values = [0.0; MUJOCO_STATE_LEN];
        let len = self.data.read_state_into(STATE_SPEC, &mut values);
        MujocoState { len, values }
    }

    /// Restores a state taken by [`MujocoWorld::state`] (`mj_setState`), warm start included.
    pub fn restore(&mut self, s: &MujocoState) -> Result<(), ConfigError> {
        let need = self.data.model().state_size(STATE_SPEC);
        if s.len != need {
            return Err(ConfigError::rule(
                "world snapshot",
                format!(
                    "holds {} MuJoCo state values, this model needs {need}",
                    s.len
                ),
            ));
        }
        self.data
            .set_state(&s.values[..s.len], STATE_SPEC)
            .map_err(|e| ConfigError::rule("world snapshot", e.to_string()))?;
        self.data.forward();
        let (q, qd) = self.joints();
        self.truth = self.observe(q, qd, Vector2::zeros());
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::holding_torque;

    /// MuJoCo's information (a model's compile time) is not counted as a warning.
    #[test]
    fn only_warnings_and_errors_count() {
        use mujoco_rs::mujoco_c::{mjtLogLevel as L, mjtLogTopic as T};
        let message = |level| mujoco_rs::prelude::MjLogMessage::new(level, T::mjTOPIC_NONE, "x");
        assert!(!is_warning(&message(L::mjLOG_INFO)));
        assert!(!is_warning(&message(L::mjLOG_DEBUG)));
        assert!(is_warning(&message(L::mjLOG_WARNING)));
        assert!(is_warning(&message(L::mjLOG_ERROR)));
    }

    fn pressed(cfg: &SimConfig) -> (MujocoWorld, Vector2<f64>) {
        let q = cfg.start_configuration().unwrap();
        (MujocoWorld::new(cfg, q).unwrap(), q)
    }

    /// Held by exactly the torque that balances the preload, the arm settles where the
    /// contact spring k_e (solref's direct form) carries it: the depth is F/k_e to 0.1 %,
    /// and the sensor reads what the built-in plant's sensor reads there.
    #[test]
    fn contact_stiffness_is_the_set_ups() {
        let cfg = SimConfig::default();
        let (mut world, _) = pressed(&cfg);
        let f = Vec2::new(0.0, 2.5);
        for _ in 0..100_000 {
            let (qq, _) = world.joints();
            world.step(holding_torque(world.arm(), qq, f));
        }
        let t = *world.truth();
        let k = cfg.plant.contact.stiffness();
        assert!(
            (t.depth_m * k / 2.5 - 1.0).abs() < 1e-3,
            "depth {} vs {}",
            t.depth_m,
            2.5 / k
        );
        assert!((t.contact_force - f).norm() < 1e-3, "{:?}", t.contact_force);
        assert_eq!(t.contact_count, 1);
        // At rest the sensor reads the contact force in link 2's frame.
        let phi = world.arm().link2_angle(t.q);
        let b = sensor_wrench(
            phi.sin_cos(),
            cfg.plant.tool_mass_kg,
            cfg.plant.tool_length_m,
            f,
            Vec2::zeros(),
        );
        assert!(
            (t.sensor_wrench.force - b.force).norm() < 1e-6,
            "{t:?} vs {b:?}"
        );
        // A wrong stiffness fails: twice the depth is far outside the bound.
        assert!(((2.0 * t.depth_m) * k / 2.5 - 1.0).abs() > 1e-3);
    }

    /// Pushed along the surface harder than μ F_N, the tool slides against μ F_N; well inside
    /// the cone it creeps, at most a few µm/s (impratio 100).
    #[test]
    fn friction_is_the_coulomb_cone() {
        let cfg = SimConfig::default();
        let mu = cfg.plant.friction.kinetic_n / cfg.plant.reference_normal_force_n;
        for (push, sliding) in [(0.5 * mu * 2.5, false), (1.2 * mu * 2.5, true)] {
            let (mut world, _) = pressed(&cfg);
            let f = Vec2::new(-push, 2.5);
            let mut x0 = 0.0;
            for k in 0..6000 {
                let (qq, _) = world.joints();
                world.step(holding_torque(world.arm(), qq, f));
                if k == 1000 {
                    x0 = world.truth().tip.x;
                }
            }
            let t = *world.truth();
            let v = (t.tip.x - x0) / 0.5;
            if sliding {
                assert!(v > 1e-3, "v = {v}");
                assert!(
                    (t.friction_force_n + mu * t.normal_force_n).abs() < 0.01 * mu * 2.5,
                    "friction {} vs −μF_N = {}",
                    t.friction_force_n,
                    -mu * t.normal_force_n
                );
            } else {
                assert!(v.abs() < 2e-5, "creep {v} m/s");
            }
        }
    }

    /// A world restored from its state steps exactly as the original (warm start included).
    #[test]
    fn restore_resumes_bit_for_bit() {
        let cfg = SimConfig::default();
        let (mut world, q) = pressed(&cfg);
        let tau = holding_torque(world.arm(), q, Vec2::new(-0.3, 2.5));
        for _ in 0..500 {
            world.step(tau);
        }
        let s = world.state();
        let mut copy = MujocoWorld::new(&cfg, q).unwrap();
        copy.restore(&s).unwrap();
        for _ in 0..500 {
            world.step(tau);
            copy.step(tau);
        }
        assert_eq!(world.joints(), copy.joints());
        assert_eq!(world.truth(), copy.truth());
    }
}

/// Figures of docs/mujoco.md, *What MuJoCo's friction does differently*:
/// `cargo test --release -p afs-shared --features mujoco friction_under_dither -- --ignored --nocapture`
#[cfg(test)]
mod diagnostics {
    use crate::config::SimConfig;
    use crate::sim::Lockstep;
    use crate::world::WorldKind;

    /// The normal force's range and the mean friction over 0.1 s (one dither period) of the
    /// default traverse at 10 mm/s with Aω = 50 mm/s, after 3 s.
    fn under_dither(cfg: &SimConfig) -> (f64, f64, f64) {
        let mut cfg = cfg.clone();
        cfg.start_u_m = -0.03;
        let mut sim = Lockstep::new(&cfg).unwrap();
        sim.servo_mut().hybrid_mut().set_velocity(0.01);
        sim.servo_mut().set_a_omega(0.05);
        sim.run(30_000);
        let (mut lo, mut hi, mut sum) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
        for _ in 0..1000 {
            sim.step();
            let t = sim.truth();
            lo = lo.min(t.normal_force_n);
            hi = hi.max(t.normal_force_n);
            sum += t.friction_force_n;
        }
        (lo, hi, sum / 1000.0)
    }

    #[test]
    #[ignore]
    fn friction_under_dither() {
        let builtin = SimConfig::default();
        let (lo, hi, f) = under_dither(&builtin);
        println!("built-in: F_N {lo:.2}–{hi:.2} N, mean friction {f:+.3} N");
        for (damping, noslip) in [(50.0, 0), (5.0, 0), (5.0, 20)] {
            let mut cfg = SimConfig::default();
            cfg.world.kind = WorldKind::Mujoco;
            cfg.world.mujoco.friction_damping_n_s_per_m = damping;
            cfg.world.mujoco.noslip_iterations = noslip;
            let (lo, hi, f) = under_dither(&cfg);
            println!(
                "MuJoCo, friction damping {damping} N·s/m, noslip {noslip}: F_N {lo:.2}–{hi:.2} N, \
                 mean friction {f:+.3} N"
            );
        }
    }
}
