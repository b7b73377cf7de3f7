//! One answer to "which law, and how sure", whichever kind of run asked: the law ranked
//! first, the one after it, and a strength word never stronger than what the record separates.
//!
//! The model evidence gives a Bayes factor split into the record's part and the boxes'
//! ([`BayesFactor`]), and its word is the record's ([`Strength::of`]). The paper's ABC gives
//! model probabilities P(m | ρ < ε): shares of each law's prior box below the tolerance. They
//! weigh the record only where ε lies near its likelihood scale; far above it they are ratios
//! of prior volumes ([`crate::abc::prior_volume_caveat`]), and the priors, not the record,
//! decide. Either way a pair whose least-squares fits the record does not separate
//! ([`crate::separation::UNDECIDED_NATS`]) is left to the priors, whatever the numbers say.

use crate::abc::evidence::{BayesFactor, Evidence, Strength};
use crate::laws::Law;
use crate::separation::Separation;
use serde::{Deserialize, Serialize};
use std::fmt::Display;

/// Where an answer's numbers come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The model evidence: P(m | y) from each law's marginal likelihood.
    Evidence,
    /// The paper's ABC: P(m | ρ < ε), shares of each law's prior box below the tolerance.
    PaperAbc,
}

impl Method {
    /// What the probabilities are, in the user's words.
    pub fn label(self) -> &'static str {
        match self {
            Self::Evidence => "the model evidence, P(m | y)",
            Self::PaperAbc => "the paper's ABC, P(m | ρ < ε)",
        }
    }
}

/// The law ranked first, how far ahead of the next, and how sure that makes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Answer {
    pub method: Method,
    /// The law ranked first, and its probability.
    pub law: Law,
    pub probability: f64,
    /// The law ranked next and its probability; `None` where one law was compared.
    pub runner_up: Option<Law>,
    pub runner_up_probability: Option<f64>,
    /// ln of the Bayes factor of `law` over `runner_up` (for the paper's ABC, of its
    /// probabilities over the laws' prior weights), and its Monte-Carlo error.
    pub ln_b: Option<f64>,
    pub error: Option<f64>,
    pub strength: Strength,
    /// Why the strength is what it is, where that needs saying.
    pub why: Option<String>,
    /// What the evidence's check by re-simulation said of the pair, where one ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub check: Option<AnswerCheck>,
}

/// The evidence's check by re-simulation, read for an answer's pair: how many records made by
/// the answer's law it decided for that law, and how many made by the runner-up it decided
/// for the answer's law too.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AnswerCheck {
    /// Synthetic records per law.
    pub replicates: usize,
    /// Records made by the answer's law decided for it.
    pub decided_right: usize,
    /// Records made by the runner-up decided for the answer's law; `None` without a runner-up.
    pub runner_up_decided_for_law: Option<usize>,
}

impl Answer {
    /// The evidence's answer: its law of largest evidence against the next, in the words of
    /// their Bayes factor ([`Evidence::bayes_factors`]); `None` for an evidence of no law.
    pub fn of_evidence(evidence: &Evidence, separations: &[Separation]) -> Option<Self> {
        let probability = |law: Law| evidence.laws.iter().find(|l| l.law == law).map(|l| l.probability);
        let factors = evidence.bayes_factors(separations);
        let Some(next) = factors.first() else {
            let only = evidence.laws.first()?;
            return Some(Self::alone(Method::Evidence, only.law, only.probability));
        };
        Some(Self {
            method: Method::Evidence,
            law: next.favoured,
            probability: probability(next.favoured).unwrap_or(f64::NAN),
            runner_up: Some(next.against),
            runner_up_probability: probability(next.against),
            ln_b: Some(next.ln_b),
            error: Some(next.error),
            strength: next.strength,
            why: evidence_why(next),
            check: None,
        })
    }

