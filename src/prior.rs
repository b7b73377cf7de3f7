//! Priors of the ABC: a probability per law and, per parameter, an independent uniform box.
//!
//! The paper's rule (eq. minmax): [φ̂(1 − δ), φ̂(1 + δ)] around the least-squares estimate,
//! ordered (a negative estimate flips the ends) and clipped to the law's physical bounds.
//!
//! That rule has no width where the estimate is 0 or sits on its physical bound (a laboratory
//! record's dynamic torque tcb, say, which the data push below 0): there the box is
//! φ̂ ± δ·s, where s is the record's own size of the parameter's dimension (the RMS torque for
//! a torque, the inverse of the 95th-percentile speed for a rate, their ratio for a torque per
//! speed; see [`crate::fit::RecordScales::param_scale`]), clipped to the bound. Estimates the data do not
//! identify (a standard error above |φ̂|, or none because two parameters trade off) keep the
//! paper's box, which is centred on a point of the least-squares ridge and scales the
//! trading parameters together; they are marked so that the user knows the box, not the data,
//! sets their spread. [`BoxRule`] records which rule made every box.
//!
//! A TOML file can replace any box and set the law weights:
//!
//! ```toml
//! # Torque-valued bounds in the record's torque unit (kN·m for a kN·m record), speeds in rad/s.
//! [weights]          # prior law probabilities, normalised; laws not listed keep weight 1
//! m1 = 1.0
//! m4 = 0.5
//! [m2]               # [lower, upper] per parameter; parameters not listed keep the δ rule
//! tsb = [8.0, 18.0]
//! g = [0.1, 0.5]
//! ```
//!
//! Candidates are drawn from the prior by [`Prior::candidate`], a pure function of
//! (seed, population, index) through Philox (see [`crate::rng`]); parameters are f32 so that a
//! WGSL kernel reproduces them bit for bit.

mod curve;

pub use curve::{CURVE_SPEEDS, CurveLimit, MIN_INSIDE, SHARE_DRAWS};

use crate::error::{Error, Result};
use crate::fit::LawFit;
use crate::laws::{Law, MAX_PARAMS, ParamSpec};
use crate::rng::{candidate_counter, key_of_seed, philox4x32_10, uniform_between};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The uniform box of one law, SI (torques N·m), as the f32 values candidates are drawn with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LawBox {
    pub law: Law,
    pub lower: Vec<f32>,
    pub upper: Vec<f32>,
    /// Where the law's prior is the box cut to curves within the record's torques (the
    /// evidence's, for a law whose file says so); `None`: the box alone. (Always written:
    /// the workers read a problem in postcard, which does not describe itself.)
    #[serde(default)]
    pub curve: Option<CurveLimit>,
}

impl LawBox {
    /// The box of `law` from `lower` to `upper` (SI), uniform.
    pub fn new(law: Law, lower: Vec<f32>, upper: Vec<f32>) -> Self {
        Self {
            law,
            lower,
            upper,
            curve: None,
        }
    }

    /// True when `params` (SI) lie in the law's prior: inside the box and, where the prior is
    /// cut, within its [`CurveLimit`].
    pub fn admits(&self, params: &[f64]) -> bool {
        let as_f32: Vec<f32> = params.iter().map(|&v| v as f32).collect();
        self.contains(params) && self.curve.as_ref().is_none_or(|c| c.holds(self.law, &as_f32))
    }

    /// [`Self::admits`] for the f32 parameters a candidate carries, compared with the box's
    /// ends as drawn.
    pub fn admits_f32(&self, params: &[f32]) -> bool {
        params
            .iter()
            .zip(self.lower.iter().zip(&self.upper))
            .all(|(p, (lo, hi))| p >= lo && p <= hi)
            && self.curve.as_ref().is_none_or(|c| c.holds(self.law, params))
    }

    /// True when `params` lie inside the box (ends included); a [`CurveLimit`] is not asked.
    pub fn contains(&self, params: &[f64]) -> bool {
        params
            .iter()
            .zip(self.lower.iter().zip(&self.upper))
            .all(|(&p, (&a, &b))| p >= f64::from(a) && p <= f64::from(b))
    }
}

/// Which rule made a parameter's box.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BoxRule {
    /// The paper's φ̂(1 ± δ), clipped to the physical bound.
    Delta,
    /// φ̂(1 ± δ), but the data do not identify φ̂ (a standard error above |φ̂|, or none because
    /// parameters trade off): the box, not the data, sets the spread.
    DeltaNotIdentified,
    /// φ̂ ± δ·s with s the record's scale of the parameter: φ̂ is 0 or on its physical bound,
    /// where δ·|φ̂| gives no width.
    RecordScale,
    /// φ̂ ± k·σ̂ with σ̂ the least-squares standard error (`--prior-rule stderr`), clipped to
    /// the physical bound: a width set by what the data determine, not by |φ̂|.
    StdErr,
    /// Given explicitly (a `--prior` file, or a box built by a program).
    Given,
    /// k times the record's physical scale of the parameter from its physical bound (or ±k
    /// scales where it has none): no fit involved ([`Prior::physical`]).
    Physical,
    /// Not recorded: a run store of schema version 1 kept the boxes but not their rules.
    Unrecorded,
}

impl BoxRule {
    /// A short name for tables and stores.
    pub fn name(self) -> &'static str {
        match self {
            BoxRule::Delta => "delta",
            BoxRule::DeltaNotIdentified => "delta_not_identified",
            BoxRule::RecordScale => "record_scale",
            BoxRule::StdErr => "stderr",
            BoxRule::Given => "given",
            BoxRule::Physical => "physical",
            BoxRule::Unrecorded => "unrecorded",
        }
    }

    /// Every rule.
    pub const ALL: [BoxRule; 7] = [
        BoxRule::Delta,
        BoxRule::DeltaNotIdentified,
        BoxRule::RecordScale,
        BoxRule::StdErr,
        BoxRule::Given,
        BoxRule::Physical,
        BoxRule::Unrecorded,
    ];

    /// The rule of a stored name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|r| r.name() == name)
    }
}

