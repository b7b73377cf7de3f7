//! One island: a tempered sampler of one law, from its prior box (or a reference) to its
//! posterior, with its own random stream; and the pooling of the islands' estimates.

use super::*;

/// The words of draw `index` of the stream of (law slot, island): four per call.
pub(super) fn words(seed: u64, stream: u32, index: u64) -> [u32; 4] {
    philox4x32_10(
        [index as u32, (index >> 32) as u32, stream, EVIDENCE_BLOCK],
        key_of_seed(seed),
    )
}

/// A sequential stream of Philox words for one island.
#[derive(Serialize, Deserialize)]
pub(crate) struct Stream {
    pub(crate) seed: u64,
    pub(crate) stream: u32,
    pub(crate) next: u64,
}

impl Stream {
    pub(crate) fn draw(&mut self) -> [u32; 4] {
        let w = words(self.seed, self.stream, self.next);
        self.next += 1;
        w
    }

    /// A uniform on (0, 1).
    pub(crate) fn uniform(&mut self) -> f64 {
        open_unit(self.draw()[0])
    }

    /// A uniform draw in the box from `lower` to `upper` into `out`'s first coordinates (one
    /// Philox block per four of them).
    pub(crate) fn uniform_in(&mut self, lower: &[f32], upper: &[f32], out: &mut [f32]) {
        let d = lower.len();
        for block in (0..d).step_by(4) {
            let w = self.draw();
            for (k, &word) in (block..d.min(block + 4)).zip(&w) {
                out[k] = uniform_between(lower[k], upper[k], word);
            }
        }
    }

    /// `d` standard normals.
    pub(super) fn normals(&mut self, d: usize, out: &mut [f64]) {
        for pair in out[..d].chunks_mut(2) {
            let w = self.draw();
            let z = box_muller(w[0], w[1]);
            pair.copy_from_slice(&z[..pair.len()]);
        }
    }
}

/// ln Z from independent islands' estimates (`island_ln_z`) and its Monte-Carlo error: ln of
/// the mean of their Z, and the standard error of that mean relative to it, where the islands
/// agree. Where they disagree by nats, one island carries the mean and that error saturates
/// near 1 whatever the spread: then the standard error of the islands' ln Z is the honest one.
/// Where they spread by more than [`REFINE_ABOVE_NATS`], see [`apart`].
pub(super) fn pooled_ln_z(island_ln_z: &[f64]) -> (f64, f64) {
    let ln_z = log_mean_exp(island_ln_z.iter().copied());
    let k = island_ln_z.len() as f64;
    let variance = island_ln_z
        .iter()
        .map(|v| ((v - ln_z).exp() - 1.0).powi(2))
        .sum::<f64>()
        / (k - 1.0);
    let mean_ln_z = island_ln_z.iter().sum::<f64>() / k;
    let deviation = (island_ln_z.iter().map(|v| (v - mean_ln_z).powi(2)).sum::<f64>() / (k - 1.0)).sqrt();
    (ln_z, (variance / k).sqrt().max(deviation / k.sqrt()))
}

/// The error `error` of an estimate from islands `island_ln_z`, as reported: where they
/// spread by more than [`REFINE_ABOVE_NATS`] (after any refinement) ln Z may lie anywhere
/// among them, and the error is at least half their range. (Whether two starts agree is judged
/// on their standard errors: the range would let a start that missed nats of the posterior
/// pass for one that agrees.)
pub(super) fn apart(island_ln_z: &[f64], error: f64) -> f64 {
    let range = spread_of(island_ln_z);
    if range > REFINE_ABOVE_NATS {
        error.max(range / 2.0)
    } else {
        error
    }
}

