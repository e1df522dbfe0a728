use super::*;

fn tick(seq: u64, valid: bool, safe: bool, wrench_ns: u64) -> (PlantSample, ServoSample) {
    let tick_ns = 1_000_000_000 + seq * 100_000;
    let p = PlantSample {
        seq,
        time_s: seq as f64 * 1e-4,
        normal_force_n: 2.5,
        ..Default::default()
    };
    let s = ServoSample {
        seq,
        tick_ns,
        flags: if valid {
            ServoFlags::FORCE_VALID
        } else {
            ServoFlags::empty()
        } | if safe {
            ServoFlags::SAFE
        } else {
            ServoFlags::empty()
        },
        wrench_sample_ns: wrench_ns,
        normal_force_n: 2.5,
        tangential_force_n: -1.0,
        ..Default::default()
    };
    (p, s)
}

/// A sensor that stops at tick 100: the servo goes safe at tick 116; the latency is the
/// first safe tick's time minus the last good sample's, 1.6 ms here.
#[test]
fn safe_latency_is_measured_from_the_last_good_sample() {
    let mut m = FaultMonitor::new(2.5, 0.0);
    let mut last = 0;
    for seq in 0..300 {
        let valid = !(100..200).contains(&seq);
        let safe = (116..230).contains(&seq);
        let (p, mut s) = tick(seq, valid, safe, 0);
        if valid {
            // Sampled 50 µs before the tick.
            s.wrench_sample_ns = s.tick_ns - 50_000;
            last = s.wrench_sample_ns;
        } else {
            s.wrench_sample_ns = last;
        }
        m.push(&p, &s);
    }
    let f = m.figures();
    assert_eq!(f.safe_entries, 1);
    // Tick 116 at 1e9 + 11.6 ms; last good sample at 1e9 + 9.9 ms − 0.05 ms.
    let expected = 11.6 - (9.9 - 0.05);
    assert!(
        (f.safe_after_last_good_ms_max - expected).abs() < 1e-9,
        "{f:?}"
    );
    assert!((f.safe_after_last_good_ms_mean - expected).abs() < 1e-9);
}

/// A servo that itself did not run for 2.5 ms finds its data too old: that entry is
/// counted apart, and the on-time figures keep the sensor's entry only.
#[test]
fn entries_after_a_servo_stall_are_counted_apart() {
    let mut m = FaultMonitor::new(2.5, 0.0);
    let mut t = 1_000_000_000u64;
    let push = |m: &mut FaultMonitor, t: u64, valid: bool, safe: bool, sample: u64| {
        let (p, mut s) = tick(0, valid, safe, sample);
        s.tick_ns = t;
        m.push(&p, &s);
    };
    // On time, good data, then the servo stalls 2.5 ms and wakes up safe.
    for _ in 0..10 {
        t += 100_000;
        push(&mut m, t, true, false, t - 50_000);
    }
    let good = t - 50_000;
    t += 2_500_000;
    push(&mut m, t, false, true, good);
    let stall_latency = t - good;
    // Recovered; then the sensor stops and the on-time servo goes safe 1.55 ms later.
    for _ in 0..300 {
        t += 100_000;
        push(&mut m, t, true, false, t - 50_000);
    }
    let good = t - 50_000;
    for k in 1..=16 {
        t += 100_000;
        push(&mut m, t, false, k == 16, good);
    }
    let f = m.figures();
    assert_eq!(f.safe_entries, 2);
    assert_eq!(f.safe_entries_servo_stalled, 1);
    assert!((f.safe_after_last_good_ms_max - 1.65).abs() < 1e-9, "{f:?}");
    assert!((f.safe_after_last_good_ms_max_all - stall_latency as f64 * 1e-6).abs() < 1e-9);
}

/// The start-up (no good data yet) is not a safe-state entry to measure.
#[test]
fn entries_without_good_data_are_not_measured() {
    let mut m = FaultMonitor::new(2.5, 0.0);
    let (p, s) = tick(0, false, true, 0);
    m.push(&p, &s);
    assert_eq!(m.figures().safe_entries, 0);
    let (p, s) = tick(1, true, false, 1_000_000_000);
    m.push(&p, &s);
    let (p, s) = tick(2, false, true, 0);
    m.push(&p, &s);
    assert_eq!(m.figures().safe_entries, 1);
}

