//! MuJoCo's dynamics of the three-joint arm against the closed form of
//! [`Scara`](crate::insertion::scara::Scara) (docs/insertion-arm.md): the model
//! [`mjcf::scara`] writes has, at any state, MuJoCo's joint-space inertia equal to `M(q)` and
//! its bias forces equal to `h(q, q̇)`; stepped under the same torques, the two agree.

#[cfg(test)]
mod tests {
    use super::super::mjcf;
    use super::super::mujoco_body::load;
    use crate::arm::ArmParams;
    use crate::insertion::scara::{Scara, WristParams};
    use mujoco_rs::prelude::MjData;
    use nalgebra::{Matrix3, Vector3};
    use std::sync::Arc;

    fn states() -> [(Vector3<f64>, Vector3<f64>); 4] {
        [
            (Vector3::new(0.3, 1.1, -0.7), Vector3::new(0.7, -1.2, 2.5)),
            (Vector3::new(-0.4, -1.3, 0.9), Vector3::new(-0.2, 0.4, -3.0)),
            (Vector3::new(1.2, 0.2, 2.8), Vector3::zeros()),
            (Vector3::new(0.0, 2.0, -2.0), Vector3::new(1.5, 1.5, 1.5)),
        ]
    }

    /// MuJoCo's mass matrix (`mj_fullM`) and bias forces (`qfrc_bias`) of the generated model
    /// are the closed form's M(q) and h(q, q̇) to 10⁻¹⁰, at four states; for the default
    /// wrist and for the arm's wrist without the peg. A wrist body whose centre of mass sat at
    /// its tool point instead fails both.
    #[test]
    fn mujocos_wrist_dynamics_are_the_closed_forms() {
        let arm = ArmParams::default();
        let flange = WristParams {
            mass_kg: 0.3,
            com_m: 0.01,
            inertia_kg_m2: 2e-3,
            ..WristParams::default()
        };
        for wrist in [WristParams::default(), flange] {
            let model = load(&mjcf::scara(&arm, &wrist, [0.0; 3], 1e-4)).unwrap();
            assert_eq!(model.ffi().nv, 3);
            let mut data = MjData::new(Arc::new(model));
            let s = Scara::new(arm, wrist);
            for (q, qd) in states() {
                data.qpos_mut().copy_from_slice(q.as_slice());
                data.qvel_mut().copy_from_slice(qd.as_slice());
                data.forward();
                let mut full = [0.0; 9];
                data.full_m(&mut full).unwrap();
                let m = Matrix3::from_row_slice(&full);
                let expect = s.mass_matrix(q);
                assert!((m - expect).norm() < 1e-10, "{m} vs {expect}");
                let bias = Vector3::from_column_slice(data.qfrc_bias());
                let h = s.coriolis(q, qd);
                assert!((bias - h).norm() < 1e-10, "{bias} vs {h}");
            }
        }
    }

    /// Stepped under the same joint torques for 0.2 s (MuJoCo's Euler, 0.1 ms), MuJoCo's arm
    /// and the closed form integrated alike stay within 10⁻⁹ rad of each other.
    #[test]
    fn mujocos_wrist_moves_as_the_closed_form() {
        let arm = ArmParams::default();
        let wrist = WristParams::default();
        let dt = 1e-4;
        let model = load(&mjcf::scara(&arm, &wrist, [0.0; 3], dt)).unwrap();
        let mut data = MjData::new(Arc::new(model));
        let s = Scara::new(arm, wrist);
        let (mut q, mut qd) = states()[0];
        data.qpos_mut().copy_from_slice(q.as_slice());
        data.qvel_mut().copy_from_slice(qd.as_slice());
        for n in 0..2000 {
            let t = f64::from(n) * dt;
            let tau = Vector3::new(2.0 * (5.0 * t).sin(), -1.0, 0.05 * (9.0 * t).cos());
            data.qfrc_applied_mut().copy_from_slice(tau.as_slice());
            data.step();
            // MuJoCo's Euler: velocity first, then the position with the new velocity.
            let qdd = s
                .mass_matrix(q)
                .cholesky()
                .unwrap()
                .solve(&(tau - s.coriolis(q, qd)));
            qd += qdd * dt;
            q += qd * dt;
        }
        let mj = Vector3::from_column_slice(data.qpos());
        assert!((mj - q).norm() < 1e-9, "{mj} vs {q}");
        assert!(q.norm() > 0.1);
    }
}
