//! What a sampler scores its candidates against: the prior and seed that generate them, and
//! the calibration samples that score them. Every sampler (the paper's ABC, the evidence) and
//! every backend takes the same one.

use crate::data::Samples;
use crate::fit::LawFit;
use crate::laws::Law;
use crate::prior::Prior;

/// Everything that determines ρ of a candidate: the prior and seed (which generate it) and
/// the calibration data (which score it).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Problem {
    pub prior: Prior,
    pub seed: u64,
    /// Bit speed, rad/s.
    pub speed_rad_s: Vec<f64>,
    /// Torque on bit, N·m.
    pub torque_nm: Vec<f64>,
    /// Weight-on-bit ratio r per sample.
    pub wob_ratio: Vec<f64>,
    /// Σy², (N·m)², summed once on the host in f64 with compensation.
    pub sum_sq_torque: f64,
    /// Best least-squares ρ of each law on these data where known: no candidate of the law
    /// scores below it, so a tolerance at or below it cannot be reached.
    pub best_rho: std::collections::BTreeMap<Law, f64>,
}

impl Problem {
    /// The problem of calibrating against `data` with r per sample from `w_ref_n` (see
    /// [`Samples::wob_ratio`]).
    pub fn new(prior: Prior, seed: u64, data: &Samples, w_ref_n: Option<f64>) -> Self {
        Self {
            prior,
            seed,
            speed_rad_s: data.speed_rad_s.clone(),
            torque_nm: data.torque_nm.clone(),
            wob_ratio: data.wob_ratio(w_ref_n),
            sum_sq_torque: data.sum_sq_torque(),
            best_rho: Default::default(),
        }
    }

    /// The problem with the laws' best least-squares ρ taken from `fits` (made on the same
    /// calibration data).
    pub fn with_best_rho(mut self, fits: &[LawFit]) -> Self {
        for fit in fits {
            self.best_rho.insert(fit.law, fit.rho);
        }
        self
    }

    /// False when `law`'s best least-squares ρ shows that no candidate of it can score below
    /// `epsilon`; true when it can or when its best ρ is unknown.
    pub fn can_reach(&self, law: Law, epsilon: f64) -> bool {
        self.best_rho.get(&law).is_none_or(|&best| best < epsilon)
    }

    /// Number of data points D.
    pub fn data_len(&self) -> usize {
        self.speed_rad_s.len()
    }
}
