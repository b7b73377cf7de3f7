//! What the samplers found: each law's evidence, the posterior law probabilities, and the
//! Bayes factors with their strength split into the data's part and the boxes'.

use super::*;

/// The evidence of one law.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LawEvidence {
    pub law: Law,
    /// ln Z, the log marginal likelihood with torques in N·m (see the module documentation).
    pub ln_z: f64,
    /// Its Monte-Carlo standard error (from the islands' spread: the standard error of the
    /// mean of their Z, or of their ln Z where that is larger).
    pub ln_z_error: f64,
    /// Each island's own ln Z.
    pub island_ln_z: Vec<f64>,
    /// Largest difference between two islands' ln Z, nats. Above [`ISLANDS_AGREE_NATS`] the
    /// samplers have not converged on this law: its ln Z is uncertain by about this much.
    #[serde(default)]
    pub island_spread: f64,
    /// The law's prior probability π(m).
    pub prior_probability: f64,
    /// P(m | y) ∝ π(m)·Z_m over the laws compared.
    pub probability: f64,
    /// Its standard error, carried from every law's `ln_z_error` (islands still apart after
    /// their refinements among them).
    #[serde(default)]
    pub probability_error: f64,
    /// Rounds of refinement its reported islands went through ([`REFINE_ABOVE_NATS`]): each
    /// doubled their particles.
    #[serde(default)]
    pub refinements: usize,
    /// Tempering steps of each island.
    pub stages: Vec<usize>,
    /// Candidates scored for this law.
    pub candidates_scored: u64,
    /// The lowest ρ any candidate of the law reached.
    pub best_rho: f64,
    /// Posterior parameter sets (SI), pooled over the islands; each island's sets weighed by its
    /// share of Z. Weights sum to 1.
    pub posterior: Vec<(Vec<f64>, f64)>,
    /// The island each of `posterior`'s sets comes from (an index into `island_ln_z`): the
    /// islands are independent samplers of one target, so that, as chains, they say whether
    /// they agree (R-hat) and how many independent draws they hold. Empty in documents
    /// written without it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub posterior_island: Vec<u32>,
    /// The parameters whose posterior reaches an end of its box that is not a physical bound
    /// ("a1 upper"): there the box, not the data, ends the posterior, and ln Z depends on
    /// where the box was drawn by more than the Occam factor of [`LN_Z_PER_DOUBLING`].
    #[serde(default)]
    pub cut_by_box: Vec<String>,
    /// Each start's estimate where the law's samplers started from both ([`Start::Both`]);
    /// empty otherwise. The islands and the posterior are those kept; `ln_z` and its error
    /// the kept start's, or both's weighed by their inverse variances.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub starts: Vec<StartEstimate>,
    /// ⟨ln L⟩, the log-likelihood's mean over the posterior (N·m, the constant of `ln_z`): what
    /// the record says of the law. `ln_z − mean_ln_l` = −KL(posterior ‖ prior) is the law's
    /// Occam factor, what its boxes say ([`BayesFactor`]). `None` in documents written without it.
    #[serde(default)]
    pub mean_ln_l: Option<f64>,
    /// Each parameter's box widened and narrowed, one at a time, and ln Z's change
    /// ([`sensitivity`]); empty in documents written without them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub box_changes: Vec<BoxChange>,
    /// Where the law's prior is its box cut to curves within the record's torques: the limit,
    /// and the box's share that keeps it (ln Z is over that prior, normalised).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub curve: Option<CurveLimit>,
}

/// How much ln Z changes when every parameter's box of a law doubles in width, per parameter,
/// for a posterior that lies inside its boxes: −ln 2 (the prior density halves where the
/// likelihood is). A Bayes factor between laws of d_a and d_b parameters moves by
/// (d_b − d_a)·ln 2 per doubling: how much of it the choice of boxes sets. A prior cut to the
/// record's torques moves less ([`sensitivity::every_box_widened`]).
pub const LN_Z_PER_DOUBLING: f64 = -std::f64::consts::LN_2;

