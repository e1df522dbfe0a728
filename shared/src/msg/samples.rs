//! The per-tick samples (world, force, controller) and the servo's commands.

use crate::ident::IdentTick;
use crate::plant::PlantTruth;
use crate::sensor::Wrench;
use crate::servo::{EstimationCounters, ServoCore, ServoDiag, ServoMode};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

wire_message! {
    version = 1;
    /// The world, every servo tick: what the plant simulation knows and the controller does not.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::PlantSample")]
    pub struct PlantSample {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// Number of contacts (0, 1, 2).
        pub contact_count: u32,
        /// Servo tick index since the world started.
        pub seq: u64,
        /// Monotonic time the tick woke (ns).
        pub tick_ns: u64,
        /// Monotonic time of publication (ns).
        pub publish_ns: u64,
        /// Simulated time (s).
        pub time_s: f64,
        /// Joint angles (rad).
        pub q_rad: [f64; 2],
        /// Joint rates (rad/s).
        pub qd_rad_per_s: [f64; 2],
        /// Tool tip (m, world).
        pub tip_m: [f64; 2],
        /// Tool tip velocity (m/s, world).
        pub tip_velocity_m_per_s: [f64; 2],
        /// Total contact force on the tool (N, world).
        pub contact_force_n: [f64; 2],
        /// Force the sensor feels (N, sensor frame: x along link 2).
        pub sensor_force_n: [f64; 2],
        /// Moment the sensor feels (N·m).
        pub sensor_torque_nm: f64,
        /// Sum of normal pushes (N).
        pub normal_force_n: f64,
        /// Friction along the contact tangent (N).
        pub friction_force_n: f64,
        /// Sliding velocity along the contact tangent (m/s).
        pub sliding_velocity_m_per_s: f64,
        /// Penetration (m).
        pub depth_m: f64,
        /// Surface coordinate of the contact (m).
        pub surface_u_m: f64,
        /// True tangent angle at the contact (rad, world).
        pub tangent_angle_rad: f64,
        /// Joint torques applied (N·m).
        pub torque_nm: [f64; 2],
    }
}

impl PlantSample {
    /// The world sample of a tick.
    pub fn of_tick(tr: &PlantTruth, seq: u64, tick_ns: u64) -> Self {
        PlantSample {
            version: Self::VERSION,
            contact_count: u32::try_from(tr.contact_count).unwrap_or(u32::MAX),
            seq,
            tick_ns,
            publish_ns: 0,
            time_s: tr.time_s,
            q_rad: [tr.q[0], tr.q[1]],
            qd_rad_per_s: [tr.qd[0], tr.qd[1]],
            tip_m: [tr.tip.x, tr.tip.y],
            tip_velocity_m_per_s: [tr.tip_velocity.x, tr.tip_velocity.y],
            contact_force_n: [tr.contact_force.x, tr.contact_force.y],
            sensor_force_n: [tr.sensor_wrench.force.x, tr.sensor_wrench.force.y],
            sensor_torque_nm: tr.sensor_wrench.torque,
            normal_force_n: tr.normal_force_n,
            friction_force_n: tr.friction_force_n,
            sliding_velocity_m_per_s: tr.sliding_velocity_m_per_s,
            depth_m: tr.depth_m,
            surface_u_m: tr.surface_u_m,
            tangent_angle_rad: tr.tangent_angle_rad,
            torque_nm: [tr.torque[0], tr.torque[1]],
        }
    }

    /// The wrench the sensor feels.
    pub fn sensor_wrench(&self) -> Wrench {
        Wrench {
            force: crate::math::Vec2::new(self.sensor_force_n[0], self.sensor_force_n[1]),
            torque: self.sensor_torque_nm,
        }
    }
}

wire_flags! {
    /// [`WrenchSample::flags`].
    pub struct WrenchFlags {
        /// An axis hit its rated range.
        const SATURATED = 1;
        /// A bad sample `afs chaos` injected (for the recording and the supervisor; the
        /// servo's gate judges samples by their content, never by this flag).
        const INJECTED = 1 << 31;
    }
}

