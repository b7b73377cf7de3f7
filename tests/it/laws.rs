//! The four laws against numbers computed by hand and against finite differences.

use crate::support::{random_params, rng};
use bitrock::Law;

/// Richardson-extrapolated central difference: truncation error O(h⁴).
fn numeric_derivative(f: impl Fn(f64) -> f64, x: f64) -> f64 {
    let h = 1e-3 * x.abs().max(1.0);
    let d = |h: f64| (f(x + h) - f(x - h)) / (2.0 * h);
    (4.0 * d(h / 2.0) - d(h)) / 3.0
}

#[test]
fn torques_at_the_papers_estimates_match_hand_calculation() {
    // T(w) at w = 0, 1, 10 rad/s, r = 1, kN·m; evaluated by hand from the formulas, e.g.
    // m2(1) = 6.5·exp(-0.3) + 6.5 and m4(10) = 11.8 - 9.3 + 5.7 - 1.2 = 7.0.
    let expected: [(Law, [f64; 3]); 4] = [
        (Law::M1, [0.0, 11.494104147808422, 6.759807500484669]),
        (Law::M2, [13.0, 11.315318434431166, 6.823615944391116]),
        (Law::M3, [12.218056989167152, 10.388990627245839, 6.863852918928603]),
        (Law::M4, [11.8, 10.9258, 7.0]),
    ];
    for (law, values) in expected {
        for (w, want) in [0.0, 1.0, 10.0].into_iter().zip(values) {
            let got = law.torque(law.paper_estimate().unwrap(), w, 1.0);
            assert!(
                (got - want).abs() <= 1e-12 * want.abs().max(1.0),
                "{law} at w = {w}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn weight_on_bit_scales_torque_and_derivative_linearly() {
    for law in Law::ALL {
        let p = law.paper_estimate().unwrap();
        for w in [0.5, 3.0, 12.0] {
            let t = law.torque(p, w, 1.0);
            let d = law.dtorque_dw(p, w, 1.0);
            assert!((law.torque(p, w, 1.3) - 1.3 * t).abs() < 1e-12 * t.abs());
            assert!((law.dtorque_dw(p, w, 0.7) - 0.7 * d).abs() < 1e-12 * d.abs().max(1e-9));
        }
    }
}

#[test]
fn analytic_speed_derivatives_match_central_differences() {
    let mut rng = rng(11);
    let mut worst = 0.0f64;
    for law in Law::ALL {
        for _ in 0..50 {
            let p = random_params(law, &mut rng);
            let r = 1.1;
            for k in 0..=300 {
                let w = 0.05 + (30.0 - 0.05) * k as f64 / 300.0;
                let analytic = law.dtorque_dw(&p, w, r);
                let numeric = numeric_derivative(|x| law.torque(&p, x, r), w);
                // Relative error, with a floor of 1e-6 of the torque per rad/s where the slope
                // itself crosses zero.
                let scale = analytic.abs().max(1e-6 * law.torque(&p, w, r).abs());
                let rel = (analytic - numeric).abs() / scale;
                worst = worst.max(rel);
                assert!(
                    rel < 1e-6,
                    "{law} {p:?} at w = {w}: analytic {analytic}, numeric {numeric}"
                );
            }
        }
    }
    eprintln!("worst relative error of dT/dw: {worst:.2e}");
}

#[test]
fn parameter_gradients_match_central_differences() {
    let mut rng = rng(12);
    for law in Law::ALL {
        let p = random_params(law, &mut rng);
        let mut grad = vec![0.0; law.n_params()];
        for &w in &[0.1, 0.7, 2.0, 9.0, 25.0] {
            let t = law.torque_and_gradient(&p, w, &mut grad);
            assert!((t - law.torque(&p, w, 1.0)).abs() < 1e-12 * t.abs().max(1.0));
            for j in 0..p.len() {
                let numeric = numeric_derivative(
                    |x| {
                        let mut q = p.clone();
                        q[j] = x;
                        law.torque(&q, w, 1.0)
                    },
                    p[j],
                );
                // Floor as for dT/dw: where a sensitivity vanishes (tanh saturated), rounding in the
                // difference quotient (about 1e-13 of T) dominates.
                let scale = grad[j].abs().max(1e-6 * t.abs());
                assert!(
                    (grad[j] - numeric).abs() / scale < 1e-6,
                    "{law} d/d{} at w = {w}: {} vs {numeric}",
                    law.params()[j].name,
                    grad[j]
                );
            }
        }
    }
}

#[test]
fn unit_conversion_of_parameters_is_exact_in_torque() {
    for law in Law::ALL {
        let p = law.paper_estimate().unwrap();
        let p_nm = law.scale_torque(p, 1000.0);
        for w in [0.3, 4.0, 15.0] {
            let kilo = law.torque(p, w, 1.0) * 1000.0;
            assert!((law.torque(&p_nm, w, 1.0) - kilo).abs() < 1e-9 * kilo.abs());
        }
    }
}