/// Islands whose ln Z differ by more than this many nats have not converged alike: the law's
/// posterior is harder than its islands' particles and sweeps can follow (a narrow curved
/// ridge, say), and every output says so. Four islands of a sampler with an error of one nat
/// span about two; five is what moves a Bayes factor from one verdict to another.
pub const ISLANDS_AGREE_NATS: f64 = 5.0;

impl LawEvidence {
    /// A law's evidence of one island with `ln_z` (error 0.1), the weighted `posterior` and
    /// `mean_ln_l`: for tests of what is built on evidences (Bayes factors, box changes).
    #[cfg(test)]
    pub(crate) fn for_tests(law: Law, ln_z: f64, posterior: Vec<(Vec<f64>, f64)>, mean_ln_l: Option<f64>) -> Self {
        Self {
            curve: None,
            law,
            ln_z,
            ln_z_error: 0.1,
            island_ln_z: vec![ln_z],
            island_spread: 0.0,
            prior_probability: 0.5,
            probability: 0.5,
            probability_error: 0.0,
            refinements: 0,
            stages: vec![1],
            candidates_scored: 1,
            best_rho: 0.1,
            posterior_island: Vec::new(),
            posterior,
            cut_by_box: Vec::new(),
            starts: Vec::new(),
            mean_ln_l,
            box_changes: Vec::new(),
        }
    }

    /// True when the law's islands agree within [`ISLANDS_AGREE_NATS`].
    pub fn converged(&self) -> bool {
        self.island_spread <= ISLANDS_AGREE_NATS
    }
}

/// Share of a box's width at each end within which posterior mass counts as reaching the end.
pub(crate) const EDGE_SHARE: f64 = 0.02;
/// Posterior mass within [`EDGE_SHARE`] of an end that makes the box cut the posterior.
pub(crate) const EDGE_MASS: f64 = 0.01;

/// The ends of `law`'s box (`lower`, `upper`, SI) that cut the `posterior`: those, other than
/// a physical bound, with more than [`EDGE_MASS`] of the weight within [`EDGE_SHARE`] of the
/// box's width.
pub(super) fn box_ends_reached(law: Law, lower: &[f32], upper: &[f32], posterior: &[(Vec<f64>, f64)]) -> Vec<String> {
    let mut reached = Vec::new();
    for (j, spec) in law.params().iter().enumerate() {
        let (a, b) = (f64::from(lower[j]), f64::from(upper[j]));
        let margin = EDGE_SHARE * (b - a);
        let mass =
            |near: &dyn Fn(f64) -> bool| -> f64 { posterior.iter().filter(|(p, _)| near(p[j])).map(|(_, w)| w).sum() };
        if a > spec.lower && mass(&|v| v <= a + margin) > EDGE_MASS {
            reached.push(format!("{} lower", spec.name));
        }
        if b < spec.upper && mass(&|v| v >= b - margin) > EDGE_MASS {
            reached.push(format!("{} upper", spec.name));
        }
    }
    reached
}

/// The evidence of every law of a prior.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Evidence {
    pub laws: Vec<LawEvidence>,
    /// Data points n of the likelihood.
    pub data_points: usize,
    pub config: EvidenceConfig,
    /// Candidates scored in all.
    pub candidates_scored: u64,
    /// candidates_scored × data points.
    pub evaluations: u64,
    pub seconds: f64,
    /// The evaluator's backend (`cpu`, `gpu`).
    pub backend: String,
}

impl Evidence {
    /// The evidence of `law`, if it was compared.
    pub fn of(&self, law: Law) -> Option<&LawEvidence> {
        self.laws.iter().find(|l| l.law == law)
    }

    /// The posterior over laws and parameters as weighted particles (SI): each law's sets
    /// weighed by its P(m | y), so that the weights sum to 1 and a law's share is its
    /// probability; laws of probability 0 are left out. `index` counts within the law, and
    /// `rho` is not kept (NaN).
    pub fn particles(&self) -> Vec<crate::abc::Particle> {
        self.laws
            .iter()
            .filter(|law| law.probability > 0.0)
            .flat_map(|law| {
                law.posterior
                    .iter()
                    .enumerate()
                    .map(|(i, (params, w))| crate::abc::Particle {
                        law: law.law,
                        index: i as u64,
                        params: params.clone(),
                        rho: f64::NAN,
                        weight: law.probability * w,
                    })
            })
            .collect()
    }

