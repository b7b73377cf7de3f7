//! How much of a Bayes factor the boxes set, one parameter at a time: each parameter's box
//! widened and narrowed [`FACTOR`]× (the others kept), ln Z's change got from the posterior
//! particles by importance reweighting, without sampling again.
//!
//! With uniform boxes the prior density is 1/V. A box B' ⊂ B (narrowed) changes the evidence by
//! Z'/Z = (V/V')·P(θ ∈ B' | y), the posterior mass it keeps; a box B' ⊃ B (widened) by V/V'
//! exactly where the posterior lies inside B (no mass near the ends that move). A widened box
//! whose moved end the posterior reaches, and a narrowed one that keeps too little of it, cannot
//! be reweighted: they are named, not guessed. Where the law's prior is its box cut to a
//! curve's limit C ([`CurveLimit`]), its density is 1/(V·P_B(C)) on B ∩ C, and each change
//! also moves ln Z by ln P_B(C) − ln P_B'(C), the shares estimated with the same draws.

use super::{EDGE_MASS, EDGE_SHARE, LawEvidence};
use crate::laws::Law;
use crate::prior::{CurveLimit, LawBox};
use serde::{Deserialize, Serialize};

/// How much each box is widened and narrowed.
pub const FACTOR: f64 = 2.0;

/// Posterior mass a narrowed box must keep, and particles inside it, for its reweighting to
/// count: below, its estimate rests on a handful of particles.
const MIN_KEPT_MASS: f64 = 0.02;
const MIN_KEPT_PARTICLES: usize = 20;

/// One parameter's box widened or narrowed, and what that does to its law's ln Z.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoxChange {
    /// The parameter's name (`c1`).
    pub parameter: String,
    /// New width over old: [`FACTOR`] (widened; less where a physical bound stops it) or
    /// 1/[`FACTOR`] (narrowed).
    pub factor: f64,
    /// The new box's ends (SI).
    pub lower: f64,
    pub upper: f64,
    /// ln Z′ − ln Z, nats; `None` where the posterior cannot be reweighted to it.
    pub ln_z_shift: Option<f64>,
}

/// The box changes of `law`'s evidence over its prior `bx` (SI): each parameter's widened and
/// narrowed. A box keeps its end at a physical bound and grows or shrinks away from it; a box
/// with no end at a bound (or both) about its centre.
pub fn box_changes(law: &LawEvidence, bx: &LawBox) -> Vec<BoxChange> {
    let (lower, upper) = (&bx.lower, &bx.upper);
    // ln P_B(C) − ln P_B'(C) for the box with parameter j's ends `ends`; `None` where the
    // changed box keeps too little of the limit to estimate.
    let curve_shift = |j: usize, ends: (f64, f64)| -> Option<f64> {
        let Some(curve) = &bx.curve else {
            return Some(0.0);
        };
        let mut lo: Vec<f64> = lower.iter().map(|&v| f64::from(v)).collect();
        let mut hi: Vec<f64> = upper.iter().map(|&v| f64::from(v)).collect();
        (lo[j], hi[j]) = ends;
        share_shift(curve, law.law, (&lo, &hi))
    };
    let mut changes = Vec::new();
    for (j, spec) in law.law.params().iter().enumerate() {
        let (a, b) = (f64::from(lower[j]), f64::from(upper[j]));
        let width = b - a;
        if width.is_nan() || width <= 0.0 {
            continue;
        }
        let resized_by = |factor: f64| resized(law.law, j, (a, b), factor);
        let mass = |inside: &dyn Fn(f64) -> bool| -> (f64, usize) {
            law.posterior
                .iter()
                .filter(|(p, w)| *w > 0.0 && inside(p[j]))
                .fold((0.0, 0), |(m, k), (_, w)| (m + w, k + 1))
        };
        // Widened: exact where the posterior keeps away from every end that moves.
        let (lo, hi) = resized_by(FACTOR);
        let margin = EDGE_SHARE * width;
        let reaches_moved_end = (lo < a && mass(&|v| v <= a + margin).0 > EDGE_MASS)
            || (hi > b && mass(&|v| v >= b - margin).0 > EDGE_MASS);
        changes.push(BoxChange {
            parameter: spec.name.to_string(),
            factor: (hi - lo) / width,
            lower: lo,
            upper: hi,
            ln_z_shift: (!reaches_moved_end)
                .then(|| curve_shift(j, (lo, hi)).map(|c| c - ((hi - lo) / width).ln()))
                .flatten(),
        });
        // Narrowed: the posterior mass the smaller box keeps.
        let (lo, hi) = resized_by(1.0 / FACTOR);
        let (kept, particles) = mass(&|v| (lo..=hi).contains(&v));
        changes.push(BoxChange {
            parameter: spec.name.to_string(),
            factor: (hi - lo) / width,
            lower: lo,
            upper: hi,
            ln_z_shift: (kept >= MIN_KEPT_MASS && particles >= MIN_KEPT_PARTICLES)
                .then(|| curve_shift(j, (lo, hi)).map(|c| c + (width / (hi - lo)).ln() + kept.ln()))
                .flatten(),
        });
    }
    changes
}

