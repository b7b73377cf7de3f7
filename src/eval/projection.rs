//! Semi-automatic summaries (Fearnhead & Prangle 2012): the distance compares, instead of the
//! summaries themselves, what a linear regression on strings near the record predicts from
//! them: each law's coordinates (Ê[θ | s]) and each law's indicator (P̂(m | s), Prangle,
//! Fearnhead, Cox, Biggs & French 2014). A summary that moves with no coordinate gets no
//! weight, however much it varies; a coordinate the summaries do not predict (adjusted R² near
//! 0) barely moves the distance, since each prediction is scaled by the spread of what it
//! predicts, not by its own.
//!
//! The predictions are linear in the summaries, so the distance between two sets of summaries
//! is that of the predictions' difference, B·(a − b): a function of the summaries alone, fixed
//! after the training strings, as the scaled distance is after its pilot.

use crate::laws::Law;
use crate::simulate::surface::{N_SUMMARIES, Summaries};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Fewest training strings per regressed term (each compared summary and the intercept) for a
/// law's coordinates to be regressed on its strings: fewer would fit their noise.
pub const MIN_STRINGS_PER_TERM: usize = 3;
/// Fewest training strings of a law for its coordinates to be regressed, where `active`
/// marks the summaries compared ([`MIN_STRINGS_PER_TERM`] per summary and the intercept).
pub fn least_strings(active: &[bool; N_SUMMARIES]) -> usize {
    MIN_STRINGS_PER_TERM * (active.iter().filter(|a| **a).count() + 1)
}

/// The ridge's weight, relative to the training strings' count: a summary the others nearly
/// predict does not get a large weight of either sign.
pub const RIDGE: f64 = 1e-3;

/// One predicted quantity: its weights on the scaled summary differences, divided by the
/// spread of what it predicts.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Feature {
    /// `LAW.PARAMETER` for a coordinate of the law's (the string's as `LAW.omega_n_rad_s` and
    /// `LAW.damping_ratio`), `P(LAW)` for a law's indicator.
    pub name: String,
    /// Per summary (0 for those not compared).
    #[serde(skip)]
    pub weights: Summaries,
    /// The share of its target's variance the prediction explains over the strings it was
    /// fitted on, adjusted for the summaries' count (1 − (1 − R²)(n − 1)/(n − p − 1), at
    /// least 0): what the summaries tell of it, not what fitting their noise adds.
    pub adjusted_r_squared: f64,
    /// The strings it was fitted on: its law's for a coordinate, all for an indicator.
    pub strings: usize,
}

/// The predictions a distance compares.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Projection {
    pub features: Vec<Feature>,
    /// Training strings the regressions were fitted on.
    pub training: usize,
    /// Laws with too few training strings ([`MIN_STRINGS_PER_TERM`]) for their coordinates to
    /// be regressed: their parameters are compared only through the other predictions.
    pub unregressed: Vec<Law>,
}

/// A training string: its law's slot in the prior, its coordinates (SI) and its summaries
/// (with the record's noise).
pub struct Training<'a> {
    pub slot: usize,
    pub coordinates: &'a [f64],
    pub summaries: Summaries,
}

