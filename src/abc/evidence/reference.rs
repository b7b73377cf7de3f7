//! Warm starts: the reference density a law's samplers start from instead of its box, and the
//! kernels that draw from it and weigh by it.

use super::*;

/// Share of a warm start's first draws made from the law's box rather than its reference:
/// the defence that keeps the importance weights bounded where the reference misses the
/// posterior (a change of formation).
pub const DEFENSIVE_SHARE: f64 = 0.1;

/// Where a law's samplers start instead of its prior box: a kernel density of a previous
/// posterior's particles (a Gaussian kernel on each, shaped by their covariance and
/// [`KERNEL_WIDTH`] wide), mixed with the box ([`DEFENSIVE_SHARE`]). The tempered path runs from
/// this reference q to π·L (targets q^(1−β)·(π·L)^β), so ln Z stays the evidence under the
/// prior π: the reference changes the cost, not what is estimated. A density of the particles
/// follows a curved or ridge-shaped posterior, where one Gaussian would leave whole stretches
/// of it in its tails.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reference {
    pub law: Law,
    /// The particles (SI parameters) and their weights (summing to 1).
    pub particles: Vec<Vec<f64>>,
    pub weights: Vec<f64>,
    /// Their weighted covariance (row-major, d × d).
    pub covariance: Vec<f64>,
}

/// The kernels' standard deviations, in the particles' own: wide enough to cover what a
/// window more or less moves the posterior, narrow enough to keep its shape.
pub const KERNEL_WIDTH: f64 = 0.8;

/// Most particles a reference keeps (the heaviest): its density costs a term per particle at
/// every candidate.
pub const REFERENCE_PARTICLES: usize = 400;

impl Reference {
    /// The reference of `law` from weighted posterior particles (parameters, weight): at most
    /// [`REFERENCE_PARTICLES`] of them, the heaviest; `None` with fewer than 2 × d + 1
    /// weighted particles.
    pub fn from_posterior(law: Law, particles: &[(&[f64], f64)]) -> Option<Self> {
        let d = law.n_params();
        let mut kept: Vec<(&[f64], f64)> = particles
            .iter()
            .filter(|(p, w)| *w > 0.0 && w.is_finite() && p.len() == d)
            .copied()
            .collect();
        if kept.len() <= 2 * d {
            return None;
        }
        // Heaviest first, ties in the given order: the same reference on every run.
        kept.sort_by(|a, b| b.1.total_cmp(&a.1));
        kept.truncate(REFERENCE_PARTICLES);
        let total: f64 = kept.iter().map(|(_, w)| w).sum();
        let mut mean = vec![0.0; d];
        for (p, w) in &kept {
            for j in 0..d {
                mean[j] += w * p[j] / total;
            }
        }
        let mut covariance = vec![0.0; d * d];
        for (p, w) in &kept {
            for j in 0..d {
                for k in 0..d {
                    covariance[j * d + k] += w * (p[j] - mean[j]) * (p[k] - mean[k]) / total;
                }
            }
        }
        Some(Self {
            law,
            particles: kept.iter().map(|(p, _)| p.to_vec()).collect(),
            weights: kept.iter().map(|(_, w)| w / total).collect(),
            covariance,
        })
    }

    /// A Gaussian reference: one kernel at `mean` (SI) of covariance `covariance` (row-major,
    /// d × d, SI), such as a fit's Laplace approximation of the posterior, widened.
    pub fn gaussian(law: Law, mean: Vec<f64>, covariance: &[f64]) -> Self {
        // Kernels are KERNEL_WIDTH of the covariance wide: undone here.
        let unwidened = 1.0 / (KERNEL_WIDTH * KERNEL_WIDTH);
        Self {
            law,
            particles: vec![mean],
            weights: vec![1.0],
            covariance: covariance.iter().map(|c| c * unwidened).collect(),
        }
    }

    /// The same reference moved by `by` (SI, one value per parameter): where the posterior has
    /// moved with the law's least-squares estimate.
    pub fn shifted(mut self, by: &[f64]) -> Self {
        for p in &mut self.particles {
            for (v, b) in p.iter_mut().zip(by) {
                *v += b;
            }
        }
        self
    }
}

/// The lower Cholesky factor of `cov`, its variances floored at a millionth of the box's width
/// (squared); a covariance that is not positive definite (particles collapsed onto a line)
/// falls back to its diagonal.
pub(super) fn floored_cholesky(mut cov: DMatrix<f64>, lower: &[f32], upper: &[f32]) -> DMatrix<f64> {
    for j in 0..cov.nrows() {
        let floor = 1e-6 * f64::from(upper[j] - lower[j]);
        if cov[(j, j)].is_nan() || cov[(j, j)] <= floor * floor {
            cov[(j, j)] = floor * floor;
        }
    }
    match cov.clone().cholesky() {
        Some(c) => c.l(),
        None => DMatrix::from_diagonal(&cov.diagonal().map(f64::sqrt)),
    }
}