/// Parameter `j`'s box (`a`, `b`, SI) of `law` resized by `factor`: kept at its end on a
/// physical bound and grown or shrunk away from it; about its centre where neither end (or
/// both) is on one; clipped to the bounds.
fn resized(law: Law, j: usize, (a, b): (f64, f64), factor: f64) -> (f64, f64) {
    let spec = law.params()[j];
    let w = (b - a) * factor;
    let (lo, hi) = match (a <= spec.lower, b >= spec.upper) {
        (true, false) => (a, a + w),
        (false, true) => (b - w, b),
        _ => (0.5 * (a + b) - 0.5 * w, 0.5 * (a + b) + 0.5 * w),
    };
    (lo.max(spec.lower), hi.min(spec.upper))
}

/// ln Z′ − ln Z of the law of prior `bx` with every box [`FACTOR`]× as wide (as [`box_changes`]
/// widens one), for a posterior inside the boxes: the volume ratio, −ln 2 per parameter, and
/// where the prior is cut to a curve's limit the ratio of the shares it keeps, which gives most
/// of that back (the limit, not the boxes, bounds the curves); `None` where the wider boxes
/// keep too little of the limit to estimate.
pub fn every_box_widened(bx: &LawBox) -> Option<f64> {
    let ends: Vec<(f64, f64)> = (0..bx.lower.len())
        .map(|j| resized(bx.law, j, (f64::from(bx.lower[j]), f64::from(bx.upper[j])), FACTOR))
        .collect();
    let volume: f64 = ends
        .iter()
        .zip(bx.lower.iter().zip(&bx.upper))
        .map(|(&(lo, hi), (&a, &b))| ((hi - lo) / (f64::from(b) - f64::from(a))).ln())
        .sum();
    let curve = match &bx.curve {
        None => 0.0,
        Some(curve) => {
            let (lo, hi): (Vec<f64>, Vec<f64>) = ends.into_iter().unzip();
            share_shift(curve, bx.law, (&lo, &hi))?
        }
    };
    Some(curve - volume)
}

/// ln P_B(C) − ln P_B'(C) of `curve` (its share of the box B it was made on) for the box B'
/// (`lower`, `upper`, SI) of `law`.
fn share_shift(curve: &CurveLimit, law: Law, (lower, upper): (&[f64], &[f64])) -> Option<f64> {
    curve
        .share_in(law, lower, upper)
        .map(|(ln_share, _)| curve.ln_share - ln_share)
}

/// A Bayes factor over the boxes changed one at a time (either law's, one parameter, widened
/// or narrowed).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sensitivity {
    /// The lowest and highest ln B (favoured over the other) over the changes reweighted, the
    /// unchanged boxes included, and the change that gives each ("m4 c1 ×0.5").
    pub lowest: f64,
    pub lowest_change: Option<String>,
    pub highest: f64,
    pub highest_change: Option<String>,
    /// True where the order of the pair (either law ahead by at least 1 nat beyond twice the
    /// error, or neither) differs between the lowest and the highest.
    pub prior_dependent: bool,
    /// The changes that could not be reweighted ("m4 c1 ×2"): the range leaves them out.
    pub not_reweighted: Vec<String>,
}