/// How the boxes around the least-squares estimates are sized (`--prior-rule`).
///
/// The paper's rule scales each box with |φ̂|, so a law whose parameters happen to be large
/// (or whose prediction is sensitive to a large parameter) gets a box that spans more misfit,
/// and ABC, which rewards the share of a law's box below ε, penalises it for the size of its
/// numbers rather than for its fit. `StdErr` sizes every box by what the record determines
/// instead: k standard errors of the least-squares estimate, so that every law's box covers
/// about the same region of its own likelihood.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "rule", rename_all = "lowercase")]
pub enum PriorRule {
    /// The paper's φ̂(1 ± δ) (with the fallbacks of the module documentation).
    #[default]
    Delta,
    /// φ̂ ± k·σ̂, clipped to the physical bound; where σ̂ is undefined (a parameter on its
    /// bound, or two that trade off) or zero, the δ rule's box.
    Stderr { k: f64 },
}

impl PriorRule {
    /// Refuses a k that gives no box, naming the flag.
    pub fn validate(&self) -> Result<()> {
        match *self {
            PriorRule::Delta => Ok(()),
            PriorRule::Stderr { k } if k.is_finite() && k > 0.0 => Ok(()),
            PriorRule::Stderr { k } => Err(Error::setting("prior_k", format!("must be a positive number, got {k}"))),
        }
    }
}

/// Relative distance from a physical bound (in units of the record's scale) within which an
/// estimate is taken to sit on it; the least-squares fit uses the same threshold.
const ON_BOUND: f64 = 1e-6;

/// The most laws one prior (one run) compares: the kernels' prior holds this many slots.
pub const MAX_LAWS: usize = 8;

/// A prior over (law, parameters).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Prior {
    /// One box per law considered, in the order laws were given.
    pub boxes: Vec<LawBox>,
    /// The rule that made each parameter's box, per box.
    pub rules: Vec<Vec<BoxRule>>,
    /// Prior law probabilities, normalised, in the order of `boxes`.
    pub weights: Vec<f64>,
    /// Law k is chosen when the first Philox word is below `thresholds[k]` (and not below the
    /// previous one); the last threshold is 2³². Integer comparison: identical on every backend.
    pub thresholds: Vec<u64>,
}

/// The sizes a record gives a law's parameters without any fit: how large a torque it holds
/// and over which speeds. A parameter's unit scale is, by its dimension torque^t·(rad/s)^(−s):
///
/// - a torque (t = 1, s = 0: a static or dynamic torque, a bump's amplitude): a fifth of the
///   largest recorded torque, so that k = 10 scales reach twice it;
/// - a polynomial coefficient (t = 1, s > 0): the largest torque over the fastest speed to the
///   power s, so that at k scales its term alone reaches k times the largest torque at the
///   fastest speed. Narrower cuts real fits: a cubic's least-squares fits on stick-slip records
///   have terms of up to three times the largest torque and more that cancel one another;
/// - a rate or a width (t = 0, s > 0: exp(−g·w), tanh(b·w), a bump's 1/width²): one over the
///   slowest recorded speeds to the power s (as sharp as the record resolves);
/// - a speed (s < 0, a bump's centre): a tenth of the fastest speed, its box from a tenth of
///   its width below 0, so that k = 10 scales keep it within the recorded speeds and a peak at
///   rest (a centre far below 0 would let a Gaussian's tail pose as another law's decay).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PhysicalScales {
    /// Largest |torque| of the record, N·m.
    pub torque_max: f64,
    /// 5th percentile of the bit speed, rad/s (the slowest speeds the record resolves).
    pub speed_low: f64,
    /// Largest bit speed, rad/s.
    pub speed_high: f64,
}

impl PhysicalScales {
    /// The scales of `samples` (speeds in rad/s, torques in N·m).
    pub fn of(samples: &crate::data::Samples) -> Self {
        let torque_max = samples.torque_nm.iter().fold(0.0f64, |m, y| m.max(y.abs()));
        let speed_high = samples.speed_rad_s.iter().fold(0.0f64, |m, &w| m.max(w));
        let speed_low = crate::numerics::quantile(&samples.speed_rad_s, 0.05);
        let floor = f64::MIN_POSITIVE;
        Self {
            torque_max: torque_max.max(floor),
            speed_low: speed_low.max(speed_high * 1e-6).max(floor),
            speed_high: speed_high.max(floor),
        }
    }

    /// The scale of parameter `j` of `law`, SI (see the type's documentation).
    pub fn param_scale(&self, law: Law, j: usize) -> f64 {
        let spec = law.params()[j];
        let (t, s) = (spec.torque_power, spec.inverse_speed_power);
        match (t, s) {
            (0, s) if s > 0 => 1.0 / self.speed_low.powi(s),
            (_, s) if s < 0 => self.torque_max.powi(t) * self.speed_high.powi(-s) / 10.0,
            (1, 0) => self.torque_max / 5.0,
            (t, s) => self.torque_max.powi(t) / self.speed_high.powi(s),
        }
    }