#[test]
fn normal_force_and_controller_values_are_bounded() {
    let mut m = FaultMonitor::new(2.0, 0.5);
    for seq in 0..10_000u64 {
        let (mut p, mut s) = tick(seq, true, false, 0);
        // A 9 N spike during the settling time is ignored, a 3.5 N one later is not.
        p.normal_force_n = match seq {
            100 => 9.0,
            7_000 => 3.5,
            _ => 2.0,
        };
        if seq == 8_000 {
            s.normal_force_n = f64::NAN;
        }
        // A restart at tick 9 000 and a 7 N transient 0.1 s later: reported apart.
        if seq == 9_000 {
            m.servo_restarted_at(9_000);
        }
        if seq == 9_999 {
            p.normal_force_n = 7.0;
        }
        m.push(&p, &s);
    }
    let f = m.figures();
    assert_eq!(f.normal_force_max_n, 3.5);
    assert_eq!(f.normal_force_max_over_preload, 1.75);
    assert!((f.normal_force_max_at_s - 0.7).abs() < 1e-12);
    assert_eq!(f.controller_non_finite, 1);
    assert_eq!(f.normal_force_max_after_servo_restart_n, 7.0);
    assert_eq!(f.controller_force_max_abs_n, 2.5);
}

/// The spans of the default stack file (examples/stack.toml) and scenario probe.
fn spans() -> FaultSpans {
    FaultSpans {
        backoff_s: [0.05, 0.02, 0.05],
        stall_s: [0.5, 0.1, 3.0],
        start_s: 0.3,
        uptime_s: 0.5,
        probe_start_s: 0.6,
        probe_s: 8.3,
        retry_s: 1.5,
        thaw_s: 1.0,
        burst_s: 0.05,
        link_backoff_s: 0.2,
        link_up_s: 3.0,
        cut_s: 5.0,
        link_lease_s: 10.0,
    }
}

/// Each fault is due after the one before has had its span, and the last one's span ends
/// in the window.
fn assert_fits(p: &[PlannedFault], start: f64, end: f64, sp: &FaultSpans) {
    let mut free_from = start;
    for (i, f) in p.iter().enumerate() {
        assert!(
            f.at_s >= free_from - 1e-9,
            "fault {i} at {} s overlaps: {p:?}",
            f.at_s
        );
        free_from = f.at_s + sp.span(f.kind);
    }
    assert!(
        free_from <= end + 1e-9,
        "the last span ends at {free_from} s > {end} s"
    );
}

/// Plans are seeded, every kind is drawn, spans never overlap, and a random plan fits
/// whatever the seed, also where one kind is as long as the window allows only once.
#[test]
fn plans_are_seeded_and_always_fit() {
    let sp = spans();
    let kinds: Vec<FaultKind> = FaultKind::ALL.iter().map(|(_, k)| *k).collect();
    let a = plan(7, 50, (2.0, 200.0), &kinds, false, &sp, 2.0).unwrap();
    assert_eq!(
        a,
        plan(7, 50, (2.0, 200.0), &kinds, false, &sp, 2.0).unwrap()
    );
    assert_ne!(
        a,
        plan(8, 50, (2.0, 200.0), &kinds, false, &sp, 2.0).unwrap()
    );
    assert_eq!(a.len(), 50);
    assert_fits(&a, 2.0, 200.0, &sp);
    for (name, k) in FaultKind::ALL {
        assert!(a.iter().any(|f| f.kind == k), "{name} never drawn");
        assert_eq!(FaultKind::from_name(name), Ok(k));
        assert_eq!(k.name(), name);
    }
    assert!(FaultKind::from_name("kill-everything").is_err());
    // The link's faults end no board of the control loop and need a link board; a kill
    // takes the restart and the tunnel's return, a cut its length and the return.
    for k in [FaultKind::KillLink, FaultKind::CutLink] {
        assert!(k.needs_link() && !k.needs_probe() && k.target().is_none());
    }
    assert!(
        FaultKind::ALL
            .iter()
            .filter(|(_, k)| k.needs_link())
            .count()
            == 2
    );
    assert!((sp.span(FaultKind::KillLink) - 3.5).abs() < 1e-12);
    // Within the lease TCP's backoff may hold the data as long again; beyond it zenoh
    // reconnects.
    assert!((sp.span(FaultKind::CutLink) - 13.0).abs() < 1e-12);
    let long = FaultSpans { cut_s: 12.0, ..sp };
    assert!((long.span(FaultKind::CutLink) - 15.0).abs() < 1e-12);
    // 8 faults of every kind in the 18 s of a 20-s run, at 200 seeds: the mid-request kill
    // (its span is 11.3 s) is drawn at most once, and every plan fits.
    for seed in 0..200 {
        let p = plan(seed, 8, (1.0, 19.0), &kinds, false, &sp, 2.0).unwrap();
        assert_eq!(p.len(), 8);
        assert_fits(&p, 1.0, 19.0, &sp);
        let long = p
            .iter()
            .filter(|f| f.kind == FaultKind::KillEstimatorMidRequest)
            .count();
        assert!(long <= 1, "seed {seed}: {p:?}");
    }
}

