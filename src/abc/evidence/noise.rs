//! The noise models of the evidence: how the residuals e = y − r·T(w; θ) of a record are
//! distributed, and the log-likelihood of a candidate from the sums the evaluators return.
//!
//! Both models are Gaussian with an unknown scale σ that a Jeffreys prior p(σ) ∝ 1/σ
//! integrates out, so both share the constant [`log_likelihood_constant`] and their evidences
//! compare directly:
//!
//! - **i.i.d.**: p(y | θ) = ½ Γ(n/2) (π S)^(−n/2), S = Σ e².
//! - **AR(1)**: e_t = φ e_(t−1) + u_t, u_t i.i.d., stationary (|φ| < 1), φ uniform on (−1, 1)
//!   and integrated out. With Q(φ) = (1 − φ²) e_0² + Σ_(t≥1) (e_t − φ e_(t−1))²
//!   = S + φ² (S − e_0² − e_(n−1)²) − 2φ L, L = Σ e_t e_(t−1), the exact likelihood is
//!   p(y | θ) = ∫ ½ (1 − φ²)^½ · ½ Γ(n/2) (π Q(φ))^(−n/2) dφ.
//!
//!   Residuals that follow slow changes the law does not describe (a fluctuating weight on
//!   bit, drift, a filtered sensor) are correlated from one sample to the next; the i.i.d.
//!   model then counts each sample as independent information and overstates every Bayes
//!   factor by about (1 + φ)/(1 − φ). The AR(1) model pays for its φ with an Occam factor of
//!   about ½·√(π/(n/2)) (4 nats at n = 2,400) where the residuals are independent.
//!
//! The kernels return S and L per candidate (the lag pass, [`crate::eval::Evaluator::score_params_lagged`]);
//! the two end residuals e_0, e_(n−1) are computed here, on the host, in f64.

use serde::{Deserialize, Serialize};

/// How the residuals of a record are modelled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum NoiseModel {
    /// Independent Gaussian residuals of one unknown σ.
    #[default]
    Iid,
    /// First-order autoregressive Gaussian residuals, φ uniform on (−1, 1) integrated out.
    Ar1,
}

impl NoiseModel {
    /// Every noise model, in the order the evidence compares them.
    pub const ALL: [NoiseModel; 2] = [NoiseModel::Iid, NoiseModel::Ar1];

    /// The model's name in tables and JSON (`iid`, `ar1`).
    pub fn name(self) -> &'static str {
        match self {
            NoiseModel::Iid => "iid",
            NoiseModel::Ar1 => "ar1",
        }
    }

    /// The model in a few words ("i.i.d. Gaussian residuals").
    pub fn label(self) -> &'static str {
        match self {
            NoiseModel::Iid => "i.i.d. Gaussian residuals",
            NoiseModel::Ar1 => "AR(1) Gaussian residuals",
        }
    }

    /// A sentence describing the model, for tables and reports.
    pub fn describe(self) -> &'static str {
        match self {
            NoiseModel::Iid => "i.i.d. Gaussian residuals, σ integrated out (Jeffreys)",
            NoiseModel::Ar1 => "AR(1) Gaussian residuals, σ (Jeffreys) and φ (uniform on (−1, 1)) integrated out",
        }
    }
}

impl std::fmt::Display for NoiseModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What the record says about a model of its residuals (a noise model, the torque scaled by
/// the weight on bit or not): ln p(y | model) = ln Σ_m π(m)·Z_m over the laws compared, with its
/// Monte-Carlo error, and the model's posterior probability among those compared (equal prior
/// odds).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseEvidence {
    pub model: NoiseModel,
    /// W_ref, kN, where each predicted torque was scaled by WOB / W_ref; `None`: not scaled.
    pub w_ref_kn: Option<f64>,
    pub ln_evidence: f64,
    pub ln_evidence_error: f64,
    pub probability: f64,
    /// The law the model's evidence puts first, and its P(m | y) under the model.
    pub first_law: crate::laws::Law,
    pub first_probability: f64,
    /// What its samplers cost: candidates scored and seconds.
    pub candidates_scored: u64,
    pub seconds: f64,
}