/// The mean of independent estimates (value, standard error) weighed by their inverse
/// variances, and its standard error, scaled up by the Birge ratio √(χ²/(k − 1)) where the k
/// estimates scatter more than their errors allow (the Particle Data Group's scale factor):
/// errors from a few islands each are rough, and where two disagree the mean's error says so.
pub(super) fn inverse_variance_mean(estimates: &[(f64, f64)]) -> (f64, f64) {
    // An error of exactly zero (islands that agree to the last bit) weighs as a tiny one.
    let weight = |error: f64| error.max(1e-9).powi(-2);
    let total: f64 = estimates.iter().map(|&(_, e)| weight(e)).sum();
    let mean = estimates.iter().map(|&(v, e)| v * weight(e)).sum::<f64>() / total;
    let chi2: f64 = estimates.iter().map(|&(v, e)| (v - mean).powi(2) * weight(e)).sum();
    let birge = (chi2 / (estimates.len() as f64 - 1.0).max(1.0)).sqrt().max(1.0);
    (mean, birge / total.sqrt())
}

/// Largest difference between two islands' ln Z, nats.
pub(super) fn spread_of(island_ln_z: &[f64]) -> f64 {
    let highest = island_ln_z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let lowest = island_ln_z.iter().copied().fold(f64::INFINITY, f64::min);
    highest - lowest
}

/// ln of the mean of exp(values) (−∞ entries count as 0).
pub(super) fn log_mean_exp(values: impl Iterator<Item = f64> + Clone) -> f64 {
    let count = values.clone().count() as f64;
    let max = values.clone().fold(f64::NEG_INFINITY, f64::max);
    if max == f64::NEG_INFINITY {
        return f64::NEG_INFINITY;
    }
    let sum: f64 = values.map(|v| (v - max).exp()).sum();
    max + (sum / count).ln()
}

/// Kish's effective sample size of the weights exp(Δβ·ℓ) (−∞ entries weigh 0).
pub(super) fn ess_of_step(loglik: &[f64], step: f64) -> f64 {
    let max = loglik.iter().fold(f64::NEG_INFINITY, |m, &l| m.max(step * l));
    let (mut s1, mut s2) = (0.0, 0.0);
    for &l in loglik {
        if l > f64::NEG_INFINITY {
            let w = (step * l - max).exp();
            s1 += w;
            s2 += w * w;
        }
    }
    if s2 > 0.0 { s1 * s1 / s2 } else { 0.0 }
}

/// What an island is waiting for.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub(super) enum Phase {
    /// Its draws from the prior to be scored.
    Prior,
    /// Its proposals of a Metropolis sweep to be scored.
    Sweep,
    /// Nothing: β reached 1, and the particles are weighted by the last step.
    Done,
}

/// One tempered sampler of one law; everything it holds between two scored batches is its
/// state ([`Checkpoints`]), less its reference, which the job makes again.
#[derive(Serialize, Deserialize)]
pub(super) struct Island {
    pub(super) law: Law,
    pub(super) slot: usize,
    pub(super) dims: usize,
    pub(super) lower: [f32; MAX_PARAMS],
    pub(super) upper: [f32; MAX_PARAMS],
    pub(super) theta: Vec<[f32; MAX_PARAMS]>,
    pub(super) loglik: Vec<f64>,
    /// The particles' normalised weights once β reached 1 (empty before).
    pub(super) weights: Vec<f64>,
    pub(super) beta: f64,
    pub(super) ln_z: f64,
    pub(super) stages: usize,
    pub(super) phase: Phase,
    /// Lower Cholesky factor of the proposal covariance (before `scale`).
    pub(super) factor: DMatrix<f64>,
    /// The proposal's multiplier of 2.38/√d, adapted to the acceptance rate.
    pub(super) scale: f64,
    pub(super) sweeps_done: usize,
    pub(super) sweeps_wanted: usize,
    /// Proposals of the sweep in progress, and whether each lies in the box.
    pub(super) proposals: Vec<[f32; MAX_PARAMS]>,
    pub(super) inside: Vec<bool>,
    pub(super) stream: Stream,
    pub(super) scored: u64,
    pub(super) best_rho: f64,
    /// The warm start's reference, where the sampler starts from one: `loglik` is then
    /// ln L + ln π − ln q (ln L alone from the box, where the last two cancel) and `ln_q`
    /// each particle's ln q.
    #[serde(skip)]
    pub(super) reference: Option<Kernels>,
    /// The law's prior cut to curves within the record's torques, where it is: the prior's
    /// support is then the box's part that keeps it (the job makes it again on a resume).
    #[serde(skip)]
    pub(super) curve: Option<CurveLimit>,
    pub(super) ln_q: Vec<f64>,
    pub(super) proposal_ln_q: Vec<f64>,
}

