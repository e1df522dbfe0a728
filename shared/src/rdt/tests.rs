use super::*;

/// Byte-exact vectors written from the published layout.
#[test]
fn requests_encode_and_decode_byte_exact() {
    let start = Request {
        command: Command::RealTime,
        count: 0,
    };
    assert_eq!(start.encode(), [0x12, 0x34, 0x00, 0x02, 0, 0, 0, 0]);
    let buffered = Request {
        command: Command::Buffered,
        count: 1000,
    };
    assert_eq!(
        buffered.encode(),
        [0x12, 0x34, 0x00, 0x03, 0, 0, 0x03, 0xe8]
    );
    let bias = Request {
        command: Command::SetBias,
        count: 0,
    };
    assert_eq!(bias.encode(), [0x12, 0x34, 0x00, 0x42, 0, 0, 0, 0]);
    let stop = Request {
        command: Command::Stop,
        count: 0,
    };
    assert_eq!(stop.encode(), [0x12, 0x34, 0, 0, 0, 0, 0, 0]);
    for r in [start, buffered, bias, stop] {
        assert_eq!(Request::decode(&r.encode()), Ok(r));
    }
    assert_eq!(
        Request::decode(&[0x12, 0x34, 0, 2, 0, 0, 0]),
        Err(RdtError::RequestLength(7))
    );
    assert_eq!(
        Request::decode(&[0x34, 0x12, 0, 2, 0, 0, 0, 0]),
        Err(RdtError::RequestHeader(0x3412))
    );
    assert_eq!(
        Request::decode(&[0x12, 0x34, 0, 0x41, 0, 0, 0, 0]),
        Err(RdtError::Command(0x41))
    );
}

#[test]
fn records_decode_byte_exact() {
    #[rustfmt::skip]
    let bytes: [u8; RECORD_LEN] = [
        0x00, 0x00, 0x00, 0x01,             // rdt_sequence 1
        0x00, 0x01, 0x00, 0x00,             // ft_sequence 65536
        0x80, 0x00, 0x00, 0x00,             // status: the error bit
        0x00, 0x0f, 0x42, 0x40,             // Fx = 1 000 000
        0xff, 0xf0, 0xbd, 0xc0,             // Fy = −1 000 000
        0x00, 0x00, 0x00, 0x00,             // Fz = 0
        0x7f, 0xff, 0xff, 0xff,             // Tx = i32::MAX
        0x80, 0x00, 0x00, 0x00,             // Ty = i32::MIN
        0xff, 0xff, 0xff, 0xff,             // Tz = −1
    ];
    let r = Record::decode(&bytes);
    assert_eq!(
        r,
        Record {
            rdt_sequence: 1,
            ft_sequence: 65536,
            status: STATUS_ERROR,
            counts: [1_000_000, -1_000_000, 0, i32::MAX, i32::MIN, -1],
        }
    );
    assert_eq!(r.encode(), bytes);
    assert!(!status_healthy(r.status));
    let two: Vec<u8> = bytes.iter().chain(bytes.iter()).copied().collect();
    assert_eq!(Record::decode_packet(&two).unwrap().count(), 2);
    for bad in [0, 35, 37, 71, RECORD_LEN * 41] {
        assert_eq!(
            Record::decode_packet(&vec![0; bad]).err(),
            Some(RdtError::PacketLength(bad))
        );
    }
}

#[test]
fn counts_convert_to_si_and_back() {
    let cal = Calibration {
        counts_per_force: 1_000_000.0,
        counts_per_torque: 1_000.0,
    };
    let si = cal.to_si(&[1_000_000, -2_500_000, 1, 1_000, -500, 0]);
    assert_eq!(si, [1.0, -2.5, 1e-6, 1.0, -0.5, 0.0]);
    assert_eq!(
        cal.to_counts(&si),
        ([1_000_000, -2_500_000, 1, 1_000, -500, 0], false)
    );
    // A force beyond the counts' range is held at it and flagged.
    let (c, held) = cal.to_counts(&[3000.0, f64::NAN, 0.0, 0.0, 0.0, -1e7]);
    assert!(held);
    assert_eq!((c[0], c[1], c[5]), (i32::MAX, i32::MAX, i32::MIN));
    assert!(cal.validate().is_ok());
    assert!(
        Calibration {
            counts_per_force: 0.0,
            ..cal
        }
        .validate()
        .is_err()
    );
}