impl NoiseEvidence {
    /// One row per evidence, each computed under its own noise model and torque scaling (W_ref
    /// in N, or `None`), with the models' posterior probabilities.
    pub fn compare(evidences: &[(&super::Evidence, Option<f64>)]) -> Vec<NoiseEvidence> {
        let mut rows: Vec<NoiseEvidence> = evidences
            .iter()
            .map(|&(e, w_ref_n)| {
                let (ln_evidence, ln_evidence_error) = e.ln_evidence();
                let first = e
                    .laws
                    .iter()
                    .max_by(|a, b| a.probability.total_cmp(&b.probability))
                    .expect("at least one law");
                NoiseEvidence {
                    model: e.config.noise,
                    w_ref_kn: w_ref_n.map(|w| w / 1000.0),
                    ln_evidence,
                    ln_evidence_error,
                    probability: 0.0,
                    first_law: first.law,
                    first_probability: first.probability,
                    candidates_scored: e.candidates_scored,
                    seconds: e.seconds,
                }
            })
            .collect();
        let best = rows.iter().map(|r| r.ln_evidence).fold(f64::NEG_INFINITY, f64::max);
        let total: f64 = rows.iter().map(|r| (r.ln_evidence - best).exp()).sum();
        for row in &mut rows {
            row.probability = (row.ln_evidence - best).exp() / total;
        }
        rows
    }
}

/// ln Γ(x) for x > 0: the Stirling series after shifting x to 15 or more (truncation error
/// below 1e-17; rounding of the shift's logarithms a few 1e-15).
pub(super) fn ln_gamma(mut x: f64) -> f64 {
    let mut shift = 0.0;
    while x < 15.0 {
        shift -= x.ln();
        x += 1.0;
    }
    let inv = 1.0 / x;
    let inv2 = inv * inv;
    let series =
        inv * (1.0 / 12.0 - inv2 * (1.0 / 360.0 - inv2 * (1.0 / 1260.0 - inv2 * (1.0 / 1680.0 - inv2 / 1188.0))));
    shift + (x - 0.5) * x.ln() - x + 0.5 * (2.0 * std::f64::consts::PI).ln() + series
}

/// The constant of ln p(y | θ) = constant + ℓ, shared by every noise model: ln(½ Γ(n/2)) −
/// (n/2)·ln(π·Σy²), Σy² in N·m². ℓ is [`iid_log_likelihood`] or [`ar1_log_likelihood`].
pub fn log_likelihood_constant(n: usize, sum_sq_torque: f64) -> f64 {
    let half_n = n as f64 / 2.0;
    ln_gamma(half_n) - std::f64::consts::LN_2 - half_n * (std::f64::consts::PI * sum_sq_torque).ln()
}

/// ℓ of the i.i.d. model: −(n/2)·ln ρ, ρ = S/Σy²; −∞ where ρ has no value.
pub fn iid_log_likelihood(rho: f64, half_n: f64) -> f64 {
    if rho.is_finite() {
        -half_n * rho.max(f64::MIN_POSITIVE).ln()
    } else {
        f64::NEG_INFINITY
    }
}

/// The sums of one candidate's residuals the AR(1) likelihood needs, each divided by Σy².
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagSums {
    /// ρ = Σ e² / Σy².
    pub rho: f64,
    /// λ = Σ_(t≥1) e_t·e_(t−1) / Σy².
    pub lag: f64,
    /// (e_0² + e_(n−1)²) / Σy².
    pub ends: f64,
}

impl LagSums {
    /// q(φ) = Q(φ)/Σy² (see the module documentation).
    fn q(&self, phi: f64) -> f64 {
        self.rho + phi * phi * (self.rho - self.ends) - 2.0 * phi * self.lag
    }
}

/// Largest |u| = |atanh φ| the quadrature reaches (φ within 3e-8 of ±1).
const U_LIMIT: f64 = 9.0;
/// The trapezoid rule's nodes lie half a standard deviation (of a Gaussian fitted at the
/// mode) apart, where its error for a Gaussian is below 1e-30, and reach each side until the
/// integrand lies this many nats below its peak...
const TAIL_NATS: f64 = 40.0;
/// ... or this many nodes were taken on that side.
const MAX_NODES: i32 = 4_000;

