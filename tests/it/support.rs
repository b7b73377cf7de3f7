//! Helpers shared by the integration tests.

use bitrock::Law;
use bitrock::data::Samples;
use rand::{Rng, SeedableRng, rngs::StdRng};

/// Parameters drawn uniformly in [0.5, 1.5] × the paper's estimate (kN·m).
pub fn random_params(law: Law, rng: &mut StdRng) -> Vec<f64> {
    law.paper_estimate()
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
    Samples {
        speed_rad_s: w,
        torque_nm: y,
        wob_n: None,
        time_s: None,
    }
}

/// Path of the built `bitrock` binary.
pub fn bin() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_bitrock"))
}