/// A reference made ready for one box: its kernels' Cholesky factor, the centres whitened by
/// it, the log-normaliser and the box's log-volume.
#[derive(Clone, Debug)]
pub(crate) struct Kernels {
    pub(super) dims: usize,
    pub(super) centres: Vec<[f64; MAX_PARAMS]>,
    /// L⁻¹·c for each centre c: a kernel's exponent is then one difference of whitened points.
    pub(super) whitened: Vec<[f64; MAX_PARAMS]>,
    pub(super) ln_weights: Vec<f64>,
    /// Running sums of the weights, for drawing a kernel.
    pub(super) cumulative: Vec<f64>,
    pub(super) factor: DMatrix<f64>,
    /// ln of one kernel's normaliser, (2π)^(−d/2)·|h²Σ|^(−1/2).
    pub(super) ln_norm: f64,
    /// ln of the box's volume (the prior's density is its negative inside).
    pub(super) ln_volume: f64,
}

impl Kernels {
    pub(crate) fn new(reference: &Reference, lower: &[f32], upper: &[f32]) -> Self {
        let d = lower.len();
        let width = KERNEL_WIDTH * KERNEL_WIDTH;
        let covariance = DMatrix::from_row_slice(d, d, &reference.covariance) * width;
        let factor = floored_cholesky(covariance, lower, upper);
        let ln_det: f64 = (0..d).map(|j| factor[(j, j)].ln()).sum();
        let centres: Vec<[f64; MAX_PARAMS]> = reference
            .particles
            .iter()
            .map(|p| {
                let mut c = [0.0; MAX_PARAMS];
                c[..d].copy_from_slice(&p[..d]);
                c
            })
            .collect();
        let whitened = centres.iter().map(|c| whiten(&factor, &c[..d])).collect();
        let mut total = 0.0;
        let cumulative = reference
            .weights
            .iter()
            .map(|w| {
                total += w;
                total
            })
            .collect();
        Self {
            dims: d,
            centres,
            whitened,
            ln_weights: reference.weights.iter().map(|w| w.ln()).collect(),
            cumulative,
            factor,
            ln_norm: -0.5 * d as f64 * (2.0 * std::f64::consts::PI).ln() - ln_det,
            ln_volume: (0..d).map(|j| (f64::from(upper[j]) - f64::from(lower[j])).ln()).sum(),
        }
    }

    /// A draw from the kernels (not the box): a centre by its weight, plus its kernel's noise.
    pub(crate) fn draw(&self, stream: &mut Stream, out: &mut [f32]) {
        let total = self.cumulative.last().copied().unwrap_or(1.0);
        let u = stream.uniform() * total;
        let i = self.cumulative.partition_point(|&c| c <= u).min(self.centres.len() - 1);
        let mut z = [0.0f64; MAX_PARAMS];
        stream.normals(self.dims, &mut z);
        for (j, (v, c)) in out.iter_mut().zip(&self.centres[i]).take(self.dims).enumerate() {
            let step: f64 = (0..=j).map(|k| self.factor[(j, k)] * z[k]).sum();
            *v = (c + step) as f32;
        }
    }

    /// ln q(θ) of the mixture (1 − s)·Σ w_i·N(c_i, h²Σ) + s·U(box), `inside` whether θ is in
    /// the box.
    pub(crate) fn ln_q(&self, theta: &[f32], inside: bool) -> f64 {
        let d = self.dims;
        let mut x = [0.0f64; MAX_PARAMS];
        for (x, &t) in x.iter_mut().zip(&theta[..d]) {
            *x = f64::from(t);
        }
        let v = whiten(&self.factor, &x[..d]);
        // Each kernel's exponent once, into this thread's buffer (nothing allocated per
        // candidate: this runs for every candidate of a warm start).
        let (max, sum) = EXPONENTS.with_borrow_mut(|exponents| {
            exponents.clear();
            exponents.extend(self.whitened.iter().zip(&self.ln_weights).map(|(u, lw)| {
                let squared: f64 = (0..d).map(|j| (v[j] - u[j]).powi(2)).sum();
                lw - 0.5 * squared
            }));
            let max = exponents.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            // Kernels more than NEGLIGIBLE_NATS below the nearest add less than an ulp of the
            // sum (which the nearest's 1 starts): their exponentials, most of the cost, are
            // skipped.
            let sum: f64 = exponents
                .iter()
                .filter(|&&e| e - max > -NEGLIGIBLE_NATS)
                .map(|&e| (e - max).exp())
                .sum();
            (max, sum)
        });
        let kernels = (1.0 - DEFENSIVE_SHARE).ln() + self.ln_norm + max + sum.ln();
        if inside {
            let uniform = DEFENSIVE_SHARE.ln() - self.ln_volume;
            let m = kernels.max(uniform);
            m + ((kernels - m).exp() + (uniform - m).exp()).ln()
        } else {
            kernels
        }
    }
}

thread_local! {
    /// The kernels' exponents of the candidate [`Kernels::ln_q`] is at, per thread.
    static EXPONENTS: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// How far below the largest a kernel's log-density term may lie and still be added: e^−50
/// ≈ 2·10⁻²², so even 400 such terms move the sum (at least 1) by less than an ulp.
pub(super) const NEGLIGIBLE_NATS: f64 = 50.0;

/// L⁻¹·x for the lower-triangular `factor` L (forward substitution), on the stack: nalgebra's
/// `solve_lower_triangular` allocates, and this runs for every candidate of a warm start.
pub(super) fn whiten(factor: &DMatrix<f64>, x: &[f64]) -> [f64; MAX_PARAMS] {
    let mut z = [0.0; MAX_PARAMS];
    for j in 0..x.len() {
        let known: f64 = (0..j).map(|k| factor[(j, k)] * z[k]).sum();
        z[j] = (x[j] - known) / factor[(j, j)];
    }
    z
}