    /// The paper's ABC's answer from the model probabilities of its summarised population
    /// (`probabilities`, in the laws' order, with their prior weights `prior_weights` and the
    /// population's effective sample size `ess`), the caveat its tolerance earns
    /// ([`crate::abc::prior_volume_caveat`]) and the fits' separations; `None` where no law
    /// holds a particle.
    pub fn of_abc(
        probabilities: &[(Law, f64)],
        prior_weights: &[f64],
        ess: f64,
        prior_volumes: bool,
        separations: &[Separation],
    ) -> Option<Self> {
        let weight = |law: Law| {
            probabilities
                .iter()
                .position(|(l, _)| *l == law)
                .and_then(|i| prior_weights.get(i).copied())
                .unwrap_or(1.0)
        };
        let mut order: Vec<(Law, f64)> = probabilities.to_vec();
        order.sort_by(|a, b| b.1.total_cmp(&a.1));
        let (law, p) = *order.first().filter(|(_, p)| *p > 0.0)?;
        let Some(&(next, q)) = order.get(1) else {
            return Some(Self::alone(Method::PaperAbc, law, p));
        };
        // A law with no particle has less than one particle's share: its probability is
        // bounded by 1/ESS, and so the factor from below.
        let ess = ess.max(1.0);
        let q_seen = q.max(1.0 / ess);
        let ln_b = (p / weight(law)).ln() - (q_seen / weight(next)).ln();
        // Multinomial shares: var(ln p − ln q) ≈ (1/p + 1/q) / ESS.
        let error = ((1.0 / p + 1.0 / q_seen) / ess).sqrt();
        let gap = gap_nats(separations, law, next);
        let (strength, why) = if prior_volumes {
            (
                Strength::DecidedByTheBoxes,
                Some(
                    "at this tolerance the probabilities are ratios of the laws' prior volumes below ε, not \
                     evidence (the run's warning); the model evidence weighs the record"
                        .to_string(),
                ),
            )
        } else {
            let strength = Strength::of(ln_b, error, None, gap);
            (strength, separation_why(strength, law, next, gap))
        };
        Some(Self {
            method: Method::PaperAbc,
            law,
            probability: p,
            runner_up: Some(next),
            runner_up_probability: Some(q),
            ln_b: Some(ln_b),
            error: Some(error),
            strength,
            why,
            check: None,
        })
    }

    /// An answer among one law: nothing was compared.
    fn alone(method: Method, law: Law, probability: f64) -> Self {
        Self {
            method,
            law,
            probability,
            runner_up: None,
            runner_up_probability: None,
            ln_b: None,
            error: None,
            strength: Strength::Undecided,
            why: Some("one law was compared: nothing was selected".into()),
            check: None,
        }
    }

    /// The answer weighed by the evidence's `check`: where it decided fewer than half the
    /// records made by the answer's law for it, or half or more of the runner-up's for the
    /// answer's law too, records like this one do not settle the question, and a decided
    /// answer becomes undecided.
    pub fn checked(mut self, check: AnswerCheck) -> Self {
        let k = check.replicates;
        let misses_own = 2 * check.decided_right < k;
        let takes_rival = check.runner_up_decided_for_law.is_some_and(|n| 2 * n >= k);
        if self.strength.decides() && (misses_own || takes_rival) {
            self.strength = Strength::Undecided;
            self.why = Some("the check by re-simulation does not decide records like this one".into());
        }
        self.check = Some(check);
        self
    }

    /// The answer as documents keep it: its fields, and its `sentence` for people.
    pub fn json(&self) -> serde_json::Value {
        let mut document = serde_json::to_value(self).expect("an answer serialises");
        document["sentence"] = self.sentence().into();
        document
    }

    /// Serialises an optional answer as [`json`](Self::json) does, its `sentence` beside its
    /// fields (for `#[serde(serialize_with)]`; reading it back ignores the sentence).
    pub fn serialize_with_sentence<S: serde::Serializer>(answer: &Option<Self>, to: S) -> Result<S::Ok, S::Error> {
        use serde::Serialize;
        answer.as_ref().map(Self::json).serialize(to)
    }

