//! A law's prior cut to the curves that stay within the record's torques.
//!
//! A box per coefficient cannot say "the cubic stays within the record's torques": its terms
//! must be free to reach several times the largest torque, since fits cancel them against one
//! another, and most of such a box then draws curves that reach far beyond any torque the
//! record or the other laws' boxes hold. The Occam factor charges the law for that volume.
//! Where a law's file says so (`prior_curve_within = k`), the evidence's prior of the law is its
//! box B cut to C = {θ : |T(w; θ)| ≤ k·|y|max at every speed of a grid from rest to the record's
//! fastest}, uniform on B ∩ C: density 1/(V_B·P_B(C)) there. The samplers from the prior
//! start inside C, a warm start's draws outside it weigh 0, and no proposal leaves it; the
//! share P_B(C) is estimated once by Monte Carlo over the box.

use crate::error::{Error, Result};
use crate::laws::{Law, MAX_PARAMS};
use crate::rng::{key_of_seed, philox4x32_10, uniform_between};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Speeds of the grid the limit holds at, evenly from rest to the record's fastest.
pub const CURVE_SPEEDS: usize = 33;

/// Draws of the box that estimate its share inside the limit: the share's relative error is
/// √((1 − P)/(N·P)), 0.012 nats at P = 0.09.
pub const SHARE_DRAWS: u64 = 1 << 16;

/// The fewest of [`SHARE_DRAWS`] that must keep the limit: below, the limit leaves too little
/// of the box to sample or to estimate (ln P below about −6.5).
pub const MIN_INSIDE: u64 = 100;

/// The Philox block and seed of the share's draws: the same draws for every record and run.
const SHARE_BLOCK: u32 = 0x4375_7276;
const SHARE_SEED: u64 = 0x5368_6172_6520_4321;

/// A law's prior cut to curves within a torque over the record's speeds (see the module's
/// documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CurveLimit {
    /// The limit in multiples of the record's largest |torque| (the law file's
    /// `prior_curve_within`).
    pub within: f64,
    /// The limit, N·m.
    pub limit_nm: f64,
    /// The speeds the limit holds at, rad/s.
    pub speeds_rad_s: Vec<f64>,
    /// ln P_B(C), the share of the box that keeps the limit.
    pub ln_share: f64,
    /// Its Monte-Carlo standard error, nats.
    pub ln_share_error: f64,
}

impl CurveLimit {
    /// The limit of `law` at `within` times `torque_max_nm` over speeds from rest to
    /// `speed_high_rad_s`, on the box (`lower`, `upper`, SI); refused where it keeps too little
    /// of the box to sample.
    pub fn new(
        law: Law,
        within: f64,
        torque_max_nm: f64,
        speed_high_rad_s: f64,
        (lower, upper): (&[f32], &[f32]),
    ) -> Result<Self> {
        let speeds_rad_s = (0..CURVE_SPEEDS)
            .map(|i| speed_high_rad_s * i as f64 / (CURVE_SPEEDS - 1) as f64)
            .collect();
        let mut limit = Self {
            within,
            limit_nm: within * torque_max_nm,
            speeds_rad_s,
            ln_share: 0.0,
            ln_share_error: 0.0,
        };
        let lower: Vec<f64> = lower.iter().map(|&v| f64::from(v)).collect();
        let upper: Vec<f64> = upper.iter().map(|&v| f64::from(v)).collect();
        (limit.ln_share, limit.ln_share_error) = limit.share_in(law, &lower, &upper).ok_or_else(|| {
            Error::setting(
                "prior_curve_within",
                format!(
                    "law {law}: fewer than {MIN_INSIDE} of {SHARE_DRAWS} draws of its box keep its torque within {within} times the record's largest ({:.4e} N·m) from rest to {speed_high_rad_s:.4} rad/s; narrow the law's boxes (the prior scale, or a prior file), or raise its law file's prior_curve_within",
                    limit.limit_nm
                ),
            )
        })?;
        Ok(limit)
    }