wire_message! {
    version = 1;
    /// One force-sensor sample.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::WrenchSample")]
    pub struct WrenchSample {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// [`WrenchFlags`].
        pub flags: WrenchFlags,
        /// Sensor sample index since the sensor process started.
        pub seq: u64,
        /// Monotonic time the sensor process started (ns): a restarted sensor has a later epoch
        /// and numbers its samples from 0 again.
        pub epoch_ns: u64,
        /// `seq` of the [`PlantSample`] sampled (0 from an RDT device, which does not know it).
        pub plant_seq: u64,
        /// Its `tick_ns` (0 from an RDT device).
        pub plant_tick_ns: u64,
        /// Monotonic time of the sample (ns): from an RDT device, the datagram's receipt.
        pub sample_ns: u64,
        /// Monotonic time of publication (ns).
        pub publish_ns: u64,
        /// Measured force (N, sensor frame).
        pub force_n: [f64; 2],
        /// Measured moment (N·m).
        pub torque_nm: f64,
        /// The zero-load reading taken in free air at start-up, to subtract (N); 0 from an RDT
        /// device, whose own bias does it.
        pub tare_force_n: [f64; 2],
        /// Its moment (N·m).
        pub tare_torque_nm: f64,
    }
}

impl WrenchSample {
    /// The reading as a [`Wrench`].
    pub fn wrench(&self) -> Wrench {
        Wrench {
            force: crate::math::Vec2::new(self.force_n[0], self.force_n[1]),
            torque: self.torque_nm,
        }
    }

    /// The tare as a [`Wrench`].
    pub fn tare(&self) -> Wrench {
        Wrench {
            force: crate::math::Vec2::new(self.tare_force_n[0], self.tare_force_n[1]),
            torque: self.tare_torque_nm,
        }
    }
}

wire_flags! {
    /// [`ServoSample::flags`].
    pub struct ServoFlags {
        /// The servo is in its safe state.
        const SAFE = 1;
        /// The force sample used this tick passed the checks.
        const FORCE_VALID = 2;
        /// The set-point was out of reach and held.
        const SETPOINT_HELD = 4;
        /// The servo waits for the estimator.
        const AWAITING_ESTIMATE = 8;
    }
}

wire_message! {
    version = 3;
    /// The controller's state, every servo tick.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::ServoSample.v3")]
    pub struct ServoSample {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// [`ServoMode`] as its wire code (`u32::from`, `ServoMode::try_from`).
        pub mode: u32,
        /// [`ServoFlags`].
        pub flags: ServoFlags,
        /// Why the safe state was last entered ([`crate::watchdog::Verdict`] code, 0 = never).
        pub safe_reason: u32,
        /// Servo tick index (the same as the [`PlantSample`] of the tick).
        pub seq: u64,
        /// Monotonic time the tick woke (ns).
        pub tick_ns: u64,
        /// `seq` of the [`WrenchSample`] used (u64::MAX: none yet).
        pub wrench_seq: u64,
        /// Its `sample_ns`.
        pub wrench_sample_ns: u64,
        /// Age of the force data at use: tick time − sample time (ns).
        pub force_age_ns: u64,
        /// Monotonic time of publication (ns).
        pub publish_ns: u64,
        /// Simulated time (s).
        pub time_s: f64,
        /// Measured normal force (N).
        pub normal_force_n: f64,
        /// Measured tangential force (N).
        pub tangential_force_n: f64,
        /// Friction resisting the motion, normalised to the model's reference force (N).
        pub friction_normalized_n: f64,
        /// Commanded Aω (m/s).
        pub a_omega_m_per_s: f64,
        /// Dither amplitude (m).
        pub dither_amplitude_m: f64,
        /// Dither phase (rad).
        pub dither_phase_rad: f64,
        /// Nominal tangential velocity (m/s).
        pub nominal_velocity_m_per_s: f64,
        /// Requested nominal velocity (m/s): the nominal velocity ramps towards it.
        pub velocity_target_m_per_s: f64,
        /// Measured tip velocity along the estimated tangent (m/s).
        pub tangent_velocity_m_per_s: f64,
        /// Estimated tangent angle (rad, world).
        pub tangent_angle_rad: f64,
        /// Cartesian set-point (m, world).
        pub set_point_m: [f64; 2],
        /// Joint torques (N·m).
        pub torque_nm: [f64; 2],
        /// Estimations started.
        pub estimations_started: u32,
        /// Accepted estimates.
        pub estimates: u32,
        /// Re-probes.
        pub reprobes: u32,
        /// Failed estimations.
        pub failures: u32,
        /// Estimations abandoned because the force data was lost mid-probe (the safe state).
        pub aborted: u32,
        /// Entries into the safe state.
        pub safe_entries: u32,
        /// Estimations started because they were asked for ([`ServoCommand`]).
        pub estimations_requested: u32,
        /// Estimations started by the normal force leaving its band.
        pub force_triggers: u32,
        /// Estimations started by the normal set-point drifting against the travel.
        pub slope_triggers: u32,
        /// Probe runs the contact guard abandoned.
        pub contact_losses: u32,
        /// Reserved (0; no padding left to the compiler).
        pub reserved: [u32; 2],
    }
}