/// Taken in turn the kinds cycle; a plan that cannot fit is refused with the shortest run
/// that holds it, and that run's window does hold it.
#[test]
fn plans_that_cannot_fit_name_the_shortest_run() {
    let sp = spans();
    let two = [FaultKind::Kill(Board::Sensor), FaultKind::BadSamples];
    let t = plan(7, 5, (0.0, 10.0), &two, true, &sp, 2.0).unwrap();
    let got: Vec<FaultKind> = t.iter().map(|f| f.kind).collect();
    assert_eq!(got, [two[0], two[1], two[0], two[1], two[0]]);
    let mid = [FaultKind::KillEstimatorMidRequest];
    let err = plan(1, 2, (1.0, 19.0), &mid, true, &sp, 2.0).unwrap_err();
    let PlanError::TooShort {
        needed_s,
        minimum_duration_s,
        ..
    } = err
    else {
        panic!("{err:?}");
    };
    assert!((needed_s - 2.0 * sp.span(mid[0])).abs() < 1e-9);
    assert!(err.to_string().contains("at least 25 s"), "{err}");
    let fits = plan(1, 2, (1.0, minimum_duration_s - 1.0), &mid, true, &sp, 2.0).unwrap();
    assert_fits(&fits, 1.0, minimum_duration_s - 1.0, &sp);
    // At random, the shortest kind sets the limit.
    let kinds = [FaultKind::Kill(Board::Sensor), mid[0]];
    assert!(plan(1, 30, (1.0, 19.0), &kinds, false, &sp, 2.0).is_err());
    assert!(plan(1, 3, (5.0, 5.0), &kinds, false, &sp, 2.0).is_err());
    assert!(plan(1, 3, (0.0, 5.0), &[], false, &sp, 2.0).is_err());
    assert!(plan(1, 3, (f64::NAN, 5.0), &kinds, false, &sp, 2.0).is_err());
    let bad = FaultSpans {
        start_s: f64::NAN,
        ..sp
    };
    assert_eq!(
        plan(1, 3, (0.0, 50.0), &kinds, false, &bad, 2.0),
        Err(PlanError::Spans)
    );
}

/// A robot's servo at 1 kHz whose sensor sends a new sample each tick until tick 99 (but for
/// ticks 40 and 41, which reuse tick 39's: a short silence, over before any hold) and none
/// after: with force data valid up to 2 ms old, the servo holds from tick 102. The hold came
/// 2 ms (of the servo's own time) after the first tick without a new sample; on the wall
/// clock, where a simulated robot's ticks came 1.7 ms apart, that is 3.4 ms and more. Ticks
/// 1.7 ms apart are a 1-kHz servo's pace, not its stall: with its period given, the entry is on
/// time; without, a 10-kHz servo's limit counts it as stalled.
#[test]
fn a_robot_servo_holds_2_ms_after_the_sensor_falls_silent() {
    let run = |period_ns: Option<u64>| {
        let mut m = FaultMonitor::new(2.5, 0.0);
        if let Some(p) = period_ns {
            m = m.with_period_ns(p);
        }
        for seq in 0..200u64 {
            let (p, mut s) = tick(seq, seq < 102, seq >= 102, 0);
            s.tick_ns = 1_000_000_000 + seq * 1_700_000;
            s.time_s = seq as f64 * 1e-3;
            let newest = if (40..42).contains(&seq) {
                39
            } else {
                seq.min(99)
            };
            s.wrench_seq = newest;
            s.wrench_sample_ns = 1_000_000_000 + newest * 1_700_000 - 300_000;
            m.push(&p, &s);
        }
        m.figures()
    };
    let f = run(Some(1_000_000));
    assert_eq!(
        (f.safe_entries, f.safe_entries_servo_stalled),
        (1, 0),
        "{f:?}"
    );
    assert!((f.safe_after_silence_ms_max - 2.0).abs() < 1e-9, "{f:?}");
    // Tick 102 at 173.4 ms; the last sample taken at 168.3 − 0.3 ms.
    assert!((f.safe_after_last_good_ms_max - 5.4).abs() < 1e-9, "{f:?}");
    let g = run(None);
    assert_eq!(g.safe_entries_servo_stalled, 1, "{g:?}");
}