/// Box draws an island starting from a law's prior makes for one particle inside a curve's
/// limit before it keeps one outside (weight 0): never reached where the limit keeps the
/// 0.15 % of the box [`CurveLimit`] requires.
const MAX_CURVE_ATTEMPTS: usize = 1_000_000;

/// Acceptance rate the random walk's scale is adapted towards (Roberts, Gelman & Gilks).
pub(super) const TARGET_ACCEPTANCE: f64 = 0.234;
/// A sweep count that leaves a particle unmoved with at most this probability.
pub(super) const UNMOVED: f64 = 0.05;

impl Island {
    pub(super) fn new(
        slot: usize,
        bx: &LawBox,
        config: &EvidenceConfig,
        stream: u32,
        reference: Option<&Reference>,
    ) -> Self {
        let (law, lower, upper) = (bx.law, &bx.lower, &bx.upper);
        let dims = law.n_params();
        let mut lo = [0.0f32; MAX_PARAMS];
        let mut hi = [0.0f32; MAX_PARAMS];
        lo[..dims].copy_from_slice(lower);
        hi[..dims].copy_from_slice(upper);
        let mut stream = Stream {
            seed: config.seed,
            stream,
            next: 0,
        };
        let reference = reference.map(|r| Kernels::new(r, lower, upper));
        let particles = config.particles_of(law);
        let mut inside = Vec::with_capacity(particles);
        let proposals: Vec<[f32; MAX_PARAMS]> = (0..particles)
            .map(|_| {
                let mut p = [0.0f32; MAX_PARAMS];
                let from_box = match &reference {
                    None => true,
                    Some(_) => stream.uniform() < DEFENSIVE_SHARE,
                };
                let keeps_curve = |p: &[f32; MAX_PARAMS]| bx.curve.as_ref().is_none_or(|c| c.holds(law, &p[..dims]));
                if from_box {
                    // From the prior itself where the island starts from it: the box's draws
                    // until one keeps the curve's limit (its share is at least 0.15 %). A
                    // reference's defensive draws stay the box's, as its density says.
                    let mut keeps = false;
                    for attempt in 0.. {
                        stream.uniform_in(&lo[..dims], &hi[..dims], &mut p);
                        keeps = keeps_curve(&p);
                        if reference.is_some() || keeps || attempt == MAX_CURVE_ATTEMPTS {
                            break;
                        }
                    }
                    inside.push(keeps);
                } else if let Some(kernels) = &reference {
                    kernels.draw(&mut stream, &mut p);
                    inside.push((0..dims).all(|j| p[j] >= lo[j] && p[j] <= hi[j]) && keeps_curve(&p));
                }
                p
            })
            .collect();
        let proposal_ln_q = match &reference {
            Some(g) => proposals
                .par_iter()
                .zip(&inside)
                .map(|(p, &inside)| g.ln_q(&p[..dims], inside))
                .collect(),
            None => Vec::new(),
        };
        Self {
            law,
            slot,
            dims,
            lower: lo,
            upper: hi,
            theta: Vec::new(),
            loglik: Vec::new(),
            weights: Vec::new(),
            beta: 0.0,
            ln_z: 0.0,
            stages: 0,
            phase: Phase::Prior,
            factor: DMatrix::identity(dims, dims),
            scale: 1.0,
            sweeps_done: 0,
            sweeps_wanted: 1,
            inside,
            proposals,
            stream,
            scored: 0,
            best_rho: f64::INFINITY,
            reference,
            curve: bx.curve.clone(),
            ln_q: Vec::new(),
            proposal_ln_q,
        }
    }