    /// The box of parameter `j` of `law` at `k` scales (before clipping): from its physical
    /// bound up; a speed (a bump's centre) from a tenth of its width below 0 (a peak at rest,
    /// resolved on both sides) up, since records turn forwards; symmetric about 0 for another
    /// free parameter.
    fn physical_box(&self, law: Law, j: usize, k: f64) -> (f64, f64, BoxRule) {
        let spec = law.params()[j];
        let width = k * self.param_scale(law, j);
        // A law file's upper bound ends the box where it comes first (the caller clips).
        if spec.lower.is_finite() {
            (spec.lower, spec.lower + width, BoxRule::Physical)
        } else if spec.upper.is_finite() {
            (spec.upper - width, spec.upper, BoxRule::Physical)
        } else if spec.inverse_speed_power < 0 {
            (-0.1 * width, width, BoxRule::Physical)
        } else {
            (-width, width, BoxRule::Physical)
        }
    }
}

/// Most coordinates a prior box has: a law's parameters ([`MAX_PARAMS`]) and, where a run
/// infers the drill string with the law (`bitrock surface`), its natural frequency and damping
/// ratio after them.
pub const MAX_DIMS: usize = MAX_PARAMS + 2;

/// Draws of a box whose prior is cut to a curve ([`CurveLimit`]) tried for one candidate: a
/// cut keeps at least [`MIN_INSIDE`] of [`SHARE_DRAWS`] of its box, so all of them miss with
/// probability below e⁻¹⁰⁰.
const MAX_CURVE_ATTEMPTS: u32 = 1 << 16;

/// Where a candidate's draws again inside a curve's limit take their counter blocks: draw
/// a (from 1) takes the four from `CURVE_BLOCKS + 4a` (blocks 0..2 are its first draw's).
const CURVE_BLOCKS: u32 = 4;

/// A candidate drawn from the prior: which box (index into [`Prior::boxes`]) and its
/// coordinates (the law's parameters first; unused ones 0).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Candidate {
    pub slot: usize,
    pub params: [f32; MAX_DIMS],
}

impl Candidate {
    /// The coordinates widened exactly to f64 (unused ones 0), on the stack: what the f64
    /// twins evaluate, with no allocation per candidate.
    pub fn widened(&self) -> [f64; MAX_DIMS] {
        self.params.map(f64::from)
    }

    /// The first [`MAX_PARAMS`] coordinates as f32: what a GPU proposal carries (a law's
    /// parameters; the GPU scores boxes of a law's parameters only).
    pub fn law_params(&self) -> [f32; MAX_PARAMS] {
        std::array::from_fn(|j| self.params[j])
    }
}

/// The contents of a prior TOML file (see the module documentation).
#[derive(Clone, Debug, Default, Deserialize)]
pub struct PriorFile {
    #[serde(default)]
    pub weights: BTreeMap<String, f64>,
    /// Per law (`[m2]`, or a law file's law by its name), bounds by parameter name.
    #[serde(flatten)]
    pub bounds: BTreeMap<String, BTreeMap<String, Vec<f64>>>,
}

impl PriorFile {
    /// Reads and checks a prior file; errors name the file and, for TOML syntax, line and column.
    pub fn read(path: &Path) -> Result<Self> {
        Self::parse(&Self::read_text(path)?, path)
    }

    /// The text of the prior file at `path`, refused when it is too large to be one.
    pub fn read_text(path: &Path) -> Result<String> {
        crate::files::read_text(path, "a prior file", crate::limits::MAX_SETTINGS_FILE_BYTES)
    }

    /// Checks the text of a prior file read from `path` (named in errors); see [`Self::read`].
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let file: PriorFile = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| text[..s.start].lines().count().max(1) as u64);
            Error::Format {
                path: path.to_path_buf(),
                line,
                message: e.message().to_string(),
            }
        })?;
        for (table, bounds) in &file.bounds {
            let law = table.parse::<Law>().map_err(|m| Error::Format {
                path: path.to_path_buf(),
                line: None,
                message: format!("[{table}]: {m}"),
            })?;
            for (name, bound) in bounds {
                if bound.len() != 2 {
                    return Err(Error::Format {
                        path: path.to_path_buf(),
                        line: None,
                        message: format!("[{law}] {name} has {} values; a bound is [lower, upper]", bound.len()),
                    });
                }
                if !law.param_names().contains(&name.as_str()) {
                    return Err(Error::Format {
                        path: path.to_path_buf(),
                        line: None,
                        message: format!(
                            "[{law}] has no parameter '{name}' (it has {})",
                            law.param_names().join(", ")
                        ),
                    });
                }
            }
        }
        for (name, &w) in &file.weights {
            let known = name.parse::<Law>().map_err(|m| Error::Format {
                path: path.to_path_buf(),
                line: None,
                message: format!("[weights]: {m}"),
            })?;
            if !(w.is_finite() && w >= 0.0) {
                return Err(Error::Format {
                    path: path.to_path_buf(),
                    line: None,
                    message: format!("[weights] {known} = {w}: a weight must be finite and ≥ 0"),
                });
            }
        }
        Ok(file)
    }

    /// The file that gives `prior`'s explicit boxes ([`BoxRule::Given`]) and its law weights,
    /// torque-valued bounds in units of `torque_unit_nm` N·m: what a run store keeps of the
    /// `--prior` file the run was made with (the store holds the prior, not the file). The
    /// boxes come back as the same f32 values; the weights are the normalised ones.
    pub fn of_prior(prior: &Prior, torque_unit_nm: f64) -> Self {
        let mut file = PriorFile::default();
        for ((bx, rules), &weight) in prior.boxes.iter().zip(&prior.rules).zip(&prior.weights) {
            file.weights.insert(bx.law.name().to_string(), weight);
            let given = bx.law.params().iter().zip(&bx.lower).zip(&bx.upper).zip(rules);
            let bounds: BTreeMap<String, Vec<f64>> = given
                .filter(|(_, rule)| **rule == BoxRule::Given)
                .map(|(((spec, &lo), &hi), _)| {
                    let unit = if spec.torque_power == 1 { torque_unit_nm } else { 1.0 };
                    (spec.name.to_string(), vec![f64::from(lo) / unit, f64::from(hi) / unit])
                })
                .collect();
            if !bounds.is_empty() {
                file.bounds.insert(bx.law.name().to_string(), bounds);
            }
        }
        file
    }

    /// The bounds the file gives for `law` (none where it has no table for it).
    fn bounds(&self, law: Law) -> Option<&BTreeMap<String, Vec<f64>>> {
        self.bounds.get(law.name())
    }
}

