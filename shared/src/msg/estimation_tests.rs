use super::*;

/// Every outcome survives the wire.
#[test]
fn tangent_outcomes_round_trip() {
    let params = TangentParams::default();
    let outcomes = [
        TangentOutcome::Estimate(TangentEstimate {
            alpha0_rad: 0.01,
            tangent_angle_rad: 0.2,
            method: TangentMethod::MotionRegression,
            std_error_rad: 1e-4,
            residual_n: 0.001,
            noise_n: 0.002,
            snr: 50.0,
            thesis_alpha0_rad: Some(0.011),
            thesis_6_1_alpha0_rad: None,
            ratio_alpha0_rad: Some(0.0105),
            stiffness_n_per_m: 1300.0,
            probes: 2,
            iterations: 3,
        }),
        TangentOutcome::Estimate(TangentEstimate {
            alpha0_rad: -0.02,
            tangent_angle_rad: 0.1,
            method: TangentMethod::TipPath,
            std_error_rad: 1e-5,
            residual_n: 0.0,
            noise_n: 0.002,
            snr: 1.5,
            thesis_alpha0_rad: None,
            thesis_6_1_alpha0_rad: None,
            ratio_alpha0_rad: None,
            stiffness_n_per_m: 0.0,
            probes: 4,
            iterations: 1,
        }),
        TangentOutcome::Reprobe {
            reason: ReprobeReason::Fold,
            plan: params.reprobe_plan(),
        },
        TangentOutcome::Reprobe {
            reason: ReprobeReason::SoftContact,
            plan: params.soft_contact_plan(3e-3, 0.02),
        },
        TangentOutcome::Failed(TangentError::ContactLost {
            probe: 1,
            min_n: 0.1,
        }),
        TangentOutcome::Failed(TangentError::MissingData {
            probe: 0,
            samples: 3,
        }),
        TangentOutcome::Failed(TangentError::TooNoisy {
            signal_n: 0.01,
            noise_n: 0.02,
        }),
        TangentOutcome::Failed(TangentError::Uncertain {
            std_error_deg: 0.7,
            limit_deg: 0.5,
        }),
        TangentOutcome::Failed(TangentError::Stuck {
            probe: 1,
            travel_fraction: 0.01,
        }),
        TangentOutcome::Failed(TangentError::Unresolved(ReprobeReason::EqualResponses)),
    ];
    for o in outcomes {
        let wire = TangentResponse::from_outcome(7, &o);
        assert_eq!(wire.request_id, 7);
        assert_eq!(wire.to_outcome(), Some(o), "{o:?}");
    }
    assert_eq!(TangentResponse::bad_request(3).to_outcome(), None);
    let mut wrong = TangentResponse::from_outcome(1, &outcomes[0]);
    wrong.version = 99;
    assert_eq!(wrong.to_outcome(), None);
}

/// Settings and plans survive the wire; a malformed one is refused.
#[test]
fn params_and_plans_round_trip() {
    let p = TangentParams {
        design_stiffness_n_per_m: 2.5e3,
        ..TangentParams::default()
    };
    assert_eq!(TangentParamsMsg::from(&p).to_params(), Ok(p));
    let mut bad = TangentParamsMsg::from(&p);
    bad.amplitude_m = f64::NAN;
    assert!(bad.to_params().is_err());
    let mut bad = TangentParamsMsg::from(&p);
    bad.design_stiffness_n_per_m = -1.0;
    assert!(bad.to_params().is_err());
    let plan = p.first_plan();
    assert_eq!(ProbePlanMsg::from(&plan).to_plan(), Some(plan));
    let mut bad = ProbePlanMsg::from(&plan);
    bad.count = 9;
    assert_eq!(bad.to_plan(), None);
}
