//! Least squares: exact recovery on noise-free data at any torque scale, optimality on noisy
//! data, and honest warnings when the data cannot carry a law.

use crate::support::{rng, samples};
use bitrock::Law;
use bitrock::data::Samples;
use bitrock::fit::{FitOptions, fit_law, misfit};
use rand_distr::{Distribution, Normal};

/// Field data are in kN·m (×1000 in N·m); a laboratory rig gives 0.5-4 N·m (×0.25).
const SCALES: [(&str, f64); 2] = [("field, kN·m", 1000.0), ("laboratory, N·m", 0.25)];

#[test]
fn noise_free_data_give_back_the_papers_estimates_at_any_torque_scale() {
    for (label, scale) in SCALES {
        for law in Law::ALL {
            let truth = law.scale_torque(law.paper_estimate().unwrap(), scale);
            let data = samples(law, &truth, 0.1, 22.0, 2000);
            let fit = fit_law(law, &data, &Samples::default(), &FitOptions::default()).unwrap();
            for (j, (got, want)) in fit.params_si.iter().zip(&truth).enumerate() {
                let rel = (got - want).abs() / want.abs();
                assert!(
                    rel < 1e-4,
                    "{label}, {law}.{}: {got} vs {want} (relative {rel:.1e})",
                    law.params()[j].name
                );
            }
            assert!(fit.rho < 1e-20, "{label}, {law}: rho {}", fit.rho);
            assert!(fit.warnings.is_empty(), "{label}, {law}: {:?}", fit.warnings);
        }
    }
}

#[test]
fn with_noise_the_fit_is_no_worse_than_the_generating_parameters() {
    let mut rng = rng(5);
    for (label, scale) in SCALES {
        for law in Law::ALL {
            let truth = law.scale_torque(law.paper_estimate().unwrap(), scale);
            let mut data = samples(law, &truth, 0.55, 16.0, 3000);
            // About 8 % of the mean torque, as in field records.
            let noise = Normal::new(0.0, 0.8 * scale).unwrap();
            for y in &mut data.torque_nm {
                *y += noise.sample(&mut rng);
            }
            let fit = fit_law(law, &data, &Samples::default(), &FitOptions::default()).unwrap();
            let ones = vec![1.0; data.len()];
            let rho_truth = misfit(
                law,
                &truth,
                &data.speed_rad_s,
                &data.torque_nm,
                &ones,
                data.sum_sq_torque(),
            );
            assert!(
                fit.rho <= rho_truth,
                "{label}, {law}: fit rho {} > generating rho {rho_truth}",
                fit.rho
            );
            // The reported rho is the misfit of the reported parameters.
            let rho_again = misfit(
                law,
                &fit.params_si,
                &data.speed_rad_s,
                &data.torque_nm,
                &ones,
                data.sum_sq_torque(),
            );
            assert!((rho_again - fit.rho).abs() < 1e-12 * fit.rho, "{label}, {law}");
        }
    }
}

#[test]
fn a_law_the_data_cannot_identify_says_so() {
    // Constant torque: m2's decay rate g and the split between tsb and tcb are undetermined.
    let mut rng = rng(6);
    let noise = Normal::new(0.0, 300.0).unwrap();
    let w: Vec<f64> = (0..2000).map(|i| 0.6 + 15.0 * i as f64 / 1999.0).collect();
    let y = w.iter().map(|_| 10_000.0 + noise.sample(&mut rng)).collect();
    let data = Samples::new(w, y);
    let fit = fit_law(Law::M2, &data, &Samples::default(), &FitOptions::default()).unwrap();
    assert!(
        !fit.warnings.is_empty(),
        "no warning for an unidentifiable m2: {:?}",
        fit.params_si
    );
    assert!(
        fit.warnings
            .iter()
            .any(|w| w.contains("not identified") || w.contains("ill-conditioned") || w.contains("bound")),
        "{:?}",
        fit.warnings
    );
}

