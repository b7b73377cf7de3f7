//! The paper's four bit-rock interaction laws M1..M4: torque on bit T(w), its analytic
//! derivative dT/dw (the section "Stability analysis"), the gradient with respect to the
//! parameters (for least squares) and the physical bounds of each parameter.
//!
//! Every law is scaled by the weight-on-bit ratio r = W / W_ref. Bit speed w is in rad/s.
//! The laws are homogeneous of degree one in their torque-valued parameters, so one set of
//! formulas serves any torque unit: parameters given in kN·m give torques in kN·m.
//! [`ParamSpec::torque_power`] and [`ParamSpec::inverse_speed_power`] carry the dimension of
//! each parameter, which is how the library converts units and rescales problems.
//!
//! A law of the user's own comes from a law file ([`mod@file`]): registered in the process, it is a
//! [`Law::File`] that every method here answers for from its compiled expression (a law file's
//! torque is checked dimensionally, so the same homogeneity holds).

pub mod file;

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A bit-rock interaction law: one of the paper's four, or one read from a law file
/// ([`crate::laws::file`]), named in files and on the command line by its name either way.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(into = "String", try_from = "String")]
pub enum Law {
    /// Tucker & Wang: `r b0 (tanh(b1 w) + b2 w / (1 + b3 w²))`.
    M1,
    /// Navarro-Lopez & Suarez: `r ((tsb - tcb) exp(-g w) + tcb)`.
    M2,
    /// The paper's new law: `r (a0 exp(-a1 (w - a2)²) + a3 - a4 tanh(a5 w))`.
    M3,
    /// Ritto & Aguiar's cubic: `r (c0 + c1 w + c2 w² + c3 w³)`.
    M4,
    /// A law read from a law file and registered in this process ([`crate::laws::file::register`]).
    File(FileLaw),
}

/// The handle of a registered law file: its place in the process's registry. Handles order by
/// their laws' names, so that every process (one that resumes a run registers its laws in
/// another order) lists them alike.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FileLaw(pub(crate) u16);

impl Ord for FileLaw {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        let name = |id: &FileLaw| crate::laws::file::registered(*id).file.name.as_str();
        name(self).cmp(name(other)).then(self.0.cmp(&other.0))
    }
}

impl PartialOrd for FileLaw {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl From<Law> for String {
    fn from(law: Law) -> String {
        law.name().to_string()
    }
}

impl TryFrom<String> for Law {
    type Error = String;
    fn try_from(name: String) -> Result<Self, String> {
        name.parse()
    }
}

/// Name, dimension and physical bound of one parameter of a law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamSpec {
    /// Identifier used on the command line and in every output (`b0`, `tsb`, ...).
    pub name: &'static str,
    /// 1 when the parameter is a torque (or a torque per speed power), 0 when not.
    pub torque_power: i32,
    /// Power of (rad/s)^-1 in the parameter's unit: `g` is s/rad (1), `a1` s²/rad² (2),
    /// `a2` rad/s (-1).
    pub inverse_speed_power: i32,
    /// Smallest physically meaningful value (`f64::NEG_INFINITY` when free).
    pub lower: f64,
    /// Largest physically meaningful value (`f64::INFINITY` when free: every built-in law;
    /// a law file may give one).
    pub upper: f64,
}

impl ParamSpec {
    pub(crate) const fn new(name: &'static str, torque_power: i32, inverse_speed_power: i32, lower: f64) -> Self {
        Self {
            name,
            torque_power,
            inverse_speed_power,
            lower,
            upper: f64::INFINITY,
        }
    }

    /// The spec with the physical upper bound `upper`.
    pub(crate) const fn with_upper(self, upper: f64) -> Self {
        Self { upper, ..self }
    }

    /// The physical bounds as a sentence's part: "≥ 0", "≤ 1", "in [0, 1]" (SI).
    pub fn bounds_text(&self) -> String {
        match (self.lower.is_finite(), self.upper.is_finite()) {
            (true, true) => format!("in [{}, {}]", self.lower, self.upper),
            (true, false) => format!("≥ {}", self.lower),
            (false, true) => format!("≤ {}", self.upper),
            (false, false) => "free".to_string(),
        }
    }