    /// The answer in a few words: the law, and its strength against the next.
    pub fn headline(&self) -> String {
        match self.runner_up {
            Some(next) => format!("{} over {}: {}", self.law, next, self.strength.words()),
            None => format!("{} alone", self.law),
        }
    }

    /// The headline: the law, its strength against the next, the numbers, and why.
    pub fn sentence(&self) -> String {
        let Some(next) = self.runner_up else {
            return format!(
                "{} ({}), {}",
                self.law,
                self.method.label(),
                self.why.as_deref().unwrap_or("")
            );
        };
        let odds = match (self.ln_b, self.error) {
            (Some(ln_b), Some(error)) => format!(", ln B = {ln_b:.2} ± {error:.2}"),
            _ => String::new(),
        };
        let mut line = format!(
            "{} over {}: {} ({}: {:.3} against {:.3}{odds})",
            self.law,
            next,
            self.strength.words(),
            self.method.label(),
            self.probability,
            self.runner_up_probability.unwrap_or(f64::NAN),
        );
        if let Some(why) = &self.why {
            line.push_str("; ");
            line.push_str(why);
        }
        if let Some(check) = &self.check {
            let k = check.replicates;
            line.push_str(&format!(
                "; the check decided {} of {k} records made by {} for it",
                check.decided_right, self.law
            ));
            if let Some(n) = check.runner_up_decided_for_law {
                line.push_str(&format!(" and {n} of {k} made by {next} for {}", self.law));
            }
        }
        line
    }
}

/// The fits' expected gap with `truth` as fitted making the record and `rival` fitting it.
fn gap_nats(separations: &[Separation], truth: Law, rival: Law) -> Option<f64> {
    separations
        .iter()
        .find(|s| s.truth == truth && s.rival == rival)
        .map(|s| s.gap_nats)
}

/// Why a pair the fits do not separate is left to the priors.
fn separation_why(strength: Strength, law: Law, next: Law, gap: Option<f64>) -> Option<String> {
    match (strength, gap) {
        (Strength::DecidedByTheBoxes, Some(gap)) if gap < crate::separation::UNDECIDED_NATS => Some(format!(
            "the record does not separate {law} from {next} (the fits' gap {gap:.1} nats, below {}): the priors decide",
            crate::separation::UNDECIDED_NATS
        )),
        _ => None,
    }
}

/// Why the evidence's word is what it is, where the boxes, not the record, made it.
fn evidence_why(factor: &BayesFactor) -> Option<String> {
    if factor.strength != Strength::DecidedByTheBoxes {
        return None;
    }
    separation_why(factor.strength, factor.favoured, factor.against, factor.separation_nats).or_else(|| {
        factor.data_nats.map(|d| {
            format!(
                "the record's part of ln B is {d:.2} nats (below {}): the boxes' Occam factors make it",
                crate::abc::evidence::DATA_DECIDES_NATS
            )
        })
    })
}

/// A model choice checked by re-simulation: `best` (a law, or a structure: its `kind`) with
/// probability `probability` is called where at least [`CHECK_RECOGNISED`] of the records
/// re-simulated from it are recognised as it (`recognised`) and no other model's are taken for
/// it more often than [`CHECK_CONFUSED`] (those that are: `confused`); undecided otherwise,
/// saying why.
pub fn resimulation_verdict<L: Copy + Display>(
    best: L,
    probability: f64,
    recognised: f64,
    confused: &[L],
    kind: &str,
) -> (Option<L>, String) {
    if recognised < CHECK_RECOGNISED {
        return (
            None,
            format!(
                "{best} leads (P = {probability:.2}), but only {:.0} % of the records re-simulated from it are recognised as it: the summaries do not tell it apart; undecided",
                100.0 * recognised
            ),
        );
    }
    if !confused.is_empty() {
        let names: Vec<String> = confused.iter().map(|l| l.to_string()).collect();
        let names = names.join(", ");
        return (
            None,
            format!(
                "{best} leads (P = {probability:.2}), but records re-simulated from {names} are taken for it too: undecided between {best} and {names}"
            ),
        );
    }
    (
        Some(best),
        format!(
            "{best} (P = {probability:.2}); {:.0} % of the records re-simulated from it are recognised as it, and no other {kind}'s are taken for it",
            100.0 * recognised
        ),
    )
}