impl Prior {
    /// The paper's prior: laws weighted uniformly (or by `file`), boxes φ̂(1 ± δ) around each
    /// fit, clipped to physical bounds, replaced where `file` gives explicit bounds.
    /// `torque_unit_nm` is N·m per unit of the file's torque-valued bounds.
    pub fn from_fits(fits: &[LawFit], delta: f64, file: Option<&PriorFile>, torque_unit_nm: f64) -> Result<Self> {
        Self::from_fits_by(fits, PriorRule::Delta, delta, file, torque_unit_nm)
    }

    /// As [`Prior::from_fits`], with the boxes sized by `rule` (δ is the fallback of
    /// [`PriorRule::Stderr`] where a standard error is undefined).
    pub fn from_fits_by(
        fits: &[LawFit],
        rule: PriorRule,
        delta: f64,
        file: Option<&PriorFile>,
        torque_unit_nm: f64,
    ) -> Result<Self> {
        rule.validate()?;
        if !(delta.is_finite() && delta > 0.0) {
            return Err(Error::setting(
                "delta",
                format!("must be a positive number, got {delta}"),
            ));
        }
        let laws: Vec<Law> = fits.iter().map(|f| f.law).collect();
        Self::from_boxes_by(&laws, file, torque_unit_nm, "delta", delta, |k, j| match rule {
            PriorRule::Delta => delta_box(&fits[k], j, delta),
            PriorRule::Stderr { k: width } => {
                stderr_box(&fits[k], j, width).unwrap_or_else(|| delta_box(&fits[k], j, delta))
            }
        })
    }

    /// Boxes that use no fit: parameter j of a law spans `k` times its record scale from its
    /// physical bound ([`BoxRule::Physical`], see [`PhysicalScales`]), replaced where `file`
    /// gives explicit bounds. The prior of a model evidence, which must not look at the data
    /// twice: a box centred on the least-squares estimate of the same record rewards each law
    /// for where the data put it.
    pub fn physical(
        laws: &[Law],
        scales: &PhysicalScales,
        k: f64,
        file: Option<&PriorFile>,
        torque_unit_nm: f64,
    ) -> Result<Self> {
        if !(k.is_finite() && k > 0.0) {
            return Err(Error::setting(
                "prior_scale",
                format!("must be a positive number, got {k}"),
            ));
        }
        Self::from_boxes_by(laws, file, torque_unit_nm, "prior_scale", k, |i, j| {
            scales.physical_box(laws[i], j, k)
        })
    }

    /// The prior of `laws` whose boxes come from `file` where it gives them and from
    /// `rule_box(law's position, parameter)` elsewhere, clipped to the physical bounds;
    /// `setting` (with its `value`) is what a refused box of the rule names.
    fn from_boxes_by(
        laws: &[Law],
        file: Option<&PriorFile>,
        torque_unit_nm: f64,
        setting: &str,
        value: f64,
        rule_box: impl Fn(usize, usize) -> (f64, f64, BoxRule),
    ) -> Result<Self> {
        let mut boxes = Vec::new();
        let mut rules = Vec::new();
        let mut weights = Vec::new();
        for (k, &law) in laws.iter().enumerate() {
            let explicit = file.and_then(|f| f.bounds(law));
            let mut lower = Vec::new();
            let mut upper = Vec::new();
            let mut law_rules = Vec::new();
            for (j, spec) in law.params().iter().enumerate() {
                let (lo, hi, rule) = if let Some(&[a, b]) = explicit.and_then(|m| m.get(spec.name)).map(Vec::as_slice) {
                    let unit = if spec.torque_power == 1 { torque_unit_nm } else { 1.0 };
                    if !(a.is_finite() && b.is_finite() && a < b) {
                        return Err(Error::setting(
                            "prior",
                            format!(
                                "[{law}] {} = [{a}, {b}]: need finite bounds with lower < upper",
                                spec.name
                            ),
                        ));
                    }
                    (a * unit, b * unit, BoxRule::Given)
                } else {
                    rule_box(k, j)
                };
                let (lo, hi) = (lo.max(spec.lower), hi.min(spec.upper));
                if rule == BoxRule::Given && lo >= hi {
                    let unit = if spec.torque_power == 1 { torque_unit_nm } else { 1.0 };
                    return Err(Error::setting(
                        "prior",
                        format!(
                            "[{law}] {}: the bounds lie outside its physical bounds {} {} (in the file's units); give bounds within them",
                            spec.name,
                            spec.name,
                            ParamSpec {
                                lower: spec.lower / unit,
                                upper: spec.upper / unit,
                                ..*spec
                            }
                            .bounds_text()
                        ),
                    ));
                }
                check_box_reach(law, spec.name, lo, hi, rule, setting, value)?;
                if lo >= hi {
                    return Err(Error::setting(
                        setting,
                        format!(
                            "{law}.{}: the box [{lo}, {hi}] (SI) is empty after clipping to the physical bounds {} {}; give explicit bounds in a `prior` file",
                            spec.name,
                            spec.name,
                            spec.bounds_text()
                        ),
                    ));
                }
                lower.push(lo as f32);
                upper.push(hi as f32);
                law_rules.push(rule);
            }
            boxes.push(LawBox::new(law, lower, upper));
            rules.push(law_rules);
            weights.push(file.and_then(|f| f.weights.get(law.name()).copied()).unwrap_or(1.0));
        }
        let mut prior = Self::new(boxes, weights)?;
        prior.rules = rules;
        Ok(prior)
    }