impl Sensitivity {
    /// The range of `ln_b` (of `favoured` over `against`, error `error`) over both laws' box
    /// changes; `None` where neither has any.
    pub fn of(favoured: &LawEvidence, against: &LawEvidence, ln_b: f64, error: f64) -> Option<Self> {
        if favoured.box_changes.is_empty() && against.box_changes.is_empty() {
            return None;
        }
        let named = |law: Law, c: &BoxChange| format!("{law} {} ×{:.2}", c.parameter, c.factor);
        let mut range = Self {
            lowest: ln_b,
            lowest_change: None,
            highest: ln_b,
            highest_change: None,
            prior_dependent: false,
            not_reweighted: Vec::new(),
        };
        let sides = [(favoured, 1.0), (against, -1.0)];
        for (law, sign) in sides {
            for change in &law.box_changes {
                let Some(shift) = change.ln_z_shift else {
                    range.not_reweighted.push(named(law.law, change));
                    continue;
                };
                let moved = ln_b + sign * shift;
                if moved < range.lowest {
                    range.lowest = moved;
                    range.lowest_change = Some(named(law.law, change));
                }
                if moved > range.highest {
                    range.highest = moved;
                    range.highest_change = Some(named(law.law, change));
                }
            }
        }
        let threshold = 1.0f64.max(2.0 * error);
        let lead = |x: f64| (x >= threshold) as i8 - (x <= -threshold) as i8;
        range.prior_dependent = lead(range.lowest) != lead(range.highest);
        Some(range)
    }