/// A model is called when its own re-simulations are recognised at least this often and no
/// other model's (any with particles, however improbable: the probabilities are what the check
/// checks) are taken for it more often than [`CHECK_CONFUSED`].
pub const CHECK_RECOGNISED: f64 = 0.8;
/// See [`CHECK_RECOGNISED`].
pub const CHECK_CONFUSED: f64 = 0.2;

#[cfg(test)]
mod tests {
    use super::*;

    fn separation(truth: Law, rival: Law, gap_nats: f64) -> Separation {
        Separation {
            truth,
            rival,
            gap_nats,
            misranking: 0.5,
            bands: Vec::new(),
            parts_below_rad_s: None,
            parts_above_rad_s: None,
        }
    }

    #[test]
    fn the_paper_s_abc_far_above_the_likelihood_scale_is_decided_by_the_priors() {
        let p = [(Law::M1, 0.29), (Law::M2, 0.29), (Law::M3, 0.37), (Law::M4, 0.05)];
        let a = Answer::of_abc(&p, &[1.0; 4], 25_000.0, true, &[]).unwrap();
        assert_eq!(
            (a.method, a.law, a.runner_up),
            (Method::PaperAbc, Law::M3, Some(Law::M1))
        );
        assert_eq!(a.strength, Strength::DecidedByTheBoxes);
        assert!(
            a.sentence()
                .starts_with("m3 over m1: decided by the boxes (the paper's ABC, P(m | ρ < ε): 0.370 against 0.290")
        );
        assert!(a.sentence().contains("ratios of the laws' prior volumes"));
    }

    #[test]
    fn the_paper_s_abc_near_the_likelihood_scale_is_worded_by_its_odds_and_the_fits_gap() {
        // ln(0.9/0.1) = 2.197 on 10,000 particles: positive; error √((1/0.9 + 1/0.1)/1e4).
        let p = [(Law::M2, 0.9), (Law::M3, 0.1)];
        let a = Answer::of_abc(&p, &[1.0, 1.0], 1e4, false, &[separation(Law::M2, Law::M3, 40.0)]).unwrap();
        assert_eq!(a.strength, Strength::Positive);
        assert!((a.ln_b.unwrap() - 9f64.ln()).abs() < 1e-12);
        assert!((a.error.unwrap() - ((1.0 / 0.9 + 10.0) / 1e4f64).sqrt()).abs() < 1e-15);
        assert_eq!(a.why, None);
        // Unequal prior weights: the odds are the data's, the weights divided out.
        let a = Answer::of_abc(&p, &[3.0, 1.0], 1e4, false, &[]).unwrap();
        assert!((a.ln_b.unwrap() - 3f64.ln()).abs() < 1e-12);
        // A pair the fits do not separate: the priors decide, whatever the odds.
        let a = Answer::of_abc(&p, &[1.0, 1.0], 1e4, false, &[separation(Law::M2, Law::M3, 0.4)]).unwrap();
        assert_eq!(a.strength, Strength::DecidedByTheBoxes);
        assert!(
            a.why
                .unwrap()
                .contains("does not separate m2 from m3 (the fits' gap 0.4 nats")
        );
        // A runner-up with no particle: its share is below 1/ESS, so ln B is at least this.
        let a = Answer::of_abc(&[(Law::M2, 1.0), (Law::M3, 0.0)], &[1.0, 1.0], 100.0, false, &[]).unwrap();
        assert!((a.ln_b.unwrap() - 100f64.ln()).abs() < 1e-12);
        assert_eq!(a.strength, Strength::Strong);
        // No particle at all, or one law: nothing selected.
        assert!(Answer::of_abc(&[(Law::M2, 0.0), (Law::M3, 0.0)], &[1.0, 1.0], 0.0, false, &[]).is_none());
        let one = Answer::of_abc(&[(Law::M2, 1.0)], &[1.0], 10.0, false, &[]).unwrap();
        assert_eq!((one.runner_up, one.strength), (None, Strength::Undecided));
    }

