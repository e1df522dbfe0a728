//! The byte layout of every message, for `docs/messages.md`, the recording's JSON schemas and
//! clients in other languages.

use super::*;
use crate::arm::JointServoState;
use crate::dither::DitherState;
use crate::hybrid::HybridState;
use crate::servo::ServoState;
use crate::tuner::TunerState;
use crate::window::{PeriodWindowState, SlidingSummary};
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// One field of a message's byte layout.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldLayout {
    /// Field name.
    pub name: &'static str,
    /// Type as a C-like spelling (`f64[2]` is two f64).
    pub ty: &'static str,
    /// Byte offset.
    pub offset: usize,
    /// Byte size.
    pub size: usize,
}

/// A message's byte layout, for `docs/messages.md` and clients in other languages.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MessageLayout {
    /// Rust type.
    pub rust: &'static str,
    /// The iceoryx2 type name a client must use.
    pub type_name: &'static str,
    /// Total size (bytes).
    pub size: usize,
    /// Alignment (bytes).
    pub align: usize,
    /// Fields in order.
    pub fields: Vec<FieldLayout>,
}

fn field_size<T, F>(_: fn(&T) -> &F) -> usize {
    core::mem::size_of::<F>()
}

macro_rules! layout {
    ($ty:ty, $rust:literal, [$($field:ident : $fty:literal),* $(,)?]) => {
        MessageLayout {
            rust: $rust,
            // SAFETY: type_name returns the derive attribute's string.
            type_name: unsafe { <$ty as ZeroCopySend>::type_name() },
            size: core::mem::size_of::<$ty>(),
            align: core::mem::align_of::<$ty>(),
            fields: vec![$(FieldLayout {
                name: stringify!($field),
                ty: $fty,
                offset: core::mem::offset_of!($ty, $field),
                size: field_size::<$ty, _>(|x| &x.$field),
            }),*],
        }
    };
}

impl MessageLayout {
    /// The layout as a Markdown table (what `docs/messages.md` shows).
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "### `{}` (type name `{}`, {} bytes, align {})\n\n| offset | size | type | field |\n|---:|---:|---|---|\n",
            self.rust, self.type_name, self.size, self.align
        );
        let mut end = 0;
        for f in &self.fields {
            if f.offset > end {
                s += &format!("| {end} | {} | pad | |\n", f.offset - end);
            }
            s += &format!("| {} | {} | {} | `{}` |\n", f.offset, f.size, f.ty, f.name);
            end = f.offset + f.size;
        }
        if self.size > end {
            s += &format!("| {end} | {} | pad | |\n", self.size - end);
        }
        s
    }
}

