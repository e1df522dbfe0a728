//! afs::observe::record

use afs::observe::record::{Flat, export_csv, sample_topics};
use serde_json::json;

#[test]
fn fields_flatten_to_columns_with_plain_strings() {
    let mut flat = Flat::default();
    flat.fill(&json!({"a": 1.5, "b": {"c": [1, 2]}, "mode": "probing, fast", "x": null}));
    let got: Vec<(&str, &str)> = flat
        .keys()
        .iter()
        .zip(flat.values())
        .map(|(k, v)| (k.as_str(), v.as_str()))
        .collect();
    let want = [
        ("a", "1.5"),
        ("b.c[0]", "1"),
        ("b.c[1]", "2"),
        ("mode", "probing, fast"),
        ("x", ""),
    ];
    assert_eq!(got, want);
    // The csv crate quotes the comma.
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(flat.values()).unwrap();
    let text = String::from_utf8(w.into_inner().unwrap()).unwrap();
    assert_eq!(text, "1.5,1,2,\"probing, fast\",\n");
    // The buffers are reused: a shorter message leaves nothing of the longer one.
    flat.fill(&json!({"b": [true]}));
    assert_eq!(flat.keys(), ["b[0]"]);
    assert_eq!(flat.values(), ["true"]);
}

/// A recording of `messages` (topic, JSON), written as the recorder writes one.
fn recording(dir: &std::path::Path, messages: &[(&str, serde_json::Value)]) -> std::path::PathBuf {
    let path = dir.join("r.mcap");
    let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .create(file)
        .unwrap();
    let mut channels = std::collections::BTreeMap::new();
    for (i, (topic, v)) in messages.iter().enumerate() {
        let ch = *channels.entry(*topic).or_insert_with(|| {
            let schema = w.add_schema("t", "jsonschema", b"{}").unwrap();
            w.add_channel(schema, topic, "json", &Default::default())
                .unwrap()
        });
        let header = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: i as u32,
            log_time: i as u64,
            publish_time: i as u64,
        };
        w.write_to_known_channel(&header, &serde_json::to_vec(v).unwrap())
            .unwrap();
    }
    w.finish().unwrap();
    path
}

#[test]
fn the_export_keeps_the_first_messages_columns_and_the_plot_samples_evenly() {
    let dir = std::env::temp_dir().join(format!("afs-export-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut messages = vec![
        ("/servo", json!({"t": 0, "f": [1.0, 2.0], "mode": "a"})),
        ("/plant", json!({"t": 0, "u": 5})),
        // A field missing, one unknown, and the rest in their places.
        ("/servo", json!({"t": 1, "f": [3.0, 4.0], "extra": 9})),
        ("/servo", json!({"t": 2, "f": [5.0, 6.0], "mode": "b"})),
    ];
    let rec = recording(&dir, &messages);
    let out = dir.join("csv");
    let files = export_csv(&rec, &out).unwrap();
    assert_eq!(files, [out.join("plant.csv"), out.join("servo.csv")]);
    let servo = std::fs::read_to_string(out.join("servo.csv")).unwrap();
    assert_eq!(
        servo,
        "f[0],f[1],mode,t\n1.0,2.0,a,0\n3.0,4.0,,1\n5.0,6.0,b,2\n"
    );
    let plant = std::fs::read_to_string(out.join("plant.csv")).unwrap();
    assert_eq!(plant, "t,u\n0,5\n");

    // 10 plant messages sampled to at most about 4: every second one, from the first.
    messages = (0..10).map(|i| ("/plant", json!({"t": i}))).collect();
    messages.push(("/other", json!({"t": 99})));
    let rec = recording(&dir, &messages);
    let kept = sample_topics(&rec, &["/plant", "/servo"], 4).unwrap();
    let t: Vec<i64> = kept["/plant"]
        .iter()
        .map(|m| m["t"].as_i64().unwrap())
        .collect();
    assert_eq!(t, [0, 2, 4, 6, 8]);
    assert_eq!(kept.len(), 1, "only the wanted topics: {kept:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