impl Projection {
    /// The regressions on `training`, of the summaries scaled by `scales` relative to
    /// `observed` (only `active` ones): for each law of `laws` (by slot) with enough strings,
    /// each coordinate whose box `bounds[slot]` spans a width, as a share of that width, on
    /// that law's strings; with two laws or more, each law's indicator on all strings, each
    /// weighed by √((K − 1)/K) for K laws (the indicators sum to 1, so they carry K − 1
    /// predictions' worth). `coordinate_names[slot]` names the law's coordinates. `None` where
    /// no regression could be fitted.
    #[allow(clippy::too_many_arguments)]
    pub fn learn(
        training: &[Training<'_>],
        observed: &Summaries,
        scales: &Summaries,
        active: &[bool; N_SUMMARIES],
        laws: &[Law],
        bounds: &[(Vec<f64>, Vec<f64>)],
        coordinate_names: &[Vec<String>],
    ) -> Option<Self> {
        let compared: Vec<usize> = (0..N_SUMMARIES).filter(|&j| active[j]).collect();
        let design = |rows: &[&Training<'_>]| {
            DMatrix::from_fn(rows.len(), compared.len() + 1, |i, c| {
                if c == 0 {
                    1.0
                } else {
                    let j = compared[c - 1];
                    (rows[i].summaries[j] - observed[j]) / scales[j]
                }
            })
        };
        let mut features = Vec::new();
        let mut unregressed = Vec::new();
        let least = least_strings(active);
        for (slot, (lower, upper)) in bounds.iter().enumerate() {
            let rows: Vec<&Training<'_>> = training.iter().filter(|t| t.slot == slot).collect();
            let varies = lower.iter().zip(upper).any(|(lo, hi)| hi > lo);
            if rows.len() < least {
                if varies {
                    unregressed.push(laws[slot]);
                }
                continue;
            }
            let x = design(&rows);
            for (d, (lo, hi)) in lower.iter().zip(upper).enumerate() {
                if hi <= lo {
                    continue;
                }
                let target =
                    DVector::from_iterator(rows.len(), rows.iter().map(|t| (t.coordinates[d] - lo) / (hi - lo)));
                if let Some((weights, adjusted_r_squared)) = regress(&x, &target, &compared) {
                    features.push(Feature {
                        name: format!("{}.{}", laws[slot].name(), coordinate_names[slot][d]),
                        weights,
                        adjusted_r_squared,
                        strings: rows.len(),
                    });
                }
            }
        }
        let present: Vec<usize> = (0..bounds.len())
            .filter(|&slot| training.iter().any(|t| t.slot == slot))
            .collect();
        if present.len() >= 2 && training.len() >= least {
            let all: Vec<&Training<'_>> = training.iter().collect();
            let x = design(&all);
            let share = ((present.len() - 1) as f64 / present.len() as f64).sqrt();
            for &slot in &present {
                let target = DVector::from_iterator(all.len(), all.iter().map(|t| f64::from(u8::from(t.slot == slot))));
                if let Some((weights, adjusted_r_squared)) = regress(&x, &target, &compared) {
                    features.push(Feature {
                        name: format!("P({})", laws[slot].name()),
                        weights: weights.map(|w| share * w),
                        adjusted_r_squared,
                        strings: all.len(),
                    });
                }
            }
        }
        (!features.is_empty()).then_some(Self {
            features,
            training: training.len(),
            unregressed,
        })
    }

    /// √(mean over the features of (B·d)²) for the scaled summary differences `d`.
    pub fn rho(&self, d: &Summaries) -> f64 {
        let sum: f64 = self
            .features
            .iter()
            .map(|f| f.weights.iter().zip(d).map(|(w, d)| w * d).sum::<f64>().powi(2))
            .sum();
        (sum / self.features.len().max(1) as f64).sqrt()
    }
}

/// The ridge regression of `target` on the design `x` (a column of ones, then the compared
/// summaries): the summaries' weights divided by the target's standard deviation, placed at
/// their summaries, and the adjusted R². `None` for a target that does not vary, a singular
/// system or a fit that is not finite.
fn regress(x: &DMatrix<f64>, target: &DVector<f64>, compared: &[usize]) -> Option<(Summaries, f64)> {
    let n = target.len() as f64;
    let terms = compared.len() as f64;
    let mean = target.mean();
    let total: f64 = target.iter().map(|t| (t - mean).powi(2)).sum();
    if total <= 0.0 || !total.is_finite() || n <= terms + 1.0 {
        return None;
    }
    let sd = (total / (n - 1.0)).sqrt();
    let mut gram = x.transpose() * x;
    for c in 1..gram.ncols() {
        gram[(c, c)] += RIDGE * n;
    }
    let beta = gram.cholesky()?.solve(&(x.transpose() * target));
    let residual: f64 = (x * &beta - target).iter().map(|r| r * r).sum();
    let adjusted = 1.0 - (residual / total) * (n - 1.0) / (n - terms - 1.0);
    if !(adjusted.is_finite() && beta.iter().all(|b| b.is_finite())) {
        return None;
    }
    let mut weights = [0.0; N_SUMMARIES];
    for (c, &j) in compared.iter().enumerate() {
        weights[j] = beta[c + 1] / sd;
    }
    Some((weights, adjusted.max(0.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Summaries of which the first two are linear in the law's two coordinates (with noise)
    /// and the rest noise alone: the projection predicts each coordinate from its summary
    /// (R² near 1), gives the noise summaries next to no weight, and its distance ranks
    /// strings by how near their coordinates lie, whatever the noise summaries say.
    #[test]
    fn the_regressions_find_the_summaries_that_carry_the_coordinates() {
        let mut state = 7u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut coordinates = Vec::new();
        let mut summaries = Vec::new();
        for _ in 0..400 {
            let theta = [uniform(), 2.0 + 3.0 * uniform()];
            let mut s = [0.0; N_SUMMARIES];
            s[0] = 10.0 * theta[0] + 0.05 * (uniform() - 0.5);
            s[1] = -theta[1] + 0.05 * (uniform() - 0.5);
            for v in s.iter_mut().skip(2) {
                *v = 5.0 * (uniform() - 0.5);
            }
            coordinates.push(theta.to_vec());
            summaries.push(s);
        }
        let training: Vec<Training<'_>> = coordinates
            .iter()
            .zip(&summaries)
            .map(|(c, s)| Training {
                slot: 0,
                coordinates: c,
                summaries: *s,
            })
            .collect();
        let observed = summaries[0];
        let scales = [1.0; N_SUMMARIES];
        let active = [true; N_SUMMARIES];
        let bounds = vec![(vec![0.0, 2.0], vec![1.0, 5.0])];
        let names = vec![vec!["a".to_string(), "b".to_string()]];
        let p = Projection::learn(&training, &observed, &scales, &active, &[Law::M2], &bounds, &names).unwrap();
        assert!(p.unregressed.is_empty());
        assert_eq!(p.features.len(), 2, "one law: its coordinates, no indicator");
        assert_eq!(
            (p.features[0].name.as_str(), p.features[1].name.as_str()),
            ("m2.a", "m2.b")
        );
        for f in &p.features {
            assert!(f.adjusted_r_squared > 0.99, "{}: R² {}", f.name, f.adjusted_r_squared);
            assert_eq!(f.strings, 400);
            let carried: f64 = f.weights[..2].iter().map(|w| w.abs()).sum();
            let noise: f64 = f.weights[2..].iter().map(|w| w.abs()).sum();
            assert!(noise < 0.02 * carried, "{}: {:?}", f.name, f.weights);
        }
        // A string whose coordinates are the observed's but whose noise summaries differ
        // lies nearer than one whose first coordinate is off by a tenth of its box.
        let same = {
            let mut s = observed;
            for v in s.iter_mut().skip(2) {
                *v += 2.0;
            }
            s
        };
        let off = {
            let mut s = observed;
            s[0] += 1.0;
            s
        };
        let rho = |s: &Summaries| p.rho(&std::array::from_fn(|j| s[j] - observed[j]));
        assert!(rho(&same) < 0.2 * rho(&off), "{} vs {}", rho(&same), rho(&off));
    }

    /// A law with fewer training strings than its regressions need is named, not regressed;
    /// the law with enough is.
    #[test]
    fn a_law_too_sparse_to_regress_is_named() {
        let mut active = [false; N_SUMMARIES];
        active[0] = true;
        assert_eq!(least_strings(&active), 6);
        let coordinates: Vec<Vec<f64>> = (0..30).map(|i| vec![f64::from(i) / 30.0]).collect();
        let training: Vec<Training<'_>> = coordinates
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let slot = usize::from(i >= 25);
                let mut s = [0.0; N_SUMMARIES];
                s[0] = c[0] + 0.01 * ((i * 7 % 5) as f64);
                Training {
                    slot,
                    coordinates: c,
                    summaries: s,
                }
            })
            .collect();
        let bounds = vec![(vec![0.0], vec![1.0]); 2];
        let names = vec![vec!["x".to_string()]; 2];
        let p = Projection::learn(
            &training,
            &[0.0; N_SUMMARIES],
            &[1.0; N_SUMMARIES],
            &active,
            &[Law::M2, Law::M3],
            &bounds,
            &names,
        )
        .unwrap();
        assert_eq!(p.unregressed, [Law::M3], "five strings of m3, six needed");
        let names: Vec<&str> = p.features.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["m2.x", "P(m2)", "P(m3)"]);
        assert_eq!(p.features[0].strings, 25);
    }

    /// Two laws told apart by one summary: the indicators' regressions weigh that summary
    /// and explain most of the indicators' variance.
    #[test]
    fn the_laws_indicators_are_regressed_on_all_strings() {
        let mut training = Vec::new();
        let coordinates = vec![vec![0.5]; 200];
        for (i, c) in coordinates.iter().enumerate() {
            let slot = i % 2;
            let mut s = [0.0; N_SUMMARIES];
            s[3] = slot as f64 + 0.01 * ((i * 37 % 11) as f64 - 5.0);
            s[4] = ((i * 53 % 17) as f64 - 8.0) / 8.0;
            training.push(Training {
                slot,
                coordinates: c,
                summaries: s,
            });
        }
        let mut active = [false; N_SUMMARIES];
        active[3] = true;
        active[4] = true;
        let bounds = vec![(vec![0.0], vec![1.0]); 2];
        let names = vec![vec!["x".to_string()]; 2];
        let laws = [Law::M1, Law::M2];
        let p = Projection::learn(
            &training,
            &[0.0; N_SUMMARIES],
            &[1.0; N_SUMMARIES],
            &active,
            &laws,
            &bounds,
            &names,
        )
        .unwrap();
        // The coordinate does not vary: no coordinate feature, two indicators.
        let names: Vec<&str> = p.features.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["P(m1)", "P(m2)"]);
        // Opposite predictions of one quantity, each weighed by √(1/2): together they count
        // as one.
        let d: Summaries = std::array::from_fn(|j| if j == 3 { 1.0 } else { 0.0 });
        let one = p.features[0].weights[3].abs();
        assert!((p.rho(&d) - one).abs() < 1e-12 * one, "{} vs {one}", p.rho(&d));
        for f in &p.features {
            assert!(f.adjusted_r_squared > 0.99, "{}: {}", f.name, f.adjusted_r_squared);
            assert!(f.weights[4].abs() < 0.01 * f.weights[3].abs(), "{:?}", f.weights);
            assert!(f.weights.iter().enumerate().all(|(j, w)| active[j] || w.to_bits() == 0));
        }
    }
}