/// The layouts of every message, in the order `docs/messages.md` lists them.
pub fn layouts() -> Vec<MessageLayout> {
    vec![
        layout!(WrenchSample, "WrenchSample", [
            version: "u32", flags: "u32", seq: "u64", epoch_ns: "u64", plant_seq: "u64",
            plant_tick_ns: "u64", sample_ns: "u64", publish_ns: "u64", force_n: "f64[2]",
            torque_nm: "f64", tare_force_n: "f64[2]", tare_torque_nm: "f64",
        ]),
        layout!(PlantSample, "PlantSample", [
            version: "u32", contact_count: "u32", seq: "u64", tick_ns: "u64",
            publish_ns: "u64", time_s: "f64", q_rad: "f64[2]", qd_rad_per_s: "f64[2]",
            tip_m: "f64[2]", tip_velocity_m_per_s: "f64[2]", contact_force_n: "f64[2]",
            sensor_force_n: "f64[2]", sensor_torque_nm: "f64", normal_force_n: "f64",
            friction_force_n: "f64", sliding_velocity_m_per_s: "f64", depth_m: "f64",
            surface_u_m: "f64", tangent_angle_rad: "f64", torque_nm: "f64[2]",
        ]),
        layout!(ServoSample, "ServoSample", [
            version: "u32", mode: "u32", flags: "u32", safe_reason: "u32", seq: "u64",
            tick_ns: "u64", wrench_seq: "u64", wrench_sample_ns: "u64", force_age_ns: "u64",
            publish_ns: "u64", time_s: "f64", normal_force_n: "f64",
            tangential_force_n: "f64", friction_normalized_n: "f64", a_omega_m_per_s: "f64",
            dither_amplitude_m: "f64", dither_phase_rad: "f64",
            nominal_velocity_m_per_s: "f64", velocity_target_m_per_s: "f64",
            tangent_velocity_m_per_s: "f64",
            tangent_angle_rad: "f64", set_point_m: "f64[2]", torque_nm: "f64[2]",
            estimations_started: "u32", estimates: "u32", reprobes: "u32", failures: "u32",
            aborted: "u32", safe_entries: "u32", estimations_requested: "u32", reserved: "u32",
        ]),
        layout!(ServoCommand, "ServoCommand", [
            version: "u32", command: "u32", seq: "u64", publish_ns: "u64",
            started_before: "u32", reserved: "u32",
        ]),
        layout!(Quantiles, "Quantiles", [
            p50: "u64", p90: "u64", p99: "u64", p999: "u64", p9999: "u64", max: "u64",
        ]),
        layout!(LoopStats, "LoopStats", [
            version: "u32", flags: "u32", seq: "u64", publish_ns: "u64", period_ns: "u64",
            ticks: "u64", misses: "u64", wake_latency: "Quantiles", exec: "Quantiles",
            force_age: "Quantiles", bad_non_finite: "u64", bad_out_of_range: "u64",
            bad_seq_repeat: "u64", bad_seq_backwards: "u64", bad_future: "u64",
            bad_version: "u64", stale_ticks: "u64", safe_entries: "u64", safe_ticks: "u64",
            requests: "u64", retries: "u64", answers: "u64", publish_failures: "u64",
            commands: "u64", bad_commands: "u64",
        ]),
        layout!(SensorStats, "SensorStats", [
            version: "u32", source: "u32", seq: "u64", publish_ns: "u64", published: "u64",
            late_periods: "u64", rdt_datagrams: "u64", rdt_bad_datagrams: "u64",
            rdt_records: "u64", rdt_lost: "u64", rdt_repeated: "u64", rdt_reordered: "u64",
            rdt_late: "u64", rdt_status_errors: "u64", rdt_last_status: "u32",
            rdt_streaming: "u32", rdt_requests: "u64", rdt_interval: "Quantiles",
            rdt_excess_delay: "Quantiles",
        ]),
        layout!(crate::tangent::ProbeSample, "ProbeSample", [
            t: "f64", force: "f64[2]", tip: "f64[2]", phase: "f64", probe: "u8",
            measured: "bool",
        ]),
        layout!(ProbePlanMsg, "ProbePlanMsg", [
            count: "u32", periods: "u32", offsets_rad: "f64[6]", amplitude_m: "f64",
            frequency_hz: "f64", ramp_s: "f64", settle_s: "f64", dither_hz: "f64",
        ]),
        layout!(TangentParamsMsg, "TangentParamsMsg", [
            periods: "u32", reserved: "u32", probe_angles_deg: "f64[2]",
            reprobe_angles_deg: "f64[2]", amplitude_m: "f64", frequency_hz: "f64",
            ramp_s: "f64", settle_s: "f64", sign_threshold: "f64", equal_threshold: "f64",
            max_std_error_deg: "f64", contact_loss_fraction: "f64", noise_std_n: "f64",
        ]),
        layout!(TangentRequestHeader, "TangentRequestHeader", [
            version: "u32", reprobe: "u32", request_id: "u64", attempt: "u32",
            reserved: "u32", publish_ns: "u64", base_angle_rad: "f64", plan: "ProbePlanMsg",
            params: "TangentParamsMsg",
        ]),
        layout!(TangentResponse, "TangentResponse", [
            version: "u32", outcome: "u32", request_id: "u64", publish_ns: "u64",
            code: "u32", method: "u32", probes: "u32", iterations: "u32",
            alpha0_rad: "f64", tangent_angle_rad: "f64", std_error_rad: "f64",
            residual_n: "f64", noise_n: "f64", snr: "f64", stiffness_n_per_m: "f64",
            thesis_alpha0_rad: "f64", thesis_6_1_alpha0_rad: "f64", ratio_alpha0_rad: "f64",
            error_values: "f64[2]", plan: "ProbePlanMsg",
        ]),
        layout!(RotationSample, "RotationSample", [
            t: "f64", phase: "f64", force_n: "f64[2]", dither: "u32", reserved: "u32",
        ]),
        layout!(RotationRequestHeader, "RotationRequestHeader", [
            version: "u32", centres: "u32", request_id: "u64", publish_ns: "u64",
            centre_m: "f64[6][2]", amplitude_rad: "f64", suppression_hz: "f64",
        ]),
        layout!(RotationResponse, "RotationResponse", [
            version: "u32", outcome: "u32", request_id: "u64", publish_ns: "u64",
            centre_m: "f64[2]", thesis_centre_m: "f64[2]", response_matrix: "f64[4]",
            coupling: "f64",
        ]),
        layout!(FrictionReport, "FrictionReport", [
            version: "u32", status: "u32", seq: "u64", publish_ns: "u64", windows: "u64",
            speeds: "u32", reserved: "u32", mu: "f64", mu_std: "f64", kinetic_n: "f64",
            viscous_n_s_per_m: "f64", stribeck_n: "f64", stribeck_velocity_m_per_s: "f64",
            rms_residual_n: "f64",
        ]),
        layout!(ProcessStatus, "ProcessStatus", [
            name: "u8[16]", pid: "i32", state: "u32", restarts: "u32", last_exit: "i32",
        ]),
        layout!(SupervisorStatus, "SupervisorStatus", [
            version: "u32", process_count: "u32", seq: "u64", publish_ns: "u64", pid: "i32",
            phase: "u32", scenario: "u8[32]", elapsed_s: "f64", duration_s: "f64",
            processes: "ProcessStatus[8]",
        ]),
        layout!(BoardStartup, "BoardStartup", [
            version: "u32", board: "u32", pid: "i32", reserved: "u32", main_ns: "u64",
            node_ns: "u64", ports_ns: "u64", prepared_ns: "u64", input_ns: "u64",
            rt_ns: "u64", data_ns: "u64",
        ]),
        layout!(ServoBatch, "ServoBatch", [
            version: "u32", count: "u32", seq: "u64", epoch: "u64", missed: "u64",
            publish_ns: "u64", samples: "ServoSample[50]",
        ]),
        layout!(WorldSnapshot, "WorldSnapshot", [
            version: "u32", driver_leg: "u32", seq: "u64", time_s: "f64", q_rad: "f64[2]",
            qd_rad_per_s: "f64[2]", friction_face: "u64[2]",
            friction_deflection_m: "f64[2]", driver_leg_start: "f64[2]",
            controller: "ServoState", plant: "PlantSample",
        ]),
        layout!(ServoState, "ServoState", [
            mode: "u32", flags: "u32", last_trigger: "u32", reserved: "u32",
            counters: "u32[10]", joints: "JointServoState", hybrid: "HybridState",
            dither: "DitherState", tuner: "TunerState", tare: "f64[3]", last_q_d_rad: "f64[2]",
            resume_velocity_m_per_s: "f64", normal_filtered_n: "f64", odometer_m: "f64[2]",
            last_estimate: "f64[2]", curvature_per_m: "f64", curve_base_rad: "f64",
            drift_rad: "f64", stopped_settled_s: "f64[2]", normal_window: "SlidingSummary",
            safe: "f64[4]", resume_a_omega_m_per_s: "f64", last_stroke_m: "f64[2]",
        ]),
        layout!(JointServoState, "JointServoState", [
            integral_rad_s: "f64[2]", integrating: "u32", reserved: "u32",
        ]),
        layout!(HybridState, "HybridState", [
            origin_m: "f64[2]", tangent_angle_rad: "f64", s_m: "f64", s_dot_m_per_s: "f64",
            velocity_target_m_per_s: "f64", depth_m: "f64", depth_rate_m_per_s: "f64",
            preload_n: "f64", hooke_stiffness_n_per_m: "f64",
        ]),
        layout!(DitherState, "DitherState", [
            phase_rad: "f64", amplitude_m: "f64", sin_cos: "f64[2]", wrapped: "u32",
            reserved: "u32",
        ]),
        layout!(TunerState, "TunerState", [
            a_omega_m_per_s: "f64", stribeck_velocity_estimate_m_per_s: "f64",
            transmission: "f64", friction_scale: "f64", window: "SlidingSummary",
            periods: "PeriodWindowState",
        ]),
        layout!(SlidingSummary, "SlidingSummary", [
            len: "u64", mean: "f64", variance: "f64",
        ]),
        layout!(PeriodWindowState, "PeriodWindowState", [
            current: "f64[8]", ring: "f64[16][8]", filled: "u32", head: "u32",
        ]),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/messages.md shows every message's layout exactly as compiled (regenerate it with
    /// `afs messages` after changing a message), and every field is listed: the fields' sizes
    /// plus padding add up to the size.
    #[test]
    fn layouts_match_the_documentation() {
        let doc = include_str!("../../../docs/messages.md");
        for l in layouts() {
            let listed: usize = l.fields.iter().map(|f| f.size).sum();
            assert!(listed <= l.size, "{}", l.rust);
            let last = l.fields.last().map_or(0, |f| f.offset + f.size);
            assert!(
                l.size - last < l.align,
                "{}: a field is missing at the end",
                l.rust
            );
            for w in l.fields.windows(2) {
                assert!(
                    w[1].offset - (w[0].offset + w[0].size) < 8,
                    "{}: a field is missing before {}",
                    l.rust,
                    w[1].name
                );
            }
            assert!(
                doc.contains(&l.markdown()),
                "docs/messages.md is out of date for {}; run `afs messages`:\n{}",
                l.rust,
                l.markdown()
            );
        }
    }

    /// The type names clients must use.
    #[test]
    fn type_names_are_stable() {
        // SAFETY: type_name only returns the attribute's string.
        unsafe {
            assert_eq!(
                <WrenchSample as ZeroCopySend>::type_name(),
                "afs::WrenchSample"
            );
            assert_eq!(
                <PlantSample as ZeroCopySend>::type_name(),
                "afs::PlantSample"
            );
            assert_eq!(
                <ServoSample as ZeroCopySend>::type_name(),
                "afs::ServoSample"
            );
            assert_eq!(<LoopStats as ZeroCopySend>::type_name(), "afs::LoopStats");
            assert_eq!(
                <SensorStats as ZeroCopySend>::type_name(),
                "afs::SensorStats"
            );
        }
    }
}