#[test]
fn mountings_map_the_chosen_plane() {
    let six = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    let xy = Mounting::default().planar(&six);
    assert_eq!((xy.force.x, xy.force.y, xy.torque), (1.0, 2.0, 6.0));
    let yz = Mounting {
        plane: Plane::Yz,
        angle_rad: 0.0,
    }
    .planar(&six);
    assert_eq!((yz.force.x, yz.force.y, yz.torque), (2.0, 3.0, 4.0));
    let zx = Mounting {
        plane: Plane::Zx,
        angle_rad: 0.0,
    }
    .planar(&six);
    assert_eq!((zx.force.x, zx.force.y, zx.torque), (3.0, 1.0, 5.0));
    // Turned by 90°: the sensor's y is afs's x, the sensor's −x is afs's y.
    let q = Mounting {
        plane: Plane::Xy,
        angle_rad: std::f64::consts::FRAC_PI_2,
    }
    .planar(&six);
    assert!((q.force.x - 2.0).abs() < 1e-12 && (q.force.y + 1.0).abs() < 1e-12);
    // six() inverts planar() for every plane and angle.
    for plane in [Plane::Xy, Plane::Yz, Plane::Zx] {
        for angle_rad in [0.0, 0.3, -2.0] {
            let m = Mounting { plane, angle_rad };
            let w = Wrench {
                force: Vec2::new(1.5, -0.25),
                torque: 0.125,
            };
            let back = m.planar(&m.six(w));
            assert!((back.force - w.force).norm() < 1e-12);
            assert_eq!(back.torque, w.torque);
        }
    }
}

#[test]
fn sequences_are_judged_across_the_wrap() {
    let mut t = SequenceTracker::default();
    assert_eq!(t.judge(u32::MAX - 1), Verdict::Fresh { lost: 0 });
    assert_eq!(t.judge(u32::MAX), Verdict::Fresh { lost: 0 });
    assert_eq!(t.judge(u32::MAX), Verdict::Repeated);
    assert_eq!(t.judge(2), Verdict::Fresh { lost: 2 }); // 0 and 1 lost
    assert_eq!(t.judge(u32::MAX), Verdict::Reordered);
    assert_eq!(t.judge(1), Verdict::Reordered);
    assert_eq!(t.judge(3), Verdict::Fresh { lost: 0 });
    t.restart();
    assert_eq!(t.judge(1), Verdict::Fresh { lost: 0 });
}

#[test]
fn lateness_is_the_excess_over_the_least_delayed_record() {
    let period = 1e9 / 7000.0;
    let mut l = Lateness::new(period, 1_000_000_000);
    let base = 5_000_000_000u64;
    let at = |k: u32, extra: u64| base + (f64::from(k) * period) as u64 + extra;
    // ft_sequence wraps inside the run.
    let first = u32::MAX - 3;
    for k in 0..10u32 {
        let e = l.observe(first.wrapping_add(k), at(k, 40_000));
        assert!(e < 2.0, "{k}: {e}");
    }
    let e = l.observe(first.wrapping_add(10), at(10, 40_000 + 700_000));
    assert!((e - 700_000.0).abs() < 2.0, "{e}");
    // A reordered (older) record is placed where it belongs.
    let e = l.observe(first.wrapping_add(9), at(10, 40_000 + 800_000));
    assert!((e - 800_000.0 - period).abs() < 2.0, "{e}");
    // A device restart (sequence far away) starts again.
    assert_eq!(l.observe(17, at(11, 0)), 0.0);
}