#[test]
fn bounds_hold_by_default_and_lift_on_request() {
    // Data from a cubic with a negative static torque c0 = -1 kN·m.
    let truth = [-1000.0, 900.0, -20.0, 0.5];
    let data = samples(Law::M4, &truth, 0.6, 15.0, 500);
    let bounded = fit_law(Law::M4, &data, &Samples::default(), &FitOptions::default()).unwrap();
    assert!(
        bounded.params_si[0] >= 0.0 && bounded.params_si[0] < 1e-3,
        "{:?}",
        bounded.params_si
    );
    assert!(
        bounded
            .warnings
            .iter()
            .any(|w| w.contains("c0 sits on its physical bound")),
        "{:?}",
        bounded.warnings
    );
    assert!(bounded.std_errors_si[0].is_none());
    let free = fit_law(
        Law::M4,
        &data,
        &Samples::default(),
        &FitOptions {
            bounded: false,
            ..Default::default()
        },
    )
    .unwrap();
    for (got, want) in free.params_si.iter().zip(truth) {
        assert!((got - want).abs() < 1e-6 * want.abs(), "{:?}", free.params_si);
    }
}

#[test]
fn validation_misfit_is_reported() {
    let truth = Law::M2.scale_torque(Law::M2.paper_estimate().unwrap(), 1000.0);
    let calibration = samples(Law::M2, &truth, 0.6, 15.0, 400);
    let mut validation = samples(Law::M2, &truth, 0.7, 14.0, 300);
    for y in &mut validation.torque_nm {
        *y *= 1.1;
    }
    let fit = fit_law(Law::M2, &calibration, &validation, &FitOptions::default()).unwrap();
    // y_v = 1.1 T: rho_v = Σ(0.1 T)² / Σ(1.1 T)² = (0.1/1.1)².
    let expected = (0.1f64 / 1.1).powi(2);
    assert!(
        (fit.validation_rho.unwrap() - expected).abs() < 1e-9,
        "{:?}",
        fit.validation_rho
    );
}

/// Replicates as the selection check makes them: each law at its estimate on a record from m2
/// with noise above the paper's, plus residuals drawn from its own. Their fits started from
/// the record's estimates (and the generating parameters) are never worse than the fits from
/// the grid alone, beyond what the fit itself calls an equal fit (10⁻⁶ of the misfit), and
/// spend far fewer runs crawling out of patience.
#[test]
fn fits_from_known_starts_are_never_worse_and_rarely_run_out_of_patience() {
    use bitrock::fit::{fit_laws, fit_laws_from};
    use rand::Rng;
    let record = bitrock::bench::SelectionRecord::M2.field_data().unwrap();
    let cal = &record.calibration;
    let opts = FitOptions::default();
    let estimates = fit_laws(&Law::ALL, cal, &Samples::default(), &opts).unwrap();
    let (mut old_out, mut new_out, mut abandoned, mut better) = (0, 0, 0, 0);
    for (slot, generating) in estimates.iter().enumerate() {
        let law = generating.law;
        let r = cal.wob_ratio(None);
        let residuals: Vec<f64> = (0..cal.len())
            .map(|i| cal.torque_nm[i] - law.torque(&generating.params_si, cal.speed_rad_s[i], r[i]))
            .collect();
        for replicate in 0..2u64 {
            let mut rng = rng(100 * slot as u64 + replicate);
            let synthetic = Samples {
                torque_nm: (0..cal.len())
                    .map(|i| {
                        law.torque(&generating.params_si, cal.speed_rad_s[i], r[i])
                            + residuals[rng.random_range(0..residuals.len())]
                    })
                    .collect(),
                ..cal.clone()
            };
            let known: Vec<(Law, Vec<f64>)> = estimates.iter().map(|f| (f.law, f.params_si.clone())).collect();
            let old = fit_laws(&Law::ALL, &synthetic, &Samples::default(), &opts).unwrap();
            let new = fit_laws_from(&Law::ALL, &synthetic, &Samples::default(), &opts, &known).unwrap();
            for (o, n) in old.iter().zip(&new) {
                assert!(
                    n.rho <= o.rho * (1.0 + 1e-6),
                    "{law} replicate {replicate}, fit of {}: ρ {} from known starts against {} from the grid",
                    o.law,
                    n.rho,
                    o.rho
                );
                // The grid's starts are all still polished; the known ones come on top.
                assert!(n.starts >= o.starts, "{} starts against {}", n.starts, o.starts);
                better += usize::from(n.rho < o.rho * (1.0 - 1e-9));
                old_out += o.endings.out_of_patience;
                new_out += n.endings.out_of_patience;
                abandoned += n.endings.abandoned;
            }
        }
    }
    eprintln!(
        "runs out of patience: {old_out} from the grid, {new_out} with known starts ({abandoned} stopped early); {better} fits better"
    );
    assert!(old_out > 0, "no fit crawled: the test does not exercise the race");
    assert!(
        abandoned > 0 && 2 * new_out <= old_out,
        "{new_out} runs out of patience against {old_out}"
    );
}