    /// Drops the particles of an island a refinement replaced; its ln Z, counts and stream
    /// stay, for the record of what was spent.
    pub(super) fn let_go(&mut self) {
        self.theta = Vec::new();
        self.proposals = Vec::new();
        self.inside = Vec::new();
        self.loglik = Vec::new();
        self.weights = Vec::new();
        self.ln_q = Vec::new();
        self.proposal_ln_q = Vec::new();
    }

    /// Whether a refinement replaced this island ([`let_go`](Self::let_go)).
    pub(super) fn let_go_of(&self) -> bool {
        self.phase == Phase::Done && self.theta.is_empty()
    }

    /// ln π − ln q at a particle inside the prior's support with ln q = `ln_q` (0 without a
    /// reference): π is uniform there, 1/V on the box, 1/(V·P_B(C)) on a box cut to a curve's
    /// limit C.
    pub(super) fn prior_over_reference(&self, ln_q: f64) -> f64 {
        let ln_share = self.curve.as_ref().map_or(0.0, |c| c.ln_share);
        self.reference.as_ref().map_or(0.0, |g| -g.ln_volume - ln_share - ln_q)
    }

    /// ⟨ln L⟩ over the island's posterior (β = 1), without the likelihood's constant: the
    /// weighted particles' log-likelihoods, a warm start's ln π − ln q taken back out.
    pub(super) fn posterior_mean_ln_l(&self) -> f64 {
        self.weights
            .iter()
            .enumerate()
            .filter(|(_, w)| **w > 0.0)
            .map(|(i, w)| w * (self.loglik[i] - self.ln_q.get(i).map_or(0.0, |&q| self.prior_over_reference(q))))
            .sum()
    }

    /// The candidates to score now: the proposals inside the box.
    pub(super) fn candidates(&self, out: &mut Vec<Candidate>) {
        if self.phase == Phase::Done {
            return;
        }
        for (p, _) in self.proposals.iter().zip(&self.inside).filter(|(_, inside)| **inside) {
            let mut params = [0.0f32; crate::prior::MAX_DIMS];
            params[..p.len()].copy_from_slice(p);
            out.push(Candidate {
                slot: self.slot,
                params,
            });
        }
    }