    #[test]
    fn the_evidence_s_word_says_whether_the_fits_or_the_data_s_part_left_it_to_the_boxes() {
        use crate::abc::evidence::LawEvidence;
        let (m2, m4) = (
            LawEvidence::for_tests(Law::M2, -100.0, Vec::new(), Some(-90.0)),
            LawEvidence::for_tests(Law::M4, -104.0, Vec::new(), Some(-86.5)),
        );
        // The data's part points to m4 (−3.5 nats), the fits separate the pair well.
        let factor = BayesFactor::between(&m2, &m4, &[separation(Law::M2, Law::M4, 30.0)]);
        assert_eq!(factor.strength, Strength::DecidedByTheBoxes);
        let why = evidence_why(&factor).unwrap();
        assert_eq!(
            why,
            "the record's part of ln B is -3.50 nats (below 1): the boxes' Occam factors make it"
        );
        // Fits the record does not separate: that is said first.
        let factor = BayesFactor::between(&m2, &m4, &[separation(Law::M2, Law::M4, 0.9)]);
        assert!(
            evidence_why(&factor)
                .unwrap()
                .starts_with("the record does not separate m2 from m4")
        );
        // A word the data make needs no why.
        let m1 = LawEvidence::for_tests(Law::M1, -130.0, Vec::new(), Some(-120.0));
        let factor = BayesFactor::between(&m2, &m1, &[]);
        assert_eq!((factor.strength, evidence_why(&factor)), (Strength::VeryStrong, None));
    }

    #[test]
    fn a_check_that_does_not_tell_the_pair_s_records_apart_takes_the_word_back() {
        let p = [(Law::M2, 0.999), (Law::M3, 0.001)];
        let a = Answer::of_abc(&p, &[1.0, 1.0], 1e5, false, &[]).unwrap();
        assert!(a.strength.decides());
        let check = |decided_right, rival| AnswerCheck {
            replicates: 5,
            decided_right,
            runner_up_decided_for_law: rival,
        };
        // Three of five of its own decided, two of five of the rival's taken: the word stands,
        // with the check beside it.
        let kept = a.clone().checked(check(3, Some(2)));
        assert_eq!((kept.strength, &kept.why), (a.strength, &a.why));
        assert!(
            kept.sentence()
                .ends_with("; the check decided 3 of 5 records made by m2 for it and 2 of 5 made by m3 for m2")
        );
        // Two of five of its own: undecided.
        let weak = a.clone().checked(check(2, Some(0)));
        assert_eq!(weak.strength, Strength::Undecided);
        assert!(weak.sentence().contains(
            "undecided (the paper's ABC, P(m | ρ < ε): 0.999 against 0.001, ln B = 6.91 ± 0.10); the check by re-simulation does not decide records like this one; the check decided 2 of 5"
        ));
        // Its own all decided, but the rival's records decided for it in three of five: the
        // check cannot tell the pair apart.
        assert_eq!(a.clone().checked(check(5, Some(3))).strength, Strength::Undecided);
        // An answer that did not decide is not made to, and keeps its why.
        let boxes = Answer {
            strength: Strength::DecidedByTheBoxes,
            why: Some("boxes".into()),
            ..a
        };
        let checked = boxes.clone().checked(check(5, Some(0)));
        assert_eq!((checked.strength, &checked.why), (boxes.strength, &boxes.why));
        // An answer an earlier bitrock kept reads without a check.
        let mut stored = boxes.json();
        stored.as_object_mut().unwrap().remove("check");
        let read: Answer = serde_json::from_value(stored).unwrap();
        assert_eq!(read, boxes);
    }
}
