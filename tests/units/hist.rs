//! afs::hist

use afs::hist::*;

/// A histogram survives the V2 round trip and its percentiles are the recorded values'.
#[test]
fn round_trip_and_percentiles() {
    let mut h = new().unwrap();
    for v in 1..=10_000u64 {
        record(&mut h, v * 1000);
    }
    let dir = std::env::temp_dir().join(format!("afs-hist-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("h.hdr");
    save(&h, &p).unwrap();
    let back = load(&p).unwrap();
    assert_eq!(back, h);
    let summary = Summary::of(&back);
    assert_eq!(summary.count, 10_000);
    let s = summary.quantiles;
    // 3 significant digits: within 0.1 %.
    assert!((s.p50 - 5000.0).abs() <= 5.0, "{}", s.p50);
    assert!((s.p99 - 9900.0).abs() <= 10.0, "{}", s.p99);
    assert!((s.max - 10_000.0).abs() <= 10.0, "{}", s.max);
    let r = s.ratio_to(&s);
    assert_eq!(r.p50, 1.0);
    assert_eq!(
        s.ratio_to(&QuantilesUs::constant(2500.0)).p50,
        s.p50 / 2500.0
    );
    // The JSON of a summary is flat, and reads back (NaN as null).
    let json = serde_json::to_value(summary).unwrap();
    assert_eq!(json["count"], 10_000);
    assert_eq!(json["p50"], s.p50);
    let empty = Summary::of(&new().unwrap());
    let text = serde_json::to_string(&empty).unwrap();
    let read: Summary = serde_json::from_str(&text).unwrap();
    assert!(read.count == 0 && read.quantiles.p99.is_nan(), "{text}");
    write_hgrm(&back, &dir.join("h.hgrm")).unwrap();
    let text = std::fs::read_to_string(dir.join("h.hgrm")).unwrap();
    assert!(text.contains("Total count    =        10000"), "{text}");
    std::fs::remove_dir_all(&dir).unwrap();
}