    /// The parameter's unit, written with the given torque unit (`kN·m`, `N·m`).
    pub fn unit(&self, torque_unit: &str) -> String {
        let speed = match self.inverse_speed_power {
            0 => String::new(),
            -1 => "rad/s".to_string(),
            1 => "s/rad".to_string(),
            p => format!("s^{p}/rad^{p}"),
        };
        match (self.torque_power, speed.is_empty()) {
            (0, true) => "1".to_string(),
            (0, false) => speed,
            (_, true) => torque_unit.to_string(),
            (_, false) => format!("{torque_unit}·{speed}"),
        }
    }

    /// True when `value` respects the physical bounds.
    pub fn admits(&self, value: f64) -> bool {
        value >= self.lower && value <= self.upper
    }
}

const FREE: f64 = f64::NEG_INFINITY;

/// The largest torque on bit any parameter set is taken to mean, N·m: 1,000 kN·m, ten times the
/// largest top drives' rated torque. Beyond it a value was almost surely given in N·m where
/// kN·m was read ([`Law::implausible_torque`]).
pub const MAX_BIT_TORQUE_NM: f64 = 1.0e6;

// Bounds (documented in the README, "The laws"):
// - M1: the asymptotic torque r·b0 is positive, b1 is a rate, the hump b2·w/(1+b3 w²) adds
//   torque (b2 ≥ 0) and b3 ≥ 0 keeps its denominator from vanishing.
// - M2: static torque tsb and dynamic torque tcb are positive, the decay rate g is positive.
// - M3: the bump amplitude a0 and its sharpness a1 are non-negative (a1 < 0 is not a bump but
//   a blow-up), the static gain a3 is positive, and a5 ≥ 0 removes the exact symmetry
//   (a4, a5) ↔ (-a4, -a5) of the tanh term. a2 (bump centre) and a4 (tanh amplitude; negative
//   means velocity strengthening) are free.
// - M4: the static torque c0 is positive; the polynomial coefficients are free.
const M1_PARAMS: [ParamSpec; 4] = [
    ParamSpec::new("b0", 1, 0, 0.0),
    ParamSpec::new("b1", 0, 1, 0.0),
    ParamSpec::new("b2", 0, 1, 0.0),
    ParamSpec::new("b3", 0, 2, 0.0),
];
const M2_PARAMS: [ParamSpec; 3] = [
    ParamSpec::new("tsb", 1, 0, 0.0),
    ParamSpec::new("tcb", 1, 0, 0.0),
    ParamSpec::new("g", 0, 1, 0.0),
];
const M3_PARAMS: [ParamSpec; 6] = [
    ParamSpec::new("a0", 1, 0, 0.0),
    ParamSpec::new("a1", 0, 2, 0.0),
    ParamSpec::new("a2", 0, -1, FREE),
    ParamSpec::new("a3", 1, 0, 0.0),
    ParamSpec::new("a4", 1, 0, FREE),
    ParamSpec::new("a5", 0, 1, 0.0),
];
const M4_PARAMS: [ParamSpec; 4] = [
    ParamSpec::new("c0", 1, 0, 0.0),
    ParamSpec::new("c1", 1, 1, FREE),
    ParamSpec::new("c2", 1, 2, FREE),
    ParamSpec::new("c3", 1, 3, FREE),
];

/// The paper's reference weight on bit W_ref (N): every law's torque is scaled by r = W / W_ref,
/// and the paper's estimates hold at W = W_ref.
pub const PAPER_W_REF_N: f64 = 244.2e3;

/// The laws in f32 and the kernels' shared transcendentals (shaders/shared/laws.wgsl), the
/// WGSL twin of this module that a law file's WGSL is compiled against.
pub(crate) const LAWS_WGSL: &str = include_str!("../../shaders/shared/laws.wgsl");

/// The largest number of parameters of any law (M3 has six).
pub const MAX_PARAMS: usize = 6;

impl Law {
    /// All laws in the paper's order.
    pub const ALL: [Law; 4] = [Law::M1, Law::M2, Law::M3, Law::M4];

    /// Position in [`Law::ALL`] (m1 = 0 .. m4 = 3), and 4 + the registry place of a law
    /// file's law: the law id of the WGSL kernels.
    pub fn index(self) -> usize {
        match self {
            Law::M1 => 0,
            Law::M2 => 1,
            Law::M3 => 2,
            Law::M4 => 3,
            Law::File(FileLaw(k)) => Law::ALL.len() + usize::from(k),
        }
    }