    /// Whether the curve of `law` at `params` keeps the limit (r = 1: the torque at the
    /// reference weight on bit).
    pub fn holds(&self, law: Law, params: &[f32]) -> bool {
        let mut p = [0.0f64; MAX_PARAMS];
        for (slot, &v) in p.iter_mut().zip(params) {
            *slot = f64::from(v);
        }
        let p = &p[..law.n_params()];
        self.speeds_rad_s
            .iter()
            .all(|&w| law.torque(p, w, 1.0).abs() <= self.limit_nm)
    }

    /// ln of the share of the box (`lower`, `upper`, SI) whose curves keep the limit, and its
    /// standard error, from [`SHARE_DRAWS`] draws (the same for every box: a changed box is
    /// estimated with the same random numbers); `None` where fewer than [`MIN_INSIDE`] keep it.
    pub fn share_in(&self, law: Law, lower: &[f64], upper: &[f64]) -> Option<(f64, f64)> {
        let d = law.n_params();
        let inside: u64 = (0..SHARE_DRAWS)
            .into_par_iter()
            .filter(|&index| self.holds(law, &share_draw(d, lower, upper, index)[..d]))
            .count() as u64;
        if inside < MIN_INSIDE {
            return None;
        }
        let share = inside as f64 / SHARE_DRAWS as f64;
        Some((share.ln(), ((1.0 - share) / inside as f64).sqrt()))
    }

    /// Per parameter of `law`, the central `level` interval of the prior cut to this limit on
    /// the box (`lower`, `upper`, SI), from the share's draws that keep it: what the prior
    /// alone spans, against which a posterior's interval tells whether the record narrowed it.
    pub fn central_intervals(&self, law: Law, lower: &[f64], upper: &[f64], level: f64) -> Vec<(f64, f64)> {
        let d = law.n_params();
        let kept: Vec<[f32; MAX_PARAMS]> = (0..SHARE_DRAWS)
            .into_par_iter()
            .map(|index| share_draw(d, lower, upper, index))
            .filter(|p| self.holds(law, &p[..d]))
            .collect();
        (0..d)
            .map(|j| {
                let values: Vec<f64> = kept.iter().map(|p| f64::from(p[j])).collect();
                (
                    crate::numerics::quantile(&values, 0.5 * (1.0 - level)),
                    crate::numerics::quantile(&values, 0.5 * (1.0 + level)),
                )
            })
            .collect()
    }
}

