//! Scoring candidates: the [`Evaluator`] trait the samplers call, and the problem every backend
//! scores against. The CPU evaluator (f64) is the reference; the GPU one must match it.

pub mod cpu;

use crate::data::Samples;
use crate::error::Result;
use crate::prior::Prior;

/// Everything that determines ρ of a candidate: the prior and seed (which generate it) and
/// the calibration data (which score it).
#[derive(Clone, Debug)]
pub struct AbcProblem {
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
}

impl AbcProblem {
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
        }
    }

    /// Number of data points D.
    pub fn data_len(&self) -> usize {
        self.speed_rad_s.len()
    }
}

/// Scores contiguous ranges of candidate indices. Implementations must return, for candidate
/// i of population g, ρ of `problem.prior.candidate(seed, g, i)` against the data.
pub trait Evaluator: Sync {
    /// Backend name for records (`cpu`, `gpu`).
    fn backend(&self) -> &'static str;
    /// The problem being scored.
    fn problem(&self) -> &AbcProblem;
    /// Writes ρ of candidates `start .. start + out.len()` of `population` into `out`.
    fn score(&self, population: u32, start: u64, out: &mut [f64]) -> Result<()>;
}