    /// The law file behind a law of a law file; `None` for the built-in laws.
    /// How much ρ = Σ(y − T)²/Σy² moves when this law's torque is computed in f32, as the GPU
    /// computes it (parameters, speeds, torques and residuals rounded to f32), instead of f64:
    /// |ρ₃₂ − ρ₆₄| / ρ₆₄ at parameters `p` (SI) on the speeds `w` (rad/s) and torques `y` (N·m),
    /// r = 1. What the law itself loses in f32, whatever the GPU. `None` for the built-in laws,
    /// whose kernels are written for f32 and tested against the CPU twin.
    pub fn f32_rho_error(self, p: &[f64], w: &[f64], y: &[f64]) -> Option<f64> {
        let file = self.file()?;
        let p32: Vec<f32> = p.iter().map(|&v| v as f32).collect();
        // Σy² divides both residual sums alike: their ratio is the ratio of the ρ.
        let (mut exact, mut single) = (0.0f64, 0.0f64);
        for (&w, &y) in w.iter().zip(y) {
            let t64 = file.torque(p, w, 1.0);
            let t32 = file.torque_f32(&p32, w as f32, 1.0);
            exact += (y - t64).powi(2);
            single += f64::from(y as f32 - t32).powi(2);
        }
        Some(if exact > 0.0 {
            (single - exact).abs() / exact
        } else if single == 0.0 {
            0.0
        } else {
            f64::INFINITY
        })
    }