    /// ln p(y) = ln Σ_m π(m)·Z_m over the laws compared (the evidence of the noise model and
    /// prior as a whole), and its Monte-Carlo error: each law's error weighed by its P(m | y),
    /// the laws' islands being independent.
    pub fn ln_evidence(&self) -> (f64, f64) {
        let joint: Vec<f64> = self.laws.iter().map(|l| l.prior_probability.ln() + l.ln_z).collect();
        let ln_evidence = log_mean_exp(joint.iter().copied()) + (joint.len() as f64).ln();
        let error = self
            .laws
            .iter()
            .map(|l| (l.probability * l.ln_z_error).powi(2))
            .sum::<f64>()
            .sqrt();
        (ln_evidence, error)
    }

    /// ln of the Bayes factor Z_a / Z_b and its Monte-Carlo error (the islands of different
    /// laws are independent).
    pub fn ln_bayes_factor(&self, a: Law, b: Law) -> Option<(f64, f64)> {
        let (a, b) = (self.of(a)?, self.of(b)?);
        Some(ln_bayes_factor((a.ln_z, a.ln_z_error), (b.ln_z, b.ln_z_error)))
    }

    /// The Bayes factors of the law of the largest evidence against each other law, largest
    /// evidence first, split into the data's and the boxes' parts ([`BayesFactor`]).
    pub fn bayes_factors(&self, separations: &[crate::separation::Separation]) -> Vec<BayesFactor> {
        let mut order: Vec<&LawEvidence> = self.laws.iter().collect();
        order.sort_by(|a, b| b.ln_z.total_cmp(&a.ln_z));
        let Some((best, rest)) = order.split_first() else {
            return Vec::new();
        };
        rest.iter()
            .map(|other| BayesFactor::between(best, other, separations))
            .collect()
    }
}

/// ln of the Bayes factor Z_a / Z_b from each law's (ln Z, Monte-Carlo error), and its error
/// (the islands of different laws are independent).
pub fn ln_bayes_factor(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (a.0 - b.0, a.1.hypot(b.1))
}

/// Below this many nats of ⟨ln L⟩ between two laws the record prefers neither: a Bayes factor
/// beyond it is made by the laws' Occam factors, which their boxes set (Kass & Raftery's
/// threshold of a preference worth stating).
pub const DATA_DECIDES_NATS: f64 = 1.0;

/// How strongly the record favours one law over another ([`Strength::of`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Strength {
    /// Below 1 nat, or within twice its error of 0: neither data nor boxes decide.
    Undecided,
    /// A Bayes factor the boxes make: the record's own part is below [`DATA_DECIDES_NATS`] or
    /// points the other way, or its fits do not separate the pair.
    DecidedByTheBoxes,
    Positive,
    Strong,
    VeryStrong,
}

impl Strength {
    /// How strongly a log Bayes factor `ln_b` = ln Z_a − ln Z_b (Monte-Carlo error `error`)
    /// favours its law, given the record's part of it, `data_nats` = ⟨ln L⟩_a − ⟨ln L⟩_b, and
    /// the fits' gap `separation_nats` (the expected D with the favoured law as the truth,
    /// [`crate::separation`], or the fits' own log-likelihood gap), either unknown as `None`. Kass & Raftery's (1995) words, positive
    /// from 1 nat, strong from 3, very strong from 5, on the smaller of |ln B| and the data's
    /// part: boxes twice as wide move ln B by ln 2 per parameter, and a word must not change
    /// with them.
    pub fn of(ln_b: f64, error: f64, data_nats: Option<f64>, separation_nats: Option<f64>) -> Self {
        let b = ln_b.abs();
        if b.is_nan() || b < 1.0 || b < 2.0 * error {
            return Self::Undecided;
        }
        // The data's part in the favoured law's direction.
        let data = data_nats.map(|d| d * ln_b.signum());
        // A NaN part (a fit with no value) decides nothing.
        let below = |x: f64, threshold: f64| x.is_nan() || x < threshold;
        let boxes_decide = data.is_some_and(|d| below(d, DATA_DECIDES_NATS))
            || separation_nats.is_some_and(|g| below(g, crate::separation::UNDECIDED_NATS));
        if boxes_decide {
            return Self::DecidedByTheBoxes;
        }
        match b.min(data.unwrap_or(f64::INFINITY)) {
            x if x < 3.0 => Self::Positive,
            x if x < 5.0 => Self::Strong,
            _ => Self::VeryStrong,
        }
    }

