//! Helpers shared by the integration tests.

use bitrock::Law;
use bitrock::data::Samples;
use bitrock::eval::Problem;
use bitrock::fit::{FitOptions, fit_laws};
use bitrock::prior::Prior;
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};

/// Parameters drawn uniformly in [0.5, 1.5] × the paper's estimate (kN·m).
pub fn random_params(law: Law, rng: &mut StdRng) -> Vec<f64> {
    law.paper_estimate()
        .unwrap()
        .iter()
        .map(|&p| p * rng.random_range(0.5..1.5))
        .collect()
}

/// A seeded generator for reproducible tests.
pub fn rng(seed: u64) -> StdRng {
    StdRng::seed_from_u64(seed)
}

/// Noise-free samples of `law` at `params` (SI) over an even speed grid.
pub fn samples(law: Law, params: &[f64], w_lo: f64, w_hi: f64, count: usize) -> Samples {
    let w: Vec<f64> = (0..count)
        .map(|i| w_lo + (w_hi - w_lo) * i as f64 / (count - 1) as f64)
        .collect();
    let y = w.iter().map(|&w| law.torque(params, w, 1.0)).collect();
    Samples::new(w, y)
}

/// Path of the built `bitrock` binary.
pub fn bin() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_bitrock"))
}

/// Runs `command` to its end: (exit status, standard output, standard error).
pub fn outcome(command: &mut std::process::Command) -> (i32, String, String) {
    let out = command.output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// m2 at the paper's estimate with 5 % noise, speeds 0.1-20 rad/s (where m1, whose torque
/// vanishes at w = 0, cannot mimic m2's static torque), against all four laws with priors from
/// least squares, δ = 0.4; also m2's least-squares ρ.
pub fn paper_m2_problem(seed: u64) -> (Problem, f64) {
    let truth = Law::M2.scale_torque(Law::M2.paper_estimate().unwrap(), 1000.0);
    let mut data = samples(Law::M2, &truth, 0.1, 20.0, 800);
    let mut g = rng(21);
    let noise = Normal::new(0.0, 400.0).unwrap();
    for y in &mut data.torque_nm {
        *y += noise.sample(&mut g);
    }
    let fits = fit_laws(&Law::ALL, &data, &Samples::default(), &FitOptions::default()).unwrap();
    let rho = fits[1].rho;
    let prior = Prior::from_fits(&fits, 0.4, None, 1000.0).unwrap();
    (Problem::new(prior, seed, &data, None), rho)
}
