//! The estimator board's requests over iceoryx2.

use super::*;

/// The estimator board answers over iceoryx2: a probe record of a 3° tangent error gives the
/// error back, a malformed request is refused, and three rotational dithers about known
/// centres give the rotation centre.
#[test]
fn the_estimator_board_answers_requests() {
    use afs::ipc;
    use afs_shared::math::Vec2;
    use afs_shared::msg::{
        self, Outcome, RotationRequestHeader, RotationSample, TangentRequestHeader,
    };
    use afs_shared::tangent::TangentParams;
    use iceoryx2::service::port_factory::PortFactory;
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let p = prefix("es");
    let _clean = CleanPrefix(p.clone());
    let est = KillOnDrop(Some(
        Command::new(env!("CARGO_BIN_EXE_afs-estimator"))
            .args(["--prefix", &p])
            .spawn()
            .unwrap(),
    ));
    let node = ipc::node(&p, "test-client").unwrap();
    let tangent_service = ipc::tangent(&node).unwrap();
    let rotation_service = ipc::rotation(&node).unwrap();
    // A request sent before the server's port exists is not delivered: wait for it.
    let t0 = Instant::now();
    while tangent_service.dynamic_config().number_of_servers() == 0
        || rotation_service.dynamic_config().number_of_servers() == 0
    {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "the estimator did not come up"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let client = tangent_service
        .client_builder()
        .initial_max_slice_len(20_000)
        .create()
        .unwrap();

    // A rigid 1 mm stroke against a 1.4 kN/m spring, no noise.
    let params = TangentParams::default();
    let plan = params.first_plan();
    let model = rigid_stroke_model();
    let (base, alpha0) = (model.base, model.alpha0);
    let rec = model.record(&plan, 0);
    let ask = |header: TangentRequestHeader| {
        let mut req = client.loan_slice_uninit(rec.len()).unwrap();
        *req.user_header_mut() = header;
        let req = req.write_from_slice(&rec);
        let pending = req.send().unwrap();
        let t0 = Instant::now();
        loop {
            if let Some(r) = pending.receive().unwrap() {
                return *r.payload();
            }
            assert!(t0.elapsed() < Duration::from_secs(20), "no answer");
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    let header = TangentRequestHeader {
        version: msg::TangentRequestHeader::VERSION,
        request_id: 7,
        base_angle_rad: base,
        plan: (&plan).into(),
        params: (&params).into(),
        ..Default::default()
    };
    let r = ask(header);
    assert_eq!(Outcome::try_from(r.outcome), Ok(Outcome::Estimate), "{r:?}");
    assert_eq!(r.request_id, 7);
    assert!(
        (r.alpha0_rad - alpha0).abs() < 1e-3,
        "α0 {} vs {alpha0}",
        r.alpha0_rad
    );
    let mut bad = header;
    bad.request_id = 8;
    bad.params.amplitude_m = f64::NAN;
    let r = ask(bad);
    assert_eq!(
        (Outcome::try_from(r.outcome), r.request_id),
        (Ok(Outcome::BadRequest), 8)
    );

    // Rotation centre: responses g(c) = −K J (P − c) with a diagonal K, three dithers.
    let rclient = rotation_service
        .client_builder()
        .initial_max_slice_len(10_000)
        .create()
        .unwrap();
    let centre = Vec2::new(0.02, 0.05);
    let centres = [
        Vec2::new(0.0, 0.0),
        Vec2::new(0.01, 0.01),
        Vec2::new(-0.01, 0.005),
    ];
    let amp = 0.5f64.to_radians();
    let mut samples = Vec::new();
    for (d, c) in centres.iter().enumerate() {
        let dp = centre - c;
        let g = Vec2::new(-3000.0 * -dp.y, -2500.0 * dp.x);
        for i in 0..1000 {
            let phase = std::f64::consts::TAU * i as f64 / 500.0;
            let f = g * (amp * phase.sin()) + Vec2::new(2.0, 2.0);
            samples.push(RotationSample {
                t: i as f64 * 1e-3,
                phase,
                force_n: [f.x, f.y],
                dither: d as u32,
                reserved: 0,
            });
        }
    }
    let mut centre_m = [[0.0; 2]; msg::MAX_CENTRES];
    for (i, c) in centres.iter().enumerate() {
        centre_m[i] = [c.x, c.y];
    }
    let mut req = rclient.loan_slice_uninit(samples.len()).unwrap();
    *req.user_header_mut() = RotationRequestHeader {
        version: msg::RotationRequestHeader::VERSION,
        centres: 3,
        request_id: 1,
        centre_m,
        amplitude_rad: amp,
        ..Default::default()
    };
    let pending = req.write_from_slice(&samples).send().unwrap();
    let t0 = Instant::now();
    let answer = loop {
        if let Some(r) = pending.receive().unwrap() {
            break *r.payload();
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "no rotation answer");
        std::thread::sleep(Duration::from_millis(5));
    };
    assert_eq!(answer.outcome, 0, "{answer:?}");
    let got = Vec2::new(answer.centre_m[0], answer.centre_m[1]);
    assert!((got - centre).norm() < 1e-4, "{got:?} vs {centre:?}");
    let thesis = Vec2::new(answer.thesis_centre_m[0], answer.thesis_centre_m[1]);
    assert!((thesis - centre).norm() < 1e-4, "thesis form {thesis:?}");

    drop(pending);
    drop((rclient, client, tangent_service, rotation_service));
    drop(node);
    // SAFETY: signalling our own child.
    unsafe {
        libc::kill(est.id() as i32, libc::SIGTERM);
    }
    let st = est.take().wait().unwrap();
    assert!(st.success(), "{st:?}");
    // The test's own node was a member of the domain: release it (its node counter goes).
    ipc::release_prefix(&p).unwrap();
    assert!(leftovers(&p).is_empty(), "{:?}", leftovers(&p));
}

/// A rigid 1 mm stroke's record model: a 1.4 kN/m spring, no noise, no friction, α0 = 3°.
fn rigid_stroke_model() -> afs_shared::tangent::ProbeModel {
    afs_shared::tangent::ProbeModel {
        alpha0: 3f64.to_radians(),
        base: 0.3,
        k: 1400.0,
        noise: 0.0,
        friction: 0.0,
        preload: 2.5,
        travel: 1.0,
        share: 1.0,
    }
}