/// The integrand in u = atanh φ, log: ln ½ + (3/2)·ln(1 − φ²) − (n/2)·ln q(φ) (the prior ½,
/// the stationary start (1 − φ²)^½, the Jacobian 1 − φ²).
fn log_integrand(s: &LagSums, u: f64, half_n: f64) -> f64 {
    let phi = u.tanh();
    let sech2 = 1.0 / u.cosh().powi(2);
    let q = s.q(phi);
    if q > 0.0 && sech2 > 0.0 {
        -std::f64::consts::LN_2 + 1.5 * sech2.ln() - half_n * q.ln()
    } else {
        f64::NEG_INFINITY
    }
}

/// ℓ of the AR(1) model: ln ∫ ½ (1 − φ²)^½ q(φ)^(−n/2) dφ, by the trapezoid rule in
/// u = atanh φ around the integrand's mode (Newton's method from φ = λ/(ρ − ends)), on nodes
/// half its standard deviation apart out to where it is negligible; −∞ where ρ or λ has no
/// value.
pub fn ar1_log_likelihood(s: &LagSums, half_n: f64) -> f64 {
    if !(s.rho.is_finite() && s.lag.is_finite() && s.ends.is_finite()) {
        return f64::NEG_INFINITY;
    }
    // Derivatives of h(u) = log_integrand: with φ = tanh u, c = 1 − φ², q' = dq/dφ,
    // h' = −3φ − (n/2)·c·q'/q, h'' = −3c − (n/2)·[−2φ·c·q'/q + c²·(q''/q − (q'/q)²)].
    let derivatives = |u: f64| -> (f64, f64) {
        let phi = u.tanh();
        let c = 1.0 - phi * phi;
        let q = s.q(phi);
        let dq = 2.0 * phi * (s.rho - s.ends) - 2.0 * s.lag;
        let ddq = 2.0 * (s.rho - s.ends);
        let g = dq / q;
        let first = -3.0 * phi - half_n * c * g;
        let second = -3.0 * c - half_n * (-2.0 * phi * c * g + c * c * (ddq / q - g * g));
        (first, second)
    };
    let start = (s.lag / (s.rho - s.ends)).clamp(-0.999, 0.999);
    let mut u = if start.is_finite() { start.atanh() } else { 0.0 };
    for _ in 0..50 {
        let (first, second) = derivatives(u);
        // Newton where h is concave, else a step uphill; at most 1 in u at a time.
        let step = if second < 0.0 { -first / second } else { first.signum() };
        let next = (u + step.clamp(-1.0, 1.0)).clamp(-U_LIMIT, U_LIMIT);
        let done = (next - u).abs() < 1e-12;
        u = next;
        if done {
            break;
        }
    }
    let (_, second) = derivatives(u);
    let sd = if second < 0.0 { (-1.0 / second).sqrt() } else { 1.0 };
    let spacing = 0.5 * sd;
    let peak = log_integrand(s, u, half_n);
    if peak == f64::NEG_INFINITY {
        return f64::NEG_INFINITY;
    }
    // Nodes outwards from the mode until the integrand lies TAIL_NATS below it (a skewed or
    // heavy tail towards |φ| = 1 gets as many nodes as it needs) or u reaches its limit. The
    // nodes' buffer is the thread's own, kept between calls: this runs once per candidate.
    thread_local! {
        static NODES: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    NODES.with_borrow_mut(|values| {
        values.clear();
        values.push(peak);
        for direction in [-1.0, 1.0] {
            for k in 1..MAX_NODES {
                let v = u + direction * f64::from(k) * spacing;
                if v.abs() > U_LIMIT {
                    break;
                }
                let value = log_integrand(s, v, half_n);
                values.push(value);
                if value < peak - TAIL_NATS {
                    break;
                }
            }
        }
        let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        max + values.iter().map(|v| (v - max).exp()).sum::<f64>().ln() + spacing.ln()
    })
}

/// Nats by which the data must prefer AR(1) residuals to i.i.d. ones at every law's best fit
/// ([`ar1_preference_nats`]) for the i.i.d. model's evidence to be said to be misspecified: a
/// Bayes factor of e³ ≈ 20, "strong" on Kass and Raftery's scale.
pub const AR1_PREFERRED_NATS: f64 = 3.0;

/// ln p(y | AR(1)) − ln p(y | i.i.d.) of residuals `e` (time order) of a record whose torques'
/// squares sum to `sum_sq_torque` (N·m²): the log Bayes factor of the two noise models at the
/// parameters the residuals are of, with σ (and AR(1)'s φ) integrated out as the evidence
/// integrates them, so that φ pays its Occam factor: about −3 nats for independent noise of a
/// few thousand samples, about −(n/2)·ln(1 − φ̂²) for noise that lasts. NaN with fewer than
/// three residuals or no torque.
pub fn ar1_preference_nats(e: &[f64], sum_sq_torque: f64) -> f64 {
    use crate::numerics::compensated_sum;
    if e.len() < 3 || sum_sq_torque.is_nan() || sum_sq_torque <= 0.0 {
        return f64::NAN;
    }
    let sums = LagSums {
        rho: compensated_sum(e.iter().map(|v| v * v)) / sum_sq_torque,
        lag: compensated_sum(e.windows(2).map(|w| w[0] * w[1])) / sum_sq_torque,
        ends: (e[0] * e[0] + e[e.len() - 1] * e[e.len() - 1]) / sum_sq_torque,
    };
    let half_n = e.len() as f64 / 2.0;
    ar1_log_likelihood(&sums, half_n) - iid_log_likelihood(sums.rho, half_n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// AR(1) noise e_t = φ·e_{t−1} + η_t on an m2 record of 4,000 samples in time order: the
    /// data's preference for AR(1) residuals at the fit is negative for independent noise (φ's
    /// Occam factor, about ½·ln(2π/n) − ln 2 ≈ −4.6 nats, less what chance correlation buys
    /// back), and for lasting noise the profile likelihood ratio −(n/2)·ln(1 − φ̂²) within the
    /// same few nats; a record of too few residuals has none.
    #[test]
    fn the_data_prefer_ar1_residuals_by_their_profile_likelihood_less_phi_s_occam_factor() {
        use crate::data::Samples;
        use crate::fit::{FitOptions, fit_laws};
        use crate::laws::Law;
        let n = 4000;
        let opts = FitOptions::default();
        for phi in [0.0, 0.2, 0.5] {
            let data = crate::separation::ar1_m2_record(phi);
            let fit = &fit_laws(&[Law::M2], &data, &Samples::default(), &opts).unwrap()[0];
            let e = crate::fit::residuals(fit.law, &fit.params_si, &data, opts.w_ref_n);
            let sum_sq: f64 = data.torque_nm.iter().map(|y| y * y).sum();
            let prefers = ar1_preference_nats(&e, sum_sq);
            let lag1 = crate::separation::lag1_of(&e);
            if phi == 0.0 {
                assert!(prefers < 0.0 && prefers > -6.0, "independent noise: {prefers}");
            } else {
                let profile = -(n as f64 / 2.0) * (1.0 - lag1 * lag1).ln();
                assert!(prefers > AR1_PREFERRED_NATS, "φ = {phi}: {prefers}");
                assert!((prefers - profile).abs() < 6.0, "φ = {phi}: {prefers} vs {profile}");
            }
            assert!(ar1_preference_nats(&e[..2], sum_sq).is_nan());
            assert!(ar1_preference_nats(&e, 0.0).is_nan());
        }
    }

    #[test]
    fn ln_gamma_matches_known_values() {
        // Γ(1) = Γ(2) = 1, Γ(1/2) = √π, Γ(10) = 9!, ln Γ(4500) from Python's math.lgamma.
        assert!(ln_gamma(1.0).abs() < 1e-13);
        assert!(ln_gamma(2.0).abs() < 1e-13);
        assert!((ln_gamma(0.5) - 0.5 * std::f64::consts::PI.ln()).abs() < 1e-13);
        assert!((ln_gamma(10.0) - 362_880f64.ln()).abs() < 1e-12);
        assert!(
            (ln_gamma(4500.0) - 33_349.960_081_626_69).abs() < 1e-8,
            "{}",
            ln_gamma(4500.0)
        );
    }

    /// ln ∫ ½ (1 − φ²)^½ q(φ)^(−n/2) dφ by the midpoint rule on 4 million cells of φ.
    fn brute_force(s: &LagSums, half_n: f64) -> f64 {
        let cells = 4_000_000;
        let h = 2.0 / cells as f64;
        let values: Vec<f64> = (0..cells)
            .map(|i| {
                let phi = -1.0 + (i as f64 + 0.5) * h;
                let q = s.q(phi);
                if q > 0.0 {
                    -std::f64::consts::LN_2 + 0.5 * (1.0 - phi * phi).ln() - half_n * q.ln()
                } else {
                    f64::NEG_INFINITY
                }
            })
            .collect();
        let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        max + values.iter().map(|v| (v - max).exp()).sum::<f64>().ln() + h.ln()
    }

    #[test]
    fn the_ar1_likelihood_is_the_integral_over_phi() {
        // Independent, strongly and nearly perfectly correlated, anticorrelated residuals; a
        // long record and a short one.
        let cases = [
            (
                1_200.0,
                LagSums {
                    rho: 0.01,
                    lag: 0.0,
                    ends: 1e-5,
                },
            ),
            (
                1_200.0,
                LagSums {
                    rho: 0.01,
                    lag: 0.007,
                    ends: 2e-5,
                },
            ),
            (
                1_200.0,
                LagSums {
                    rho: 0.01,
                    lag: 0.0097,
                    ends: 3e-6,
                },
            ),
            (
                25.0,
                LagSums {
                    rho: 0.2,
                    lag: -0.06,
                    ends: 0.02,
                },
            ),
            (
                3.0,
                LagSums {
                    rho: 0.5,
                    lag: 0.1,
                    ends: 0.1,
                },
            ),
        ];
        for (half_n, s) in cases {
            let (got, want) = (ar1_log_likelihood(&s, half_n), brute_force(&s, half_n));
            assert!((got - want).abs() < 1e-6, "n/2 = {half_n}, {s:?}: {got} against {want}");
        }
    }

    #[test]
    fn the_quadrature_holds_across_correlations_and_record_lengths() {
        // A fixed pseudo-random spread of (ρ, λ, ends, n): every φ from −1 to 1, records of 6
        // to 2,000 samples; the midpoint rule on 4 million cells as the reference.
        let mut state = 12_345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut worst: f64 = 0.0;
        for _ in 0..40 {
            let rho = 0.001 + next();
            let lag = rho * (2.0 * next() - 1.0) * next().sqrt();
            let ends = rho * 0.01 * next();
            let half_n = [3.0, 100.0, 1_000.0][(next() * 3.0) as usize];
            let s = LagSums { rho, lag, ends };
            worst = worst.max((ar1_log_likelihood(&s, half_n) - brute_force(&s, half_n)).abs());
        }
        assert!(worst < 1e-3, "{worst}");
    }

    #[test]
    fn independent_residuals_pay_the_occam_factor_of_phi() {
        // λ = 0 and no ends: ℓ_AR1 − ℓ_iid = ln ∫ ½ (1 − φ²)^½ (1 + φ²)^(−n/2) dφ, about
        // ln(½·√(π/(n/2))) for large n (φ's posterior width 1/√n against its prior's 2).
        let half_n = 1_200.0;
        let s = LagSums {
            rho: 0.01,
            lag: 0.0,
            ends: 0.0,
        };
        let gap = ar1_log_likelihood(&s, half_n) - iid_log_likelihood(s.rho, half_n);
        let laplace = (0.5 * (std::f64::consts::PI / half_n).sqrt()).ln();
        assert!((gap - laplace).abs() < 2e-3, "{gap} against {laplace}");
        assert!(gap < -3.5 && gap > -4.0, "{gap}");
    }

    #[test]
    fn a_candidate_without_a_value_has_no_likelihood() {
        let s = LagSums {
            rho: f64::INFINITY,
            lag: 0.0,
            ends: 0.0,
        };
        assert!(ar1_log_likelihood(&s, 10.0).is_infinite() && ar1_log_likelihood(&s, 10.0) < 0.0);
        assert!(iid_log_likelihood(f64::INFINITY, 10.0).is_infinite());
    }
}
