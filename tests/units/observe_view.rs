//! afs::observe::view

use afs::observe::topics::{Rec, TOPICS, json_schema};
use afs::observe::view::*;
use afs_shared::msg::{PlantSample, ServoSample, WrenchSample};

#[test]
fn ticks_are_kept_at_the_same_seq_and_force_samples_by_time() {
    // 10 kHz ticks at 100 Hz: every 100th, learnt from the world stream.
    let mut d = Decimator::new(100.0, None);
    let mut kept = Vec::new();
    for seq in 1..=1000u64 {
        let p = PlantSample {
            seq,
            time_s: seq as f64 * 1e-4,
            ..Default::default()
        };
        let s = ServoSample {
            seq,
            ..Default::default()
        };
        let (kp, ks) = (d.keep(&Rec::Plant(p)), d.keep(&Rec::Servo(s)));
        assert_eq!(kp, ks, "tick {seq}");
        if kp {
            kept.push(seq);
        }
    }
    assert_eq!(kept, [100, 200, 300, 400, 500, 600, 700, 800, 900, 1000]);
    // Given the tick rate, from the start.
    let mut g = Decimator::new(2_500.0, Some(10_000.0));
    let p0 = PlantSample::default();
    assert!(g.keep(&Rec::Plant(p0)));
    // 7 kHz force samples at 1 kHz: one per millisecond.
    let mut w = Decimator::new(1_000.0, None);
    let n = (0..7000u64)
        .filter(|i| {
            w.keep(&Rec::Wrench(WrenchSample {
                sample_ns: i * 1_000_000_000 / 7000,
                ..Default::default()
            }))
        })
        .count();
    assert_eq!(n, 1000);
}

/// The panels of examples/foxglove-layout.json in its tree, and each of their message
/// paths names a topic the view publishes and a field of that topic's schema.
#[test]
fn the_layout_plots_fields_the_view_publishes() {
    let layout: serde_json::Value =
        serde_json::from_str(include_str!("../../examples/foxglove-layout.json")).unwrap();
    let cfg = layout["configById"].as_object().unwrap();
    fn leaves(v: &serde_json::Value, out: &mut Vec<String>) {
        match v {
            serde_json::Value::String(s) => out.push(s.clone()),
            serde_json::Value::Object(o) => {
                for k in ["first", "second"] {
                    leaves(&o[k], out);
                }
            }
            _ => panic!("a layout node is a panel id or a split: {v}"),
        }
    }
    let mut panels = Vec::new();
    leaves(&layout["layout"], &mut panels);
    panels.sort();
    let mut ids: Vec<String> = cfg.keys().cloned().collect();
    ids.sort();
    assert_eq!(panels, ids);
    let fields = |topic: &str| -> Vec<String> {
        let ty = TOPICS
            .iter()
            .find(|t| t.0 == topic)
            .unwrap_or_else(|| panic!("the layout reads {topic}, which the view does not publish"));
        let schema: serde_json::Value = serde_json::from_str(&json_schema(ty.1)).unwrap();
        schema["properties"]
            .as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect()
    };
    let mut checked = 0;
    for (id, panel) in cfg {
        if let Some(t) = panel["topicPath"].as_str() {
            fields(t);
            checked += 1;
        }
        for path in panel["paths"].as_array().into_iter().flatten() {
            let v = path["value"].as_str().unwrap();
            let (topic, field) = v.split_once('.').unwrap();
            assert!(fields(topic).iter().any(|f| f == field), "{id}: {v}");
            checked += 1;
        }
    }
    // Normal and tangential force, Aω, tangent error, force age, the safe-state flags; the
    // insertion's depth and forces, Whitney's axes, phase and contact states.
    for path in [
        "/live.normal_force_n",
        "/live.tangential_force_n",
        "/live.a_omega_m_per_s",
        "/live.tangent_error_deg",
        "/live.force_age_us",
        "/live.safe",
        "/insertion.depth_mm",
        "/insertion.force_y_n",
        "/insertion.whitney_m",
        "/insertion.phase",
        "/insertion.true_state",
        "/insertion.estimated_state",
    ] {
        assert!(
            cfg.values().any(|p| p["paths"]
                .as_array()
                .into_iter()
                .flatten()
                .any(|x| x["value"] == path)),
            "no panel shows {path}"
        );
    }
    assert!(checked >= 15, "{checked}");
}

#[test]
fn bad_settings_are_refused_with_the_fix() {
    let e = ViewSettings::parse("localhost", 100.0).unwrap_err();
    assert!(format!("{e:#}").contains("HOST:PORT"), "{e:#}");
    for hz in [0.0, -1.0, f64::NAN, 1e6] {
        assert!(ViewSettings::parse(DEFAULT_ADDR, hz).is_err(), "{hz}");
    }
    assert!(ViewSettings::parse("127.0.0.1:0", 50.0).is_ok());
}