    /// True where the record, not the boxes, puts the favoured law ahead.
    pub fn decides(self) -> bool {
        matches!(self, Self::Positive | Self::Strong | Self::VeryStrong)
    }

    pub fn words(self) -> &'static str {
        match self {
            Self::Undecided => "undecided",
            Self::DecidedByTheBoxes => "decided by the boxes",
            Self::Positive => "positive",
            Self::Strong => "strong",
            Self::VeryStrong => "very strong",
        }
    }
}

impl std::fmt::Display for Strength {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.words())
    }
}

/// A Bayes factor split into what the record says and what the boxes say. With
/// ln Z = ⟨ln L⟩_posterior − KL(posterior ‖ prior),
///
/// ```text
/// ln B = (⟨ln L⟩_a − ⟨ln L⟩_b)  +  (KL_b − KL_a)
///         the data's part          the boxes' part (Occam factors)
/// ```
///
/// The data's part is how much better law a's plausible curves follow the record than law
/// b's; the boxes' part is how much less of its box law a's posterior leaves out, which grows
/// by ln 2 per parameter each time its boxes double (less for a prior cut to the record's
/// torques).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BayesFactor {
    /// The law of the larger evidence.
    pub favoured: Law,
    pub against: Law,
    /// ln(Z_favoured / Z_against) ≥ 0, and its Monte-Carlo error.
    pub ln_b: f64,
    pub error: f64,
    /// ⟨ln L⟩_favoured − ⟨ln L⟩_against, nats: the record's part of ln B.
    pub data_nats: Option<f64>,
    /// ln B less the data's part: the Occam factors' part, which the boxes set.
    pub boxes_nats: Option<f64>,
    /// The fits' expected gap D with the favoured law as the truth, where it was computed.
    pub separation_nats: Option<f64>,
    pub strength: Strength,
    /// ln B over either law's boxes widened or narrowed one parameter at a time, where the
    /// evidence kept its box changes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity: Option<Sensitivity>,
}

impl BayesFactor {
    /// The Bayes factor between `a` and `b`, the larger evidence favoured, with the pair's
    /// expected gap from `separations` where they hold it.
    pub fn between(a: &LawEvidence, b: &LawEvidence, separations: &[crate::separation::Separation]) -> Self {
        let (favoured, against) = if a.ln_z >= b.ln_z { (a, b) } else { (b, a) };
        let (ln_b, error) = ln_bayes_factor((favoured.ln_z, favoured.ln_z_error), (against.ln_z, against.ln_z_error));
        let data_nats = favoured.mean_ln_l.zip(against.mean_ln_l).map(|(x, y)| x - y);
        let separation_nats = separations
            .iter()
            .find(|s| s.truth == favoured.law && s.rival == against.law)
            .map(|s| s.gap_nats);
        Self {
            favoured: favoured.law,
            against: against.law,
            ln_b,
            error,
            data_nats,
            boxes_nats: data_nats.map(|d| ln_b - d),
            separation_nats,
            strength: Strength::of(ln_b, error, data_nats, separation_nats),
            sensitivity: Sensitivity::of(favoured, against, ln_b, error),
        }
    }

    /// "data 0.4, boxes 3.6 nats; fits' gap 5.0 nats": the parts known, for a table or a line.
    pub fn parts(&self) -> String {
        let mut parts = Vec::new();
        if let (Some(d), Some(b)) = (self.data_nats, self.boxes_nats) {
            parts.push(format!("data {d:.2}, boxes {b:.2} nats"));
        }
        if let Some(g) = self.separation_nats {
            parts.push(format!("fits' gap {g:.1} nats"));
        }
        parts.join("; ")
    }
}