    /// Takes the misfits and log-likelihoods of [`Self::candidates`] (in that order) and moves on: accepts or
    /// rejects the sweep's proposals, then starts the next sweep, the next tempering step, or
    /// ends.
    pub(super) fn receive(&mut self, rho: &[f64], loglik: &[f64], config: &EvidenceConfig) -> Result<()> {
        self.scored += rho.len() as u64;
        self.best_rho = rho.iter().copied().fold(self.best_rho, f64::min);
        let mut scores = loglik.iter();
        match self.phase {
            Phase::Done => return Ok(()),
            Phase::Prior => {
                self.theta = std::mem::take(&mut self.proposals);
                self.ln_q = std::mem::take(&mut self.proposal_ln_q);
                // Outside the box (a reference's draw): π = 0.
                self.loglik = (0..self.theta.len())
                    .map(|i| match self.inside[i] {
                        true => {
                            let l = *scores.next().expect("one score per draw");
                            l + self.ln_q.get(i).map_or(0.0, |&q| self.prior_over_reference(q))
                        }
                        false => f64::NEG_INFINITY,
                    })
                    .collect();
            }
            Phase::Sweep => {
                // The reference's density at every scored proposal, in parallel (a pure
                // function of the proposal: the same bits in any order).
                let proposals_ln_q: Vec<f64> = match &self.reference {
                    Some(g) => (0..self.theta.len())
                        .into_par_iter()
                        .map(|i| match self.inside[i] {
                            true => g.ln_q(&self.proposals[i][..self.dims], true),
                            false => f64::NEG_INFINITY,
                        })
                        .collect(),
                    None => Vec::new(),
                };
                let mut accepted = 0;
                for i in 0..self.theta.len() {
                    if !self.inside[i] {
                        continue;
                    }
                    let mut proposed = *scores.next().expect("one score per proposal");
                    let u = self.stream.uniform();
                    // The ratio of tempered targets q^(1−β)·(π·L)^β = q·exp(β·ℓ), ℓ = ln(π·L/q):
                    // from the box (q = π uniform), β times the log-likelihoods' difference.
                    let mut ln_ratio = 0.0;
                    let mut proposed_ln_q = 0.0;
                    if let Some(&q) = proposals_ln_q.get(i) {
                        proposed_ln_q = q;
                        proposed += self.prior_over_reference(q);
                        ln_ratio = q - self.ln_q[i];
                    }
                    if proposed > f64::NEG_INFINITY && u.ln() < ln_ratio + self.beta * (proposed - self.loglik[i]) {
                        self.theta[i] = self.proposals[i];
                        self.loglik[i] = proposed;
                        if self.reference.is_some() {
                            self.ln_q[i] = proposed_ln_q;
                        }
                        accepted += 1;
                    }
                }
                self.sweeps_done += 1;
                if self.sweeps_done == 1 {
                    let rate = accepted as f64 / self.theta.len() as f64;
                    self.sweeps_wanted = if rate >= 1.0 - UNMOVED {
                        1
                    } else if rate <= 0.0 {
                        config.max_sweeps
                    } else {
                        ((UNMOVED.ln() / (1.0 - rate).ln()).ceil() as usize).clamp(1, config.max_sweeps)
                    };
                    // Towards the target acceptance, by at most a factor e per step.
                    self.scale *= (2.0 * (rate - TARGET_ACCEPTANCE)).clamp(-1.0, 1.0).exp();
                }
                if self.sweeps_done < self.sweeps_wanted {
                    self.propose();
                    return Ok(());
                }
            }
        }
        self.temper(config)
    }