    /// The prior with each law whose file sets `prior_curve_within` cut to the curves within
    /// that many times the record's largest torque, from rest to its fastest speed
    /// ([`CurveLimit`]): the evidence's physical prior.
    pub fn with_curve_limits(mut self, scales: &PhysicalScales) -> Result<Self> {
        for bx in &mut self.boxes {
            if let Some(within) = bx.law.prior_curve_within() {
                bx.curve = Some(CurveLimit::new(
                    bx.law,
                    within,
                    scales.torque_max,
                    scales.speed_high,
                    (&bx.lower, &bx.upper),
                )?);
            }
        }
        Ok(self)
    }

    /// A prior from explicit boxes (SI) and unnormalised law weights.
    pub fn new(boxes: Vec<LawBox>, weights: Vec<f64>) -> Result<Self> {
        if boxes.is_empty() {
            return Err(Error::setting("laws", "no law to sample"));
        }
        if boxes.len() > MAX_LAWS {
            return Err(Error::setting(
                "laws",
                format!("{} laws given; a run compares at most {MAX_LAWS}", boxes.len()),
            ));
        }
        let total: f64 = weights.iter().sum();
        if !(total.is_finite() && total > 0.0) {
            return Err(Error::setting("prior", "the law weights sum to zero"));
        }
        let weights: Vec<f64> = weights.iter().map(|w| w / total).collect();
        let mut cumulative = 0.0;
        let mut thresholds: Vec<u64> = weights
            .iter()
            .map(|w| {
                cumulative += w;
                ((cumulative * 4_294_967_296.0).round() as u64).min(1 << 32)
            })
            .collect();
        *thresholds.last_mut().expect("non-empty") = 1 << 32;
        let rules = boxes.iter().map(|b| vec![BoxRule::Given; b.lower.len()]).collect();
        Ok(Self {
            boxes,
            rules,
            weights,
            thresholds,
        })
    }

    /// Candidate `index` of population `population` in the stream of `seed`.
    ///
    /// Block 0 of the counter gives the law (word 0) and parameters 0..2 (words 1..3), block 1
    /// parameters 3..5, block 2 coordinates 6..7 (a box of more than six). Parameter j =
    /// [`uniform_between`]`(lower, upper, word)`, bit-identical on every backend. A box cut
    /// to a curve ([`CurveLimit`]) is drawn again, from blocks 8 on, until its curve keeps
    /// the limit: uniform on what the limit keeps. (The GPU's own candidates, those of
    /// rejection ABC's kernels, are of boxes without a curve: a run whose prior is cut scores
    /// the host's.)
    #[inline]
    pub fn candidate(&self, seed: u64, population: u32, index: u64) -> Candidate {
        let key = key_of_seed(seed);
        let b0 = philox4x32_10(candidate_counter(population, index, 0), key);
        let slot = self.slot_of_word(u64::from(b0[0]));
        let bx = &self.boxes[slot];
        let n = bx.lower.len();
        let mut words = [b0[1], b0[2], b0[3], 0, 0, 0, 0, 0];
        if n > 3 {
            let b1 = philox4x32_10(candidate_counter(population, index, 1), key);
            words[3..6].copy_from_slice(&b1[..3]);
        }
        if n > 6 {
            let b2 = philox4x32_10(candidate_counter(population, index, 2), key);
            words[6..].copy_from_slice(&b2[..2]);
        }
        let mut params = [0.0f32; MAX_DIMS];
        for j in 0..n {
            params[j] = uniform_between(bx.lower[j], bx.upper[j], words[j]);
        }
        if let Some(curve) = &bx.curve {
            // Uniform on the box cut to the curve: the box drawn again, from blocks of the
            // counter past the first draw's, until its curve keeps the limit.
            let mut attempt = 1;
            while !curve.holds(bx.law, &params[..n]) && attempt < MAX_CURVE_ATTEMPTS {
                for (block, chunk) in (0..n).step_by(4).enumerate() {
                    let words = philox4x32_10(
                        candidate_counter(population, index, CURVE_BLOCKS + attempt * 4 + block as u32),
                        key,
                    );
                    for (j, &word) in (chunk..n.min(chunk + 4)).zip(&words) {
                        params[j] = uniform_between(bx.lower[j], bx.upper[j], word);
                    }
                }
                attempt += 1;
            }
        }
        Candidate { slot, params }
    }

    /// The box (law) of candidate `index`: the first Philox block only, for counting draws.
    #[inline]
    pub fn candidate_slot(&self, seed: u64, population: u32, index: u64) -> usize {
        let word = u64::from(philox4x32_10(candidate_counter(population, index, 0), key_of_seed(seed))[0]);
        self.slot_of_word(word)
    }

    #[inline]
    fn slot_of_word(&self, word: u64) -> usize {
        self.thresholds
            .iter()
            .position(|&t| word < t)
            .unwrap_or(self.boxes.len() - 1)
    }

    /// The prior with `lower..=upper` appended to every law's box: coordinates a run infers
    /// with each law's parameters (the string's, for `bitrock surface`), uniform and
    /// independent of them. A coordinate whose bounds are equal is held at that value.
    pub fn with_coordinates(mut self, lower: &[f32], upper: &[f32]) -> Self {
        assert_eq!(lower.len(), upper.len(), "a lower and an upper bound per coordinate");
        for bx in &mut self.boxes {
            assert!(
                bx.lower.len() + lower.len() <= MAX_DIMS,
                "at most {MAX_DIMS} coordinates"
            );
            bx.lower.extend_from_slice(lower);
            bx.upper.extend_from_slice(upper);
        }
        for rules in &mut self.rules {
            rules.extend(std::iter::repeat_n(BoxRule::Given, lower.len()));
        }
        self
    }

