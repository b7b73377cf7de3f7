//! Approximate Bayesian Computation with model selection: the paper's rejection sampler
//! (Algorithm 1), its records, and the posterior summaries a user reads off it.

pub mod posterior;
pub mod rejection;

use crate::laws::Law;
use serde::Serialize;

/// One accepted candidate: a law, its parameters (SI; the f32 values the candidate generator
/// produced, widened exactly to f64) and its misfit ρ.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Particle {
    pub law: Law,
    /// Candidate index within its stream: with the seed and population it regenerates the
    /// particle (see `crate::rng`).
    pub index: u64,
    pub params: Vec<f64>,
    pub rho: f64,
}