    pub fn file(self) -> Option<&'static crate::laws::file::LawFile> {
        match self {
            Law::File(id) => Some(crate::laws::file::registered(id).file),
            _ => None,
        }
    }

    /// Identifier used on the command line and in outputs.
    pub fn name(self) -> &'static str {
        match self {
            Law::M1 => "m1",
            Law::M2 => "m2",
            Law::M3 => "m3",
            Law::M4 => "m4",
            Law::File(id) => &crate::laws::file::registered(id).file.name,
        }
    }

    /// The law's parameters, in the order used everywhere (CLI, JSON, CSV).
    pub fn params(self) -> &'static [ParamSpec] {
        match self {
            Law::M1 => &M1_PARAMS,
            Law::M2 => &M2_PARAMS,
            Law::M3 => &M3_PARAMS,
            Law::M4 => &M4_PARAMS,
            Law::File(id) => crate::laws::file::registered(id).specs,
        }
    }

    /// Number of parameters.
    pub fn n_params(self) -> usize {
        self.params().len()
    }

    /// Parameter names in order.
    pub fn param_names(self) -> Vec<&'static str> {
        self.params().iter().map(|p| p.name).collect()
    }

    /// The paper's least-squares estimates (eqs. detM1..detM4), or a law file's reference
    /// values where it gives one for every parameter; torques in kN·m, speeds in rad/s.
    pub fn paper_estimate(self) -> Option<&'static [f64]> {
        match self {
            Law::M1 => Some(&[5.67, 0.48, 8.79, 4.56]),
            Law::M2 => Some(&[13.0, 6.5, 0.3]),
            Law::M3 => Some(&[2.72, 1.0, 0.09, 9.52, 4.0, 0.08]),
            Law::M4 => Some(&[11.8, -0.93, 0.057, -1.2e-3]),
            Law::File(id) => crate::laws::file::registered(id).reference_knm,
        }
    }

    /// A short formula for help texts and reports.
    pub fn formula(self) -> &'static str {
        match self {
            Law::M1 => "r·b0·(tanh(b1·w) + b2·w/(1 + b3·w²))",
            Law::M2 => "r·((tsb − tcb)·exp(−g·w) + tcb)",
            Law::M3 => "r·(a0·exp(−a1·(w − a2)²) + a3 − a4·tanh(a5·w))",
            Law::M4 => "r·(c0 + c1·w + c2·w² + c3·w³)",
            Law::File(id) => &crate::laws::file::registered(id).file.formula,
        }
    }

    /// Torque on bit at bit speed `w` (rad/s, w > 0) and weight-on-bit ratio `r`, in the unit
    /// of the torque-valued parameters.
    #[inline]
    pub fn torque(self, p: &[f64], w: f64, r: f64) -> f64 {
        r * match self {
            Law::M1 => p[0] * ((p[1] * w).tanh() + p[2] * w / (1.0 + p[3] * w * w)),
            Law::M2 => (p[0] - p[1]) * (-p[2] * w).exp() + p[1],
            Law::M3 => {
                let d = w - p[2];
                p[0] * (-p[1] * d * d).exp() + p[3] - p[4] * (p[5] * w).tanh()
            }
            Law::M4 => p[0] + w * (p[1] + w * (p[2] + w * p[3])),
            // A law file's torque holds r itself (checked proportional to it).
            Law::File(id) => return crate::laws::file::registered(id).file.torque(p, w, r),
        }
    }

    /// dT/dw at bit speed `w` (rad/s): the paper's analytic derivatives, scaled by `r`.
    /// The unit is the torque unit per rad/s (kN·m·s/rad for the paper's parameters).
    #[inline]
    pub fn dtorque_dw(self, p: &[f64], w: f64, r: f64) -> f64 {
        match self {
            Law::M1 => {
                let t = (p[1] * w).tanh();
                let q = 1.0 + p[3] * w * w;
                -r * p[0] * (p[1] * (t * t - 1.0) - p[2] / q + 2.0 * p[2] * p[3] * w * w / (q * q))
            }
            Law::M2 => -r * (p[0] - p[1]) * p[2] * (-p[2] * w).exp(),
            Law::M3 => {
                let t = (p[5] * w).tanh();
                let d = w - p[2];
                r * (p[4] * p[5] * (t * t - 1.0) + (2.0 * p[2] - 2.0 * w) * p[0] * p[1] * (-p[1] * d * d).exp())
            }
            Law::M4 => r * (p[1] + 2.0 * p[2] * w + 3.0 * p[3] * w * w),
            Law::File(id) => crate::laws::file::registered(id).file.dtorque_dw(p, w, r),
        }
    }

    /// Torque at `w` with r = 1, and its gradient with respect to the parameters written
    /// into `grad` (length = number of parameters). Used by the least-squares Jacobian.
    pub fn torque_and_gradient(self, p: &[f64], w: f64, grad: &mut [f64]) -> f64 {
        match self {
            Law::M1 => {
                let t = (p[1] * w).tanh();
                let q = 1.0 + p[3] * w * w;
                let h = p[2] * w / q;
                grad[0] = t + h;
                grad[1] = p[0] * w * (1.0 - t * t);
                grad[2] = p[0] * w / q;
                grad[3] = -p[0] * p[2] * w * w * w / (q * q);
                p[0] * (t + h)
            }
            Law::M2 => {
                let e = (-p[2] * w).exp();
                grad[0] = e;
                grad[1] = 1.0 - e;
                grad[2] = -(p[0] - p[1]) * w * e;
                (p[0] - p[1]) * e + p[1]
            }
            Law::M3 => {
                let d = w - p[2];
                let e = (-p[1] * d * d).exp();
                let t = (p[5] * w).tanh();
                grad[0] = e;
                grad[1] = -p[0] * d * d * e;
                grad[2] = 2.0 * p[0] * p[1] * d * e;
                grad[3] = 1.0;
                grad[4] = -t;
                grad[5] = -p[4] * w * (1.0 - t * t);
                p[0] * e + p[3] - p[4] * t
            }
            Law::M4 => {
                grad[0] = 1.0;
                grad[1] = w;
                grad[2] = w * w;
                grad[3] = w * w * w;
                p[0] + w * (p[1] + w * (p[2] + w * p[3]))
            }
            Law::File(id) => crate::laws::file::registered(id)
                .file
                .torque_and_gradient(p, w, 1.0, grad),
        }
    }

    /// Converts parameters between torque units: multiplies every torque-valued parameter
    /// by `factor` (1000 turns kN·m parameters into N·m ones).
    pub fn scale_torque(self, p: &[f64], factor: f64) -> Vec<f64> {
        // Values beyond the law's parameters are kept as they are, for the caller's count check.
        let specs = self.params().iter().map(Some).chain(std::iter::repeat(None));
        specs
            .zip(p)
            .map(|(spec, &v)| match spec {
                Some(spec) if spec.torque_power == 1 => v * factor,
                _ => v,
            })
            .collect()
    }

    /// Refuses, naming `flag`, parameters (SI, N·m-based) that this law cannot take: the wrong
    /// count, a value that is not finite, or one outside its physical bounds.
    pub fn check_params(self, params_si: &[f64], field: &str) -> crate::Result<()> {
        let n = self.n_params();
        if params_si.len() != n {
            return Err(crate::Error::setting(
                field,
                format!(
                    "law {self} takes {n} parameters ({}), got {}",
                    self.param_names().join(", "),
                    params_si.len()
                ),
            ));
        }
        for (spec, v) in self.params().iter().zip(params_si) {
            if !v.is_finite() {
                return Err(crate::Error::setting(
                    field,
                    format!("{} must be finite, got {v}", spec.name),
                ));
            }
        }
        if let Some((spec, v)) = self.bound_violation(params_si) {
            return Err(crate::Error::setting(
                field,
                if v < spec.lower {
                    format!(
                        "{} = {v} (SI, N·m-based) is below its physical bound {}",
                        spec.name, spec.lower
                    )
                } else {
                    format!(
                        "{} = {v} (SI, N·m-based) is above its physical bound {}",
                        spec.name, spec.upper
                    )
                },
            ));
        }
        Ok(())
    }

    /// A warning when a torque parameter of `params_si` (N·m) lies beyond any drill bit's
    /// torque ([`MAX_BIT_TORQUE_NM`]): values meant in N·m but read in kN·m put every torque a
    /// thousand times too high, and the maps and traces built on them are silently wrong.
    /// `unit_setting` names the setting that reads them in N·m.
    pub fn implausible_torque(self, params_si: &[f64], unit_setting: &str) -> Option<String> {
        let (spec, v) = self
            .params()
            .iter()
            .zip(params_si)
            .find(|(s, v)| s.torque_power == 1 && s.inverse_speed_power == 0 && v.abs() > MAX_BIT_TORQUE_NM)?;
        Some(format!(
            "{} = {} kN·m lies beyond any drill bit's torque (at most {} kN·m): were the parameters given in N·m? (`{unit_setting}` nm reads them so)",
            spec.name,
            v / 1000.0,
            MAX_BIT_TORQUE_NM / 1000.0
        ))
    }

    /// The first parameter that breaks its physical bound, if any.
    pub fn bound_violation(self, p: &[f64]) -> Option<(&'static ParamSpec, f64)> {
        self.params()
            .iter()
            .zip(p)
            .find(|(s, v)| !s.admits(**v))
            .map(|(s, v)| (s, *v))
    }
}