    /// The laws of the boxes, in slot order.
    pub fn laws(&self) -> impl Iterator<Item = Law> + '_ {
        self.boxes.iter().map(|b| b.law)
    }

    /// The law of box `slot`.
    pub fn law(&self, slot: usize) -> Law {
        self.boxes[slot].law
    }

    /// The slot of `law`'s box; a law outside the prior is a caller's error.
    pub fn slot_of(&self, law: Law) -> usize {
        self.boxes
            .iter()
            .position(|b| b.law == law)
            .expect("the law is in the prior")
    }
}

/// Refuses a box that f32 candidates cannot span (an end beyond f32's range, as δ = 1e100
/// makes) and a δ box that crosses 0 (δ ≥ 1 on a parameter without a physical bound): it
/// would hold values of the sign opposite to the estimate, another law shape than the fit's.
fn check_box_reach(law: Law, name: &str, lo: f64, hi: f64, rule: BoxRule, setting: &str, delta: f64) -> Result<()> {
    let field = if rule == BoxRule::Given { "prior" } else { setting };
    if !((lo as f32).is_finite() && (hi as f32).is_finite()) {
        return Err(Error::setting(
            field,
            format!(
                "{law}.{name}: the box [{lo:e}, {hi:e}] (SI) has an end beyond what candidates (f32, ±3.4e38) can hold; narrow it"
            ),
        ));
    }
    if matches!(rule, BoxRule::Delta | BoxRule::DeltaNotIdentified) && lo < 0.0 && hi > 0.0 {
        return Err(Error::setting(
            "delta",
            format!(
                "{law}.{name}: δ = {delta} makes the box [{lo:e}, {hi:e}] (SI) cross 0, so it holds values of the sign opposite to the estimate; use δ < 1, or give the box in a `prior` file"
            ),
        ));
    }
    Ok(())
}

/// The box of parameter `j` of `fit` by the δ rules of the module documentation (before
/// clipping to the physical bound): (lower, upper, rule), SI.
fn delta_box(fit: &LawFit, j: usize, delta: f64) -> (f64, f64, BoxRule) {
    let spec = fit.law.params()[j];
    let estimate = fit.params_si[j];
    let scale = fit.scales.param_scale(fit.law, j);
    // Zero width: an estimate of 0 (or one the record's scale cannot tell from 0), or one on
    // its physical bound (the data push it further, so its size says nothing).
    let on_bound = (spec.lower.is_finite() && (estimate - spec.lower) <= ON_BOUND * scale)
        || (spec.upper.is_finite() && (spec.upper - estimate) <= ON_BOUND * scale);
    if on_bound || estimate.abs() <= ON_BOUND * scale {
        return (estimate - delta * scale, estimate + delta * scale, BoxRule::RecordScale);
    }
    let (a, b) = (estimate * (1.0 - delta), estimate * (1.0 + delta));
    let identified = fit.std_errors_si[j].is_some_and(|se| se <= estimate.abs());
    let rule = if identified {
        BoxRule::Delta
    } else {
        BoxRule::DeltaNotIdentified
    };
    (a.min(b), a.max(b), rule)
}

