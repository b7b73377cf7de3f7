//! The CPU reference evaluator: f64 arithmetic on the f32 candidate parameters, rayon across
//! candidates, compensated (Kahan) summation in four interleaved lanes per candidate.

use super::{Evaluator, KernelSums, Problem};
use crate::error::Result;
use crate::laws::file::program::BLOCK;
use crate::laws::{Law, MAX_PARAMS};
use crate::numerics;
use crate::prior::{Candidate, MAX_DIMS};
use rayon::prelude::*;

/// Scores candidates on the CPU. Thread count follows the ambient rayon pool.
pub struct CpuEvaluator {
    problem: Problem,
}

impl CpuEvaluator {
    pub fn new(problem: Problem) -> Self {
        Self { problem }
    }
}

/// Four Kahan accumulators over interleaved samples.
#[derive(Clone, Copy, Default)]
struct Lanes {
    sum: [f64; 4],
    carry: [f64; 4],
}

impl Lanes {
    #[inline(always)]
    fn add(&mut self, terms: [f64; 4]) {
        for ((sum, carry), term) in self.sum.iter_mut().zip(&mut self.carry).zip(terms) {
            let term = term - *carry;
            let t = *sum + term;
            *carry = (t - *sum) - term;
            *sum = t;
        }
    }

    /// The lanes and `tail` merged by a compensated sum.
    fn total(self, tail: impl Iterator<Item = f64>) -> f64 {
        numerics::compensated_sum(self.sum.into_iter().chain(self.carry.iter().map(|c| -c)).chain(tail))
    }
}

/// Σ e² and, with `LAG`, Σ e_t·e_(t−1) over consecutive samples (else 0), e = y − r·T(w),
/// each in four Kahan accumulators over interleaved samples, merged by a compensated sum: exact
/// to a few ulps for any D.
#[inline(always)]
fn residual_sums<const LAG: bool>(w: &[f64], y: &[f64], r: &[f64], torque: impl Fn(f64) -> f64) -> (f64, f64) {
    const LANES: usize = 4;
    let (mut squares, mut lags) = (Lanes::default(), Lanes::default());
    // The residual before the current quad (none before the first sample).
    let mut previous = 0.0f64;
    let (wc, yc, rc) = (w.chunks_exact(LANES), y.chunks_exact(LANES), r.chunks_exact(LANES));
    // The last D mod 4 samples, summed after the lanes (lazily: no allocation per candidate).
    let (w_tail, y_tail, r_tail) = (wc.remainder(), yc.remainder(), rc.remainder());
    for ((w, y), r) in wc.zip(yc).zip(rc) {
        let (w, y, r): (&[f64; LANES], &[f64; LANES], &[f64; LANES]) =
            (w.try_into().unwrap(), y.try_into().unwrap(), r.try_into().unwrap());
        let mut e = [0.0f64; LANES];
        for l in 0..LANES {
            e[l] = y[l] - r[l] * torque(w[l]);
        }
        squares.add([e[0] * e[0], e[1] * e[1], e[2] * e[2], e[3] * e[3]]);
        if LAG {
            lags.add([e[0] * previous, e[1] * e[0], e[2] * e[1], e[3] * e[2]]);
            previous = e[3];
        }
    }
    let mut tail = [0.0f64; LANES];
    for (k, ((&w, &y), &r)) in w_tail.iter().zip(y_tail).zip(r_tail).enumerate() {
        tail[k] = y - r * torque(w);
    }
    let tail = &tail[..w_tail.len()];
    let ssr = squares.total(tail.iter().map(|e| e * e));
    if !LAG {
        return (ssr, 0.0);
    }
    let tail_lags = tail.iter().scan(previous, |before, &e| {
        let product = e * *before;
        *before = e;
        Some(product)
    });
    (ssr, lags.total(tail_lags))
}