impl fmt::Display for Law {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Law {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "m1" => Ok(Law::M1),
            "m2" => Ok(Law::M2),
            "m3" => Ok(Law::M3),
            "m4" => Ok(Law::M4),
            other => crate::laws::file::find(other).ok_or_else(|| {
                let files: Vec<&str> = crate::laws::file::registered_laws()
                    .into_iter()
                    .map(Law::name)
                    .collect();
                let known = if files.is_empty() {
                    "m1, m2, m3 or m4, or a law file's law".to_string()
                } else {
                    format!("m1, m2, m3, m4 or a law file's law: {}", files.join(", "))
                };
                format!("unknown law '{other}' (expected {known})")
            }),
        }
    }
}

/// Parses a comma-separated list of laws (`m2,m3`), rejecting duplicates and empty lists.
pub fn parse_law_list(s: &str) -> Result<Vec<Law>, String> {
    let mut laws = Vec::new();
    for part in s.split(',').filter(|p| !p.trim().is_empty()) {
        let law: Law = part.parse()?;
        if laws.contains(&law) {
            return Err(format!("law '{law}' is listed twice"));
        }
        laws.push(law);
    }
    if laws.is_empty() {
        return Err("no law given (expected e.g. m1,m2,m3,m4)".into());
    }
    Ok(laws)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_is_the_position_in_all() {
        for (i, law) in Law::ALL.iter().enumerate() {
            assert_eq!(law.index(), i);
        }
    }

    #[test]
    fn units_read_like_a_paper() {
        let torque = "kN·m";
        assert_eq!(M2_PARAMS[0].unit(torque), "kN·m");
        assert_eq!(M2_PARAMS[2].unit(torque), "s/rad");
        assert_eq!(M3_PARAMS[1].unit(torque), "s^2/rad^2");
        assert_eq!(M3_PARAMS[2].unit(torque), "rad/s");
        assert_eq!(M4_PARAMS[1].unit(torque), "kN·m·s/rad");
    }

    #[test]
    fn law_lists_parse_and_reject_nonsense() {
        assert_eq!(parse_law_list("m2, M3").unwrap(), vec![Law::M2, Law::M3]);
        assert!(parse_law_list("m2,m2").is_err());
        assert!(parse_law_list("m5").unwrap_err().contains("m5"));
        assert!(parse_law_list("").is_err());
    }

    #[test]
    fn paper_estimates_respect_the_bounds() {
        for law in Law::ALL {
            let p = law.paper_estimate().unwrap();
            assert_eq!(p.len(), law.n_params());
            assert!(law.bound_violation(p).is_none(), "{law}");
        }
    }
}