    /// "one box ×2 or ×1/2: ln B 0.96 (m4 c1 ×0.50) to 2.34 (m2 tcb ×0.50), prior-dependent",
    /// for a table or a line.
    pub fn describe(&self) -> String {
        let end = |v: f64, change: &Option<String>| match change {
            Some(c) => format!("{v:.2} ({c})"),
            None => format!("{v:.2}"),
        };
        format!(
            "one box ×{FACTOR} or ×1/{FACTOR}: ln B {} to {}{}{}",
            end(self.lowest, &self.lowest_change),
            end(self.highest, &self.highest_change),
            if self.prior_dependent { ", prior-dependent" } else { "" },
            if self.not_reweighted.is_empty() {
                String::new()
            } else {
                format!("; not reweighted: {}", self.not_reweighted.join(", "))
            }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// m2's evidence with `ln_z` and a posterior of 100 equal particles spread ±`spread`
    /// around `at` (SI).
    fn m2(ln_z: f64, at: [f64; 3], spread: f64) -> LawEvidence {
        let posterior = (0..100)
            .map(|i| {
                let d = spread * (f64::from(i) / 99.0 - 0.5);
                (at.iter().map(|v| v + d).collect(), 0.01)
            })
            .collect();
        LawEvidence::for_tests(Law::M2, ln_z, posterior, None)
    }

    const LOWER: [f32; 3] = [0.0, 0.0, 0.0];
    const UPPER: [f32; 3] = [10.0, 10.0, 4.0];

    fn m2_box() -> LawBox {
        LawBox::new(Law::M2, LOWER.to_vec(), UPPER.to_vec())
    }

    #[test]
    fn a_posterior_inside_both_boxes_moves_ln_z_by_the_volume_ratio_alone() {
        let law = m2(0.0, [2.0, 3.0, 1.0], 0.2);
        let changes = box_changes(&law, &m2_box());
        assert_eq!(changes.len(), 6);
        for pair in changes.chunks(2) {
            let (wide, narrow) = (&pair[0], &pair[1]);
            // Each box keeps its end at the physical bound 0 and grows or shrinks away from it.
            assert_eq!(
                (wide.lower, narrow.lower, wide.factor, narrow.factor),
                (0.0, 0.0, 2.0, 0.5)
            );
            assert_eq!(wide.ln_z_shift.unwrap().to_bits(), (-(2.0f64.ln())).to_bits());
            // Every particle kept: ln 2 + ln 1.
            assert!((narrow.ln_z_shift.unwrap() - 2.0f64.ln()).abs() < 1e-12, "{narrow:?}");
        }
    }

    #[test]
    fn a_narrowed_box_keeps_the_posterior_mass_inside_it_and_the_rest_is_named() {
        // tsb's particles spread over 4 to 6: the half box [0, 5] keeps half of them.
        let law = m2(0.0, [5.0, 3.0, 1.0], 2.0);
        let changes = box_changes(&law, &m2_box());
        let narrow_tsb = &changes[1];
        assert_eq!((narrow_tsb.parameter.as_str(), narrow_tsb.upper), ("tsb", 5.0));
        assert!((narrow_tsb.ln_z_shift.unwrap() - (2.0f64.ln() + 0.5f64.ln())).abs() < 1e-12);
        // A posterior outside the narrowed box, and one at the end a widened box moves, are not
        // reweighted.
        let law = m2(0.0, [9.9, 3.0, 1.0], 0.1);
        let changes = box_changes(&law, &m2_box());
        assert_eq!((changes[0].ln_z_shift, changes[1].ln_z_shift), (None, None));
    }

    #[test]
    fn a_pair_whose_order_a_single_box_can_change_is_prior_dependent() {
        let mut favoured = m2(-100.0, [2.0, 3.0, 1.0], 0.2);
        favoured.box_changes = box_changes(&favoured, &m2_box());
        let mut against = m2(-101.2, [2.0, 3.0, 1.0], 0.2);
        against.law = Law::M1;
        against.box_changes = vec![BoxChange {
            parameter: "b1".into(),
            factor: 0.5,
            lower: 0.0,
            upper: 1.0,
            ln_z_shift: Some(0.69),
        }];
        let range = Sensitivity::of(&favoured, &against, 1.2, 0.1).unwrap();
        assert!((range.lowest - (1.2 - 2.0f64.ln())).abs() < 1e-12, "{range:?}");
        assert!((range.highest - (1.2 + 2.0f64.ln())).abs() < 1e-12, "{range:?}");
        assert_eq!(range.lowest_change.as_deref(), Some("m2 tsb ×2.00"));
        assert!(range.prior_dependent, "{range:?}");
        // Far apart, no single box changes the order.
        let range = Sensitivity::of(&favoured, &against, 8.0, 0.1).unwrap();
        assert!(!range.prior_dependent && range.not_reweighted.is_empty(), "{range:?}");
    }

    #[test]
    fn every_box_widened_costs_ln_2_per_parameter_less_what_a_curve_limit_gives_back() {
        // m2's boxes start at their physical bounds (0) and double away from them.
        let plain = every_box_widened(&m2_box()).unwrap();
        assert!((plain + 3.0 * std::f64::consts::LN_2).abs() < 1e-12, "{plain}");
        // m4's unit box (c0 in [0, 2], c1..c3 in ±10) cut to |T| ≤ 2 from rest to 1: its
        // doubled boxes are c0 in [0, 4] and ±20, and the shift is −4 ln 2 plus the shares'
        // ratio, the doubled box's share from its own limit.
        let lower = vec![0.0f32, -10.0, -10.0, -10.0];
        let upper = vec![2.0f32, 10.0, 10.0, 10.0];
        let mut bx = LawBox::new(Law::M4, lower.clone(), upper.clone());
        bx.curve = Some(CurveLimit::new(Law::M4, 2.0, 1.0, 1.0, (&lower, &upper)).unwrap());
        let doubled = CurveLimit::new(
            Law::M4,
            2.0,
            1.0,
            1.0,
            (&[0.0, -20.0, -20.0, -20.0], &[4.0, 20.0, 20.0, 20.0]),
        )
        .unwrap();
        let curve = bx.curve.as_ref().unwrap();
        let want = -4.0 * std::f64::consts::LN_2 + curve.ln_share - doubled.ln_share;
        let got = every_box_widened(&bx).unwrap();
        eprintln!(
            "every box of m4 widened: {got:.3} (whole boxes: {:.3})",
            -4.0 * std::f64::consts::LN_2
        );
        assert!((got - want).abs() < 1e-9, "{got} against {want}");
        // Most of the 2.77 nats come back (2.0 on this box, which is m4's physical box in the
        // record's scales): the limit, not the boxes, bounds the curves.
        assert!(got > -1.5 && got < 0.5, "{got}");
    }
}