/// ρ of one law at f64 parameters `p` against the problem's data.
///
/// exp and tanh are [`numerics::exp`] and [`numerics::tanh`] (within a few ulp of libm, and
/// vectorisable); where the CPU has AVX2 the same code is compiled for it and chosen at run
/// time. Both paths perform the same IEEE operations (Rust never fuses a multiply-add on its
/// own), so they return the same bits.
pub fn rho(problem: &Problem, law: Law, p: &[f64]) -> f64 {
    super::rho_of_sum(sums::<false>(problem, law, p).0, problem.sum_sq_torque)
}

/// ρ and λ = Σ e_t·e_(t−1) / Σy² of one law at f64 parameters `p`, in one pass over the data
/// (see [`rho`]).
pub fn rho_and_lag(problem: &Problem, law: Law, p: &[f64]) -> (f64, f64) {
    let (ssr, lag) = sums::<true>(problem, law, p);
    (
        super::rho_of_sum(ssr, problem.sum_sq_torque),
        super::rho_of_sum(lag, problem.sum_sq_torque),
    )
}

/// Σ e² and (with `LAG`) Σ e_t·e_(t−1) of one law at `p`, on AVX2 where the CPU has it.
fn sums<const LAG: bool>(problem: &Problem, law: Law, p: &[f64]) -> (f64, f64) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        return unsafe { sums_avx2::<LAG>(problem, law, p) };
    }
    sums_portable::<LAG>(problem, law, p)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn sums_avx2<const LAG: bool>(problem: &Problem, law: Law, p: &[f64]) -> (f64, f64) {
    sums_portable::<LAG>(problem, law, p)
}

#[inline(always)]
fn sums_portable<const LAG: bool>(problem: &Problem, law: Law, p: &[f64]) -> (f64, f64) {
    let (w, y, r) = (&problem.speed_rad_s[..], &problem.torque_nm[..], &problem.wob_ratio[..]);
    // A built-in law's parameters are copied into locals first: indexing `p` inside the
    // closure keeps bounds checks in the loop and stops it vectorising (3x slower for m3).
    match law {
        Law::File(id) => {
            // T = r · T(r = 1): the file's torque is checked proportional to r when read. Its
            // torques are computed block by block into this thread's scratch space, then summed
            // as the built-in laws' are.
            let program = &crate::laws::file::registered(id).program;
            // Taken and put back rather than borrowed in a closure: the loop stays in this
            // function, so the AVX2 build covers it.
            let (mut torques, mut registers) = FILE_LAW_SCRATCH.take();
            torques.resize(w.len(), 0.0);
            for (ws, out) in w.chunks(BLOCK).zip(torques.chunks_mut(BLOCK)) {
                program.eval_block(p, ws, out, &mut registers);
            }
            let sums = residual_sums::<LAG>(&torques, y, r, |t| t);
            FILE_LAW_SCRATCH.set((torques, registers));
            sums
        }
        // The built-in law's torque at r = 1 (its file's, compiled by the build), inlined.
        built_in => crate::laws::with_built_in_torque!(built_in, p, |torque| residual_sums::<LAG>(w, y, r, torque)),
    }
}