/// The box φ̂ ± k·σ̂ of parameter `j` of `fit` (before clipping), or `None` where the standard
/// error is undefined or zero.
fn stderr_box(fit: &LawFit, j: usize, k: f64) -> Option<(f64, f64, BoxRule)> {
    let estimate = fit.params_si[j];
    let half = k * fit.std_errors_si[j].filter(|se| se.is_finite() && *se > 0.0)?;
    Some((estimate - half, estimate + half, BoxRule::StdErr))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::RecordScales;

    fn fit(law: Law, params: Vec<f64>) -> LawFit {
        LawFit::for_tests(law, params, 0.0)
    }

    #[test]
    fn delta_boxes_are_ordered_and_clipped() {
        let m4 = fit(Law::M4, vec![11.8, -0.93, 0.057, -1.2e-3]);
        let p = Prior::from_fits(&[m4], 0.4, None, 1.0).unwrap();
        let b = &p.boxes[0];
        assert_eq!(b.lower[1].to_bits(), ((-0.93f64 * 1.4) as f32).to_bits());
        assert_eq!(b.upper[1].to_bits(), ((-0.93f64 * 0.6) as f32).to_bits());
        // δ > 1 would make the static torque negative: clipped at its bound 0.
        let m2 = fit(Law::M2, vec![13.0, 6.5, 0.3]);
        let p = Prior::from_fits(&[m2], 1.5, None, 1.0).unwrap();
        assert_eq!(p.boxes[0].lower, vec![0.0, 0.0, 0.0]);
        assert_eq!(p.boxes[0].upper[0].to_bits(), 32.5f32.to_bits());
    }

    #[test]
    fn refusals_name_the_flag() {
        let m2 = fit(Law::M2, vec![13.0, 6.5, 0.3]);
        assert!(
            Prior::from_fits(std::slice::from_ref(&m2), 0.0, None, 1.0)
                .unwrap_err()
                .to_string()
                .starts_with("`delta`:")
        );
    }

    #[test]
    fn zero_and_on_bound_estimates_get_boxes_of_the_record_scale() {
        // Torque scale 3 N·m, speed scale 20 rad/s: a2 (rad/s) has scale 20, tcb (N·m) 3.
        let scales = RecordScales {
            torque: 3.0,
            speed: 20.0,
        };
        let mut m3 = fit(Law::M3, vec![2.72, 1.0, 0.0, 9.52, 4.0, 0.08]);
        m3.scales = scales;
        m3.std_errors_si = vec![Some(0.1); 6];
        let mut m2 = fit(Law::M2, vec![3.0, 0.0, 0.3]);
        m2.scales = scales;
        m2.std_errors_si = vec![Some(0.1), None, Some(0.01)];
        let p = Prior::from_fits(&[m3, m2], 0.4, None, 1.0).unwrap();
        // a2 = 0 is free: ±δ·20 rad/s.
        assert_eq!(p.boxes[0].lower[2].to_bits(), (-8.0f32).to_bits());
        assert_eq!(p.boxes[0].upper[2].to_bits(), 8.0f32.to_bits());
        assert_eq!(p.rules[0][2], BoxRule::RecordScale);
        // tcb = 0 sits on its bound 0: [0, δ·3 N·m].
        assert_eq!(p.boxes[1].lower[1].to_bits(), 0.0f32.to_bits());
        assert_eq!(p.boxes[1].upper[1].to_bits(), (1.2f64 as f32).to_bits());
        assert_eq!(p.rules[1][1], BoxRule::RecordScale);
        // The others keep the paper's box; a5's standard error (0.1) exceeds 0.08.
        assert_eq!(p.rules[0], {
            use BoxRule::*;
            vec![Delta, Delta, RecordScale, Delta, Delta, DeltaNotIdentified]
        });
        assert_eq!(p.boxes[0].lower[0].to_bits(), ((2.72f64 * 0.6) as f32).to_bits());
        assert_eq!(p.rules[1][0], BoxRule::Delta);
    }

    #[test]
    fn stderr_boxes_span_k_standard_errors_and_fall_back_to_delta_where_undefined() {
        let mut m2 = fit(Law::M2, vec![13.0, 6.5, 0.3]);
        m2.std_errors_si = vec![Some(0.5), None, Some(0.25)];
        let p = Prior::from_fits_by(&[m2], PriorRule::Stderr { k: 3.0 }, 0.4, None, 1.0).unwrap();
        // tsb: 13 ± 1.5; g: 0.3 ± 0.75 clipped at its bound 0; tcb has no σ̂: the δ box.
        assert_eq!(p.boxes[0].lower, vec![11.5, (6.5f64 * 0.6) as f32, 0.0]);
        assert_eq!(p.boxes[0].upper, vec![14.5, (6.5f64 * 1.4) as f32, 1.05]);
        assert_eq!(
            p.rules[0],
            vec![BoxRule::StdErr, BoxRule::DeltaNotIdentified, BoxRule::StdErr]
        );
        // The box does not scale with |φ̂|: the same σ̂ gives the same width at 10× the estimate.
        let mut big = fit(Law::M2, vec![130.0, 65.0, 3.0]);
        big.std_errors_si = vec![Some(0.5); 3];
        let q = Prior::from_fits_by(&[big], PriorRule::Stderr { k: 3.0 }, 0.4, None, 1.0).unwrap();
        assert_eq!((q.boxes[0].upper[0] - q.boxes[0].lower[0]).to_bits(), 3.0f32.to_bits());
        let zero_k = Prior::from_fits_by(
            &[fit(Law::M2, vec![13.0, 6.5, 0.3])],
            PriorRule::Stderr { k: 0.0 },
            0.4,
            None,
            1.0,
        );
        assert!(zero_k.unwrap_err().to_string().starts_with("`prior_k`:"));
    }

    #[test]
    fn boxes_built_by_programs_are_given_and_rule_names_round_trip() {
        let p = Prior::from_fits(&[fit(Law::M2, vec![13.0, 6.5, 0.3])], 0.4, None, 1.0).unwrap();
        let q = Prior::new(p.boxes.clone(), vec![1.0]).unwrap();
        assert_eq!(q.rules, vec![vec![BoxRule::Given; 3]]);
        for rule in BoxRule::ALL {
            assert_eq!(BoxRule::from_name(rule.name()), Some(rule));
        }
        assert_eq!(BoxRule::from_name("delta "), None);
    }

    #[test]
    fn explicit_bounds_and_weights_override() {
        let file: PriorFile = toml::from_str("[weights]\nm2 = 3.0\n[m2]\ng = [0.1, 0.5]\ntsb = [10, 20]\n").unwrap();
        let fits = [
            fit(Law::M1, vec![5.67, 0.48, 8.79, 4.56]),
            fit(Law::M2, vec![13e3, 6.5e3, 0.3]),
        ];
        let p = Prior::from_fits(&fits, 0.4, Some(&file), 1000.0).unwrap();
        assert_eq!(p.weights, vec![0.25, 0.75]);
        assert_eq!(p.boxes[1].lower, vec![10e3, (6.5e3f64 * 0.6) as f32, 0.1]);
        assert_eq!(p.boxes[1].upper, vec![20e3, (6.5e3f64 * 1.4) as f32, 0.5]);
        assert_eq!(p.thresholds, vec![1 << 30, 1 << 32]);
    }

    #[test]
    fn candidates_are_pure_in_the_box_and_follow_the_weights() {
        let fits = [
            fit(Law::M2, vec![13.0, 6.5, 0.3]),
            fit(Law::M3, vec![2.72, 1.0, 0.09, 9.52, 4.0, 0.08]),
        ];
        let p = Prior::new(Prior::from_fits(&fits, 0.4, None, 1.0).unwrap().boxes, vec![1.0, 3.0]).unwrap();
        let mut count = [0usize; 2];
        for i in 0..40_000u64 {
            let c = p.candidate(9, 2, i);
            assert_eq!(c, p.candidate(9, 2, i));
            count[c.slot] += 1;
            let params: Vec<f64> = c.params[..p.boxes[c.slot].lower.len()]
                .iter()
                .map(|&v| f64::from(v))
                .collect();
            assert!(p.boxes[c.slot].contains(&params));
        }
        // Binomial(40000, 1/4): σ ≈ 87.
        assert!((count[0] as f64 - 10_000.0).abs() < 5.0 * 87.0, "{count:?}");
        assert_ne!(p.candidate(9, 2, 0), p.candidate(9, 3, 0));
        assert_ne!(p.candidate(9, 2, 0), p.candidate(10, 2, 0));
    }

    #[test]
    fn candidates_of_a_box_cut_to_a_curve_are_uniform_on_what_it_keeps() {
        // m4 as c0 + c1·w over speeds 0..1, c0 in [0, 4], c1 in [−4, 4], cut to |T| ≤ 3:
        // c0 ≤ 3 and −3 ≤ c0 + c1 ≤ 3, about half the box. Beside it an uncut m2 box.
        let boxes = vec![
            LawBox::new(Law::M2, vec![1.0, 0.5, 0.0], vec![2.0, 1.0, 1.0]),
            LawBox::new(Law::M4, vec![0.0, -4.0, 0.0, 0.0], vec![4.0, 4.0, 0.0, 0.0]),
        ];
        let uncut = Prior::new(boxes, vec![1.0, 1.0]).unwrap();
        let mut cut = uncut.clone();
        let m4 = &mut cut.boxes[1];
        m4.curve = Some(CurveLimit::new(Law::M4, 3.0, 1.0, 1.0, (&m4.lower, &m4.upper)).unwrap());
        let limit = m4.curve.clone().unwrap();
        let n = 40_000u64;
        let (mut m4_draws, mut first_kept) = (0usize, 0usize);
        let (mut sum_cut, mut sum_sq_cut) = ([0.0f64; 2], [0.0f64; 2]);
        let (mut sum_kept, mut kept) = ([0.0f64; 2], 0usize);
        for i in 0..n {
            let (a, b) = (uncut.candidate(3, 1, i), cut.candidate(3, 1, i));
            // The law is the first word's: the cut leaves the laws' shares as they are.
            assert_eq!(a.slot, b.slot);
            if b.slot == 0 {
                assert_eq!(a, b);
                continue;
            }
            m4_draws += 1;
            assert!(cut.boxes[1].admits_f32(&b.params[..4]), "{b:?}");
            for j in 0..2 {
                let v = f64::from(b.params[j]);
                sum_cut[j] += v;
                sum_sq_cut[j] += v * v;
            }
            // A first draw inside the cut is kept as drawn.
            if limit.holds(Law::M4, &a.params[..4]) {
                assert_eq!(a, b);
                first_kept += 1;
                for (j, sum) in sum_kept.iter_mut().enumerate() {
                    *sum += f64::from(a.params[j]);
                }
                kept += 1;
            }
        }
        // Binomial(40000, 1/2): σ = 100.
        assert!((m4_draws as f64 - 20_000.0).abs() < 500.0, "{m4_draws}");
        assert!((first_kept as f64 / m4_draws as f64 - limit.ln_share.exp()).abs() < 0.02);
        // Uniform on the cut: c0's and c1's means are those of the uncut draws the cut keeps
        // (rejection from the box), within five standard errors of the two means.
        for j in 0..2 {
            let mean_cut = sum_cut[j] / m4_draws as f64;
            let sd = (sum_sq_cut[j] / m4_draws as f64 - mean_cut * mean_cut).sqrt();
            let mean_kept = sum_kept[j] / kept as f64;
            let se = sd * (1.0 / m4_draws as f64 + 1.0 / kept as f64).sqrt();
            assert!(
                (mean_cut - mean_kept).abs() < 5.0 * se,
                "c{j}: {mean_cut} against {mean_kept} ± {se}"
            );
        }
    }

    #[test]
    fn coordinates_appended_to_every_box_leave_the_law_s_draws_the_same() {
        let fits = [
            fit(Law::M2, vec![13.0, 6.5, 0.3]),
            fit(Law::M3, vec![2.72, 1.0, 0.09, 9.52, 4.0, 0.08]),
        ];
        let laws_only = Prior::from_fits(&fits, 0.4, None, 1.0).unwrap();
        // ω_n inferred within [0.5, 2], ξ held at 0.25: m3's two land in block 2's words.
        let with_string = laws_only.clone().with_coordinates(&[0.5, 0.25], &[2.0, 0.25]);
        for ((bx, rules), n) in with_string.boxes.iter().zip(&with_string.rules).zip([3, 6]) {
            assert_eq!((bx.lower.len(), bx.upper.len(), rules.len()), (n + 2, n + 2, n + 2));
        }
        let (mut sum, mut count) = ([0.0f64; 2], [0usize; 2]);
        for i in 0..4_000u64 {
            let (a, b) = (laws_only.candidate(4, 1, i), with_string.candidate(4, 1, i));
            assert_eq!(a.slot, b.slot);
            let n = laws_only.boxes[a.slot].lower.len();
            assert_eq!(a.params[..n], b.params[..n], "candidate {i}");
            assert!(a.params[n..].iter().all(|v| v.to_bits() == 0), "{a:?}");
            let string = &b.params[n..n + 2];
            assert!((0.5..=2.0).contains(&string[0]), "{string:?}");
            assert_eq!(string[1].to_bits(), 0.25f32.to_bits());
            sum[a.slot] += f64::from(string[0]);
            count[a.slot] += 1;
        }
        // Uniform on [0.5, 2] for each law: mean 1.25, σ of the mean 0.43/√n < 0.01.
        for (sum, count) in sum.iter().zip(count) {
            assert!(
                count > 1_000 && (sum / count as f64 - 1.25).abs() < 0.05,
                "{sum} over {count}"
            );
        }
    }
}