    /// One tempering step: the next β, ln Z's increment, resampling, the new proposal
    /// covariance, and the first sweep's proposals.
    pub(super) fn temper(&mut self, config: &EvidenceConfig) -> Result<()> {
        if self.stages == config.max_stages {
            return Err(Error::setting(
                "max_stages",
                format!(
                    "law {} needed more than {} tempering steps (β = {:.3e}); its likelihood is much narrower than its prior box: narrow the box or raise `max_stages`",
                    self.law, config.max_stages, self.beta
                ),
            ));
        }
        let n = self.theta.len() as f64;
        let finite = self.loglik.iter().filter(|l| **l > f64::NEG_INFINITY).count();
        if finite == 0 {
            return Err(Error::setting(
                "prior",
                format!(
                    "no candidate of law {} drawn from its prior box has a finite torque on this record",
                    self.law
                ),
            ));
        }
        let target = config.ess_share * n;
        let remaining = 1.0 - self.beta;
        let reaches_one = ess_of_step(&self.loglik, remaining) >= target;
        let step = if reaches_one {
            remaining
        } else {
            let (mut lo, mut hi) = (0.0, remaining);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if ess_of_step(&self.loglik, mid) >= target {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        let increments: Vec<f64> = self
            .loglik
            .iter()
            .map(|&l| {
                if l > f64::NEG_INFINITY {
                    step * l
                } else {
                    f64::NEG_INFINITY
                }
            })
            .collect();
        self.ln_z += log_mean_exp(increments.iter().copied());
        let max = increments.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let weights: Vec<f64> = increments.iter().map(|&v| (v - max).exp()).collect();
        self.stages += 1;
        if reaches_one {
            // The weighted particles are the posterior: their effective size is at least
            // `ess_share` of the island's, and resampling and moving them would only spend
            // candidates on what the weights already say.
            let total: f64 = weights.iter().sum();
            self.weights = weights.iter().map(|w| w / total).collect();
            self.beta = 1.0;
            self.phase = Phase::Done;
            self.proposals.clear();
            return Ok(());
        }
        self.factor = self.proposal_factor(&weights);
        let picks = systematic_from(&weights, self.theta.len(), self.stream.uniform());
        self.theta = picks.iter().map(|&i| self.theta[i]).collect();
        self.loglik = picks.iter().map(|&i| self.loglik[i]).collect();
        if self.reference.is_some() {
            self.ln_q = picks.iter().map(|&i| self.ln_q[i]).collect();
        }
        self.beta += step;
        self.sweeps_done = 0;
        self.sweeps_wanted = 1;
        self.propose();
        Ok(())
    }

    /// The lower Cholesky factor of the weighted particles' covariance, times 2.38/√d; a
    /// covariance that is not positive definite (particles collapsed onto a line) falls back
    /// to its diagonal, and a zero variance to a millionth of the box.
    pub(super) fn proposal_factor(&self, weights: &[f64]) -> DMatrix<f64> {
        let d = self.dims;
        let total: f64 = weights.iter().sum();
        let mut mean = DVector::<f64>::zeros(d);
        for (p, &w) in self.theta.iter().zip(weights) {
            for j in 0..d {
                mean[j] += w * f64::from(p[j]);
            }
        }
        mean /= total;
        let mut cov = DMatrix::<f64>::zeros(d, d);
        for (p, &w) in self.theta.iter().zip(weights) {
            let x = DVector::from_iterator(d, (0..d).map(|j| f64::from(p[j]) - mean[j]));
            cov += w * &x * x.transpose();
        }
        cov /= total;
        floored_cholesky(cov, &self.lower[..d], &self.upper[..d]) * (2.38 / (d as f64).sqrt())
    }

    /// A random-walk proposal per particle; those outside the prior's support (the box, and a
    /// curve's limit where the law has one) are rejected unscored.
    pub(super) fn propose(&mut self) {
        let d = self.dims;
        let mut z = [0.0f64; MAX_PARAMS];
        self.proposals.resize(self.theta.len(), [0.0; MAX_PARAMS]);
        self.inside.resize(self.theta.len(), false);
        for i in 0..self.theta.len() {
            self.stream.normals(d, &mut z);
            let mut p = [0.0f32; MAX_PARAMS];
            let mut inside = true;
            for (j, slot) in p.iter_mut().enumerate().take(d) {
                let step: f64 = (0..=j).map(|k| self.factor[(j, k)] * z[k]).sum();
                let v = (f64::from(self.theta[i][j]) + self.scale * step) as f32;
                inside &= v >= self.lower[j] && v <= self.upper[j];
                *slot = v;
            }
            if inside && let Some(curve) = &self.curve {
                inside = curve.holds(self.law, &p[..d]);
            }
            self.proposals[i] = p;
            self.inside[i] = inside;
        }
        self.phase = Phase::Sweep;
    }
}

/// (e_0² + e_(n−1)²) / Σy² of candidate `c` on `problem`'s record, in f64: the end terms of
/// the AR(1) likelihood, which the kernels' sums do not hold.
pub(super) fn end_residuals_squared(problem: &Problem, c: &Candidate) -> f64 {
    let law = problem.prior.law(c.slot);
    let p = c.widened();
    let n = problem.data_len();
    let e = |i: usize| {
        problem.torque_nm[i] - law.torque(&p[..law.n_params()], problem.speed_rad_s[i], problem.wob_ratio[i])
    };
    (e(0).powi(2) + e(n - 1).powi(2)) / problem.sum_sq_torque
}