thread_local! {
    /// A law file's torques over the record and its block evaluator's registers, kept from one
    /// candidate to the next.
    static FILE_LAW_SCRATCH: std::cell::RefCell<(Vec<f64>, Vec<[f64; BLOCK]>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

impl Evaluator for CpuEvaluator {
    fn backend(&self) -> &'static str {
        "cpu"
    }

    fn problem(&self) -> &Problem {
        &self.problem
    }

    fn score(&self, population: u32, start: u64, out: &mut [f64]) -> Result<()> {
        score_stream(&self.problem, population, start, out);
        Ok(())
    }

    fn score_params(&self, candidates: &[Candidate], out: &mut [f64]) -> Result<()> {
        score_candidates(&self.problem, candidates, out);
        Ok(())
    }

    fn score_params_lagged(&self, candidates: &[Candidate], rho: &mut [f64], lag: &mut [f64]) -> Result<()> {
        score_candidates_lagged(&self.problem, candidates, rho, lag);
        Ok(())
    }
}

/// ρ of candidates `start .. start + out.len()` of stream `population` of `problem`, into
/// `out` (rayon across candidates).
pub fn score_stream(problem: &Problem, population: u32, start: u64, out: &mut [f64]) {
    out.par_iter_mut().with_min_len(16).enumerate().for_each(|(k, slot)| {
        let c = problem.prior.candidate(problem.seed, population, start + k as u64);
        *slot = rho_of_candidate(problem, &c);
    });
}

/// ρ of explicit candidates of `problem` into `out` (as long as `candidates`).
pub fn score_candidates(problem: &Problem, candidates: &[Candidate], out: &mut [f64]) {
    assert_eq!(candidates.len(), out.len(), "one ρ per candidate");
    out.par_iter_mut()
        .with_min_len(16)
        .zip(candidates)
        .for_each(|(slot, c)| *slot = rho_of_candidate(problem, c));
}

/// ρ of a candidate: f64 arithmetic on its f32 parameters, widened exactly.
fn rho_of_candidate(problem: &Problem, c: &Candidate) -> f64 {
    let law = problem.prior.law(c.slot);
    rho(problem, law, &c.widened()[..law.n_params()])
}

/// ρ and λ = Σ e_t·e_(t−1) / Σy² of explicit candidates of `problem` into `rho` and `lag`
/// (rayon across candidates): e = y − r·T(w) over consecutive samples of the record, f64
/// arithmetic on the f32 parameters, compensated sums; +∞ where a torque has no value.
pub fn score_candidates_lagged(problem: &Problem, candidates: &[Candidate], rho: &mut [f64], lag: &mut [f64]) {
    assert_eq!(candidates.len(), rho.len(), "one ρ per candidate");
    assert_eq!(candidates.len(), lag.len(), "one lag-1 sum per candidate");
    rho.par_iter_mut()
        .zip(lag.par_iter_mut())
        .with_min_len(16)
        .zip(candidates)
        .for_each(|((rho, lag), c)| {
            let law = problem.prior.law(c.slot);
            (*rho, *lag) = rho_and_lag(problem, law, &c.widened()[..law.n_params()]);
        });
}

/// λ alone of explicit candidates into `out` (see [`score_candidates_lagged`]): the CPU twin
/// of the kernels' lag pass.
pub fn lag_sums(problem: &Problem, candidates: &[Candidate], out: &mut [f64]) {
    let mut rho = vec![0.0; out.len()];
    score_candidates_lagged(problem, candidates, &mut rho, out);
}

/// Terms per block of the kernel sums: each block is a plain sum, blocks are added in groups,
/// as in the GPU twin `shaders/kernel_sums.wgsl` (same loop shape, f64 here).
const TERMS_PER_BLOCK: usize = 64;
const BLOCKS_PER_GROUP: usize = 64;

/// The CPU twin of `shaders/kernel_sums.wgsl` in f64: S_i = Σ_j w_j exp(−|y_i − x_j|²/2) for
/// every target, rayon across targets, each sum in a fixed order (bit-identical on any number
/// of threads).
pub fn kernel_sums(sums: &KernelSums, out: &mut [f64]) {
    // Coordinates past a law's parameters are 0 except where a run infers the string: the
    // shorter loop then, its sums the same to the bit (each skipped term is + 0).
    if sums.law_only() {
        kernel_sums_over::<MAX_PARAMS>(sums, out);
    } else {
        kernel_sums_over::<MAX_DIMS>(sums, out);
    }
}

/// [`kernel_sums`] over the first `D` coordinates.
fn kernel_sums_over<const D: usize>(sums: &KernelSums, out: &mut [f64]) {
    assert_eq!(sums.targets.len(), out.len(), "one sum per target");
    assert_eq!(sums.sources.len(), sums.weights.len(), "one weight per source");
    if let Some(c) = sums.rank_one {
        assert_eq!(c.len(), sums.sources.len(), "one rank-one coefficient per source");
    }
    out.par_iter_mut()
        .with_min_len(8)
        .zip(sums.targets)
        .for_each(|(slot, y)| {
            let (mut total, mut group, mut blocks) = (0.0f64, 0.0f64, 0usize);
            for (block, (xs, ws)) in sums
                .sources
                .chunks(TERMS_PER_BLOCK)
                .zip(sums.weights.chunks(TERMS_PER_BLOCK))
                .enumerate()
            {
                let mut s = 0.0f64;
                for (j, (x, &w)) in xs.iter().zip(ws).enumerate() {
                    let mut r2 = 0.0f64;
                    for k in 0..D {
                        let d = y[k] - x[k];
                        r2 += d * d;
                    }
                    if let Some(c) = sums.rank_one {
                        let along: f64 = (0..D).map(|k| (y[k] - x[k]) * x[k]).sum();
                        // The difference of two near-equal squares can round below 0.
                        r2 = (r2 - c[block * TERMS_PER_BLOCK + j] * along * along).max(0.0);
                    }
                    s += w * numerics::exp(-0.5 * r2);
                }
                group += s;
                blocks += 1;
                if blocks == BLOCKS_PER_GROUP {
                    total += group;
                    group = 0.0;
                    blocks = 0;
                }
            }
            *slot = total + group;
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rank_one_sums_are_gaussians_with_covariance_identity_plus_x_xt() {
        // Source x = (1, 2) with c = 1/6 has covariance Σ = I + x xᵀ = [[2, 2], [2, 5]],
        // Σ⁻¹ = [[5, −2], [−2, 2]] / 6; a target at (0, 0.5): d = (−1, −1.5), dᵀΣ⁻¹d =
        // (5 − 6 + 4.5) / 6 = 3.5 / 6.
        let x = [1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let y = [0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut out = [0.0];
        kernel_sums(
            &KernelSums {
                targets: &[y],
                sources: &[x],
                weights: &[0.25],
                rank_one: Some(&[1.0 / 6.0]),
            },
            &mut out,
        );
        let expected = 0.25 * (-0.5 * 3.5 / 6.0f64).exp();
        assert!((out[0] - expected).abs() < 1e-15, "{} vs {expected}", out[0]);
    }

    #[test]
    fn kernel_sums_are_the_weighted_gaussian_sums() {
        // Sources 0, 1, 2 on the first axis with weights 0.5, 0.25, 0.25; target at 1:
        // S = 0.5 e^{-1/2} + 0.25 + 0.25 e^{-1/2}.
        let p = |x: f64| [x, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let sources = [p(0.0), p(1.0), p(2.0)];
        let targets = [p(1.0), [1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]];
        let mut out = [0.0; 2];
        kernel_sums(
            &KernelSums {
                rank_one: None,
                targets: &targets,
                sources: &sources,
                weights: &[0.5, 0.25, 0.25],
            },
            &mut out,
        );
        let e = (-0.5f64).exp();
        assert!((out[0] - (0.75 * e + 0.25)).abs() <= 1e-15, "{}", out[0]);
        // Two units off the axis multiplies every term by e^{-2}.
        assert!(
            (out[1] - (0.75 * e + 0.25) * (-2.0f64).exp()).abs() <= 1e-15,
            "{}",
            out[1]
        );
    }

    #[test]
    fn kernel_sums_count_the_coordinates_past_a_law_s_parameters() {
        // A target and a source 1 apart in coordinate 0 and, for a run that infers the string,
        // 2 apart in coordinate 7 (the damping ratio of a six-parameter law): e^{-1/2} e^{-2}.
        let source = [0.0; MAX_DIMS];
        let mut target = [0.0; MAX_DIMS];
        target[0] = 1.0;
        let mut out = [0.0];
        let sums = |target: [f64; MAX_DIMS], out: &mut [f64]| {
            kernel_sums(
                &KernelSums {
                    rank_one: None,
                    targets: &[target],
                    sources: &[source],
                    weights: &[1.0],
                },
                out,
            )
        };
        sums(target, &mut out);
        assert_eq!(out[0].to_bits(), crate::numerics::exp(-0.5).to_bits());
        target[7] = 2.0;
        sums(target, &mut out);
        assert!((out[0] - (-2.5f64).exp()).abs() <= 1e-15, "{}", out[0]);
    }
}