/// Draw `index` of the share's: uniform on the box (`lower`, `upper`) of `d` parameters, the
/// same for every box.
fn share_draw(d: usize, lower: &[f64], upper: &[f64], index: u64) -> [f32; MAX_PARAMS] {
    let key = key_of_seed(SHARE_SEED);
    let mut p = [0.0f32; MAX_PARAMS];
    for block in (0..d).step_by(4) {
        let words = philox4x32_10([index as u32, (index >> 32) as u32, block as u32, SHARE_BLOCK], key);
        for (k, &word) in (block..d.min(block + 4)).zip(&words) {
            p[k] = uniform_between(lower[k] as f32, upper[k] as f32, word);
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    /// m4's cubic in units of the largest torque and the fastest speed: c0 in [0, 2],
    /// c1..c3 in [−10, 10], |T| ≤ 2 from rest to 1. Its share, by a grid of 21⁴ points
    /// (cell centres) as an independent estimate, agrees within the Monte-Carlo error.
    #[test]
    fn the_share_of_m4_s_box_is_the_grid_s() {
        let lower = [0.0f32, -10.0, -10.0, -10.0];
        let upper = [2.0f32, 10.0, 10.0, 10.0];
        let limit = CurveLimit::new(Law::M4, 2.0, 1.0, 1.0, (&lower, &upper)).unwrap();
        let n = 21;
        let centre = |i: usize, a: f32, b: f32| a + (b - a) * (i as f32 + 0.5) / n as f32;
        let mut inside = 0usize;
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    for l in 0..n {
                        let p = [
                            centre(i, lower[0], upper[0]),
                            centre(j, lower[1], upper[1]),
                            centre(k, lower[2], upper[2]),
                            centre(l, lower[3], upper[3]),
                        ];
                        inside += usize::from(limit.holds(Law::M4, &p));
                    }
                }
            }
        }
        let grid = (inside as f64 / (n as f64).powi(4)).ln();
        assert!(
            (limit.ln_share - grid).abs() < 4.0 * limit.ln_share_error + 0.02,
            "{} ± {} against the grid's {grid}",
            limit.ln_share,
            limit.ln_share_error
        );
        // About a tenth of the box: the coefficients' terms cancel in most of what is kept.
        assert!((0.07..0.12).contains(&limit.ln_share.exp()), "{}", limit.ln_share.exp());
        // A curve at the limit's edge: a constant 2 holds, 2.01 does not.
        assert!(limit.holds(Law::M4, &[2.0, 0.0, 0.0, 0.0]));
        assert!(!limit.holds(Law::M4, &[2.01, 0.0, 0.0, 0.0]));
    }

    /// m4 as a constant c0 in [0, 4] cut to |T| ≤ 3: the cut prior is uniform on [0, 3], its
    /// central 90 % [0.15, 2.85]; a fixed parameter's interval is its value.
    #[test]
    fn the_central_intervals_of_a_cut_prior_are_those_of_what_it_keeps() {
        let lower = [0.0f32, 0.0, 0.0, 0.0];
        let upper = [4.0f32, 0.0, 0.0, 0.0];
        let limit = CurveLimit::new(Law::M4, 3.0, 1.0, 1.0, (&lower, &upper)).unwrap();
        let (lower, upper) = ([0.0, 0.0, 0.0, 0.0], [4.0, 0.0, 0.0, 0.0]);
        let intervals = limit.central_intervals(Law::M4, &lower, &upper, 0.9);
        assert_eq!(intervals.len(), 4);
        assert!(
            (intervals[0].0 - 0.15).abs() < 0.03 && (intervals[0].1 - 2.85).abs() < 0.03,
            "{intervals:?}"
        );
        assert_eq!(intervals[1], (0.0, 0.0));
    }

    #[test]
    fn a_limit_that_keeps_almost_none_of_the_box_is_refused_naming_its_field() {
        let lower = [0.0f32, -10.0, -10.0, -10.0];
        let upper = [2.0f32, 10.0, 10.0, 10.0];
        let err = CurveLimit::new(Law::M4, 1e-3, 1.0, 1.0, (&lower, &upper))
            .unwrap_err()
            .to_string();
        assert!(err.contains("prior_curve_within") && err.contains("law m4"), "{err}");
    }

    #[test]
    fn a_box_cut_to_a_curve_admits_what_both_keep() {
        let (lower, upper) = (vec![0.0f32, -10.0, -10.0, -10.0], vec![2.0f32, 10.0, 10.0, 10.0]);
        let mut bx = crate::prior::LawBox::new(Law::M4, lower.clone(), upper.clone());
        assert!(bx.admits(&[1.5, 5.0, 0.0, 0.0]));
        bx.curve = Some(CurveLimit::new(Law::M4, 2.0, 1.0, 1.0, (&lower, &upper)).unwrap());
        // 1.5 + 0.5·w reaches 2 at the fastest speed: kept; 1.5 + 5·w reaches 6.5: not.
        assert!(bx.admits(&[1.5, 0.5, 0.0, 0.0]));
        assert!(!bx.admits(&[1.5, 5.0, 0.0, 0.0]));
        // Outside the box, whatever the curve.
        assert!(!bx.admits(&[2.5, 0.0, 0.0, 0.0]));
    }
}