impl ServoSample {
    /// The controller sample of a tick (the wrench fields are the caller's).
    pub fn of_tick(servo: &ServoCore, seq: u64, tick_ns: u64, time_s: f64) -> Self {
        let mut s = ServoSample {
            version: Self::VERSION,
            seq,
            tick_ns,
            time_s,
            wrench_seq: u64::MAX,
            ..Default::default()
        };
        s.set_diag(servo.diag(), &servo.counters());
        s
    }

    /// Fills the controller fields from the core's diagnostics and counters.
    pub fn set_diag(&mut self, d: &ServoDiag, c: &EstimationCounters) {
        self.velocity_target_m_per_s = d.velocity_target_m_per_s;
        self.flags.set(ServoFlags::SAFE, d.safe);
        self.flags.set(ServoFlags::SETPOINT_HELD, d.setpoint_held);
        self.flags.set(
            ServoFlags::AWAITING_ESTIMATE,
            d.mode == ServoMode::AwaitingEstimate,
        );
        self.mode = d.mode.into();
        self.normal_force_n = d.normal_force_n;
        self.tangential_force_n = d.tangential_force_n;
        self.friction_normalized_n = d.friction_normalized_n;
        self.a_omega_m_per_s = d.a_omega_m_per_s;
        self.dither_amplitude_m = d.dither_amplitude_m;
        self.dither_phase_rad = d.dither_phase;
        self.nominal_velocity_m_per_s = d.nominal_velocity_m_per_s;
        self.tangent_velocity_m_per_s = d.tangent_velocity_m_per_s;
        self.tangent_angle_rad = d.tangent_angle_rad;
        self.set_point_m = [d.set_point.x, d.set_point.y];
        self.torque_nm = [d.torque[0], d.torque[1]];
        self.estimations_started = c.started;
        self.estimates = c.estimates;
        self.reprobes = c.reprobes;
        self.failures = c.failures;
        self.aborted = c.aborted;
        self.safe_entries = c.safe_entries;
        self.estimations_requested = c.requested;
        self.force_triggers = c.force_triggers;
        self.slope_triggers = c.slope_triggers;
        self.contact_losses = c.contact_losses;
    }
}

/// The identification's view of a servo sample.
impl From<&ServoSample> for IdentTick {
    fn from(s: &ServoSample) -> Self {
        IdentTick {
            t: s.time_s,
            velocity_target: s.velocity_target_m_per_s,
            nominal_velocity: s.nominal_velocity_m_per_s,
            a_omega: s.a_omega_m_per_s,
            tangential_force: s.tangential_force_n,
            friction_normalized: s.friction_normalized_n,
            normal_force: s.normal_force_n,
            tangent_velocity: s.tangent_velocity_m_per_s,
            tracking: ServoMode::try_from(s.mode) == Ok(ServoMode::Track)
                && !s.flags.contains(ServoFlags::SAFE)
                && s.flags.contains(ServoFlags::FORCE_VALID),
        }
    }
}

wire_code! {
    /// [`ServoCommand::command`].
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
    #[serde(rename_all = "snake_case")]
    pub enum Command {
        /// Estimate the tangent now (stop, probe, wait for the estimate, resume), or as soon as
        /// the servo tracks again, unless an estimation started since the command was sent
        /// ([`ServoCommand::started_before`]).
        EstimateTangent = 1,
    }
}

wire_message! {
    version = 1;
    /// A command to the servo (thesis §5.3.2: surface tracking on demand).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::ServoCommand")]
    pub struct ServoCommand {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// [`Command`] as its code (a reader refuses and counts an unknown one).
        pub command: u32,
        /// Sender's sequence number.
        pub seq: u64,
        /// Monotonic time of publication (ns).
        pub publish_ns: u64,
        /// [`Command::EstimateTangent`]: the servo's `estimations_started` the sender last saw;
        /// the command lapses once more estimations than this have started.
        pub started_before: u32,
        /// Reserved (0).
        pub reserved: u32,
    }
}
