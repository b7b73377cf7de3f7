//! The bit-rock interaction laws: torque on bit T(w), its derivative dT/dw (the paper's section
//! "Stability analysis"), the gradient with respect to the parameters (for least squares) and
//! the physical bounds of each parameter.
//!
//! The built-in laws (the paper's four, m1..m4) are defined once each, in `laws/<name>.toml`:
//! the build compiles each file into the [`Law`] variant, its entry in the table of names,
//! parameters, units, bounds and estimates, its f64 code here and in the CPU scorer, and its
//! f32 WGSL in the kernels (`build/laws.rs`). Adding a built-in law is adding a file.
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

// The `Law` enum, `BUILT_INS`, `Law::ALL` and the built-in laws' code, written by the build
// from laws/*.toml.
include!(concat!(env!("OUT_DIR"), "/laws.rs"));

/// The colours of law files' laws, in turn: black, a dark yellow, brown and grey, apart from the
/// built-in laws' (Okabe & Ito's reddish purple, orange, bluish green and sky blue) and the
/// data's (its vermillion and blue).
const LAW_FILE_COLOURS: [u32; 4] = [0x000000, 0xb8a000, 0x8c564b, 0x7f7f7f];

/// A built-in law as its file (`laws/<name>.toml`) defines it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BuiltIn {
    pub name: &'static str,
    /// Whose law it is, in words ("Navarro-Lopez & Suarez").
    pub title: &'static str,
    /// The torque as every output prints it.
    pub formula: &'static str,
    pub params: &'static [ParamSpec],
    /// The paper's least-squares estimates, in the kN·m-based units.
    pub paper_estimate: Option<&'static [f64]>,
    /// The law's colour in every figure (0xRRGGBB).
    pub colour: u32,
    /// The evidence's prior keeps the law's curve within this many times the record's largest
    /// torque over its speeds ([`crate::prior::CurveLimit`]); `None`: its boxes alone.
    pub prior_curve_within: Option<f64>,
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
        file::expr::unit_text(self.torque_power, self.inverse_speed_power, torque_unit)
    }

    /// True when `value` respects the physical bounds.
    pub fn admits(&self, value: f64) -> bool {
        value >= self.lower && value <= self.upper
    }
}

/// The largest torque on bit any parameter set is taken to mean, N·m: 1,000 kN·m, ten times the
/// largest top drives' rated torque. Beyond it a value was almost surely given in N·m where
/// kN·m was read ([`Law::implausible_torque`]).
pub const MAX_BIT_TORQUE_NM: f64 = 1.0e6;

/// The paper's reference weight on bit W_ref (N): every law's torque is scaled by r = W / W_ref,
/// and the paper's estimates hold at W = W_ref.
pub const PAPER_W_REF_N: f64 = 244.2e3;

/// The laws in f32 and the kernels' shared transcendentals (shaders/shared/laws.wgsl), the
/// WGSL twin of this module that a law file's WGSL is compiled against.
pub(crate) const LAWS_WGSL: &str = include_str!("../../shaders/shared/laws.wgsl");

/// The largest number of parameters of any law (M3 has six).
pub const MAX_PARAMS: usize = 6;

impl Law {
    /// Position in [`Law::ALL`] (m1 = 0 .. m4 = 3), and 4 + the registry place of a law
    /// file's law: the law id of the WGSL kernels.
    pub fn index(self) -> usize {
        match self {
            Law::File(FileLaw(k)) => Law::ALL.len() + usize::from(k),
            built_in => built_in.built_in_index().expect("a built-in law"),
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

    /// The law's colour in every figure, page and plot (0xRRGGBB): Okabe & Ito's palette,
    /// told apart with any colour vision; a built-in law's from its file, law files' laws the
    /// palette's others in turn.
    pub fn colour(self) -> u32 {
        match self {
            Law::File(_) => LAW_FILE_COLOURS[(self.index() - Law::ALL.len()) % LAW_FILE_COLOURS.len()],
            built_in => built_in.built_in().colour,
        }
    }

    /// [`Self::colour`] as CSS and matplotlib write it, `#rrggbb`.
    pub fn colour_hex(self) -> String {
        format!("#{:06x}", self.colour())
    }

    /// Identifier used on the command line and in outputs.
    pub fn name(self) -> &'static str {
        match self {
            Law::File(id) => &crate::laws::file::registered(id).file.name,
            built_in => built_in.built_in().name,
        }
    }

    /// Whose law it is, in words, beside its name where people read it ("Navarro-Lopez &
    /// Suarez" for m2): a built-in law's title, a law file's description if it has one.
    pub fn title(self) -> Option<&'static str> {
        match self {
            Law::File(id) => crate::laws::file::registered(id).file.description.as_deref(),
            built_in => Some(built_in.built_in().title),
        }
    }

    /// The built-in law's definition; panics for a law file's.
    pub(crate) fn built_in(self) -> &'static BuiltIn {
        &BUILT_INS[self.built_in_index().expect("a built-in law")]
    }

    /// The law's parameters, in the order used everywhere (CLI, JSON, CSV).
    pub fn params(self) -> &'static [ParamSpec] {
        match self {
            Law::File(id) => crate::laws::file::registered(id).specs,
            built_in => built_in.built_in().params,
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
            Law::File(id) => crate::laws::file::registered(id).reference_knm,
            built_in => built_in.built_in().paper_estimate,
        }
    }

    /// How far the evidence's prior lets the law's torque reach over the record's speeds, in
    /// multiples of its largest torque (its file's `prior_curve_within`), where it says:
    /// a law of free polynomial coefficients needs wide boxes for its terms, which cancel, and
    /// the limit keeps its curves to the torques its rivals' boxes reach.
    pub fn prior_curve_within(self) -> Option<f64> {
        match self {
            Law::File(id) => crate::laws::file::registered(id).file.prior_curve_within,
            built_in => built_in.built_in().prior_curve_within,
        }
    }

    /// A short formula for help texts and reports.
    pub fn formula(self) -> &'static str {
        match self {
            Law::File(id) => &crate::laws::file::registered(id).file.formula,
            built_in => built_in.built_in().formula,
        }
    }

    /// Torque on bit at bit speed `w` (rad/s, w > 0) and weight-on-bit ratio `r`, in the unit
    /// of the torque-valued parameters.
    #[inline]
    pub fn torque(self, p: &[f64], w: f64, r: f64) -> f64 {
        match self {
            // A law file's torque holds r itself (checked proportional to it), as a built-in's.
            Law::File(id) => crate::laws::file::registered(id).file.torque(p, w, r),
            built_in => built_in.built_in_torque(p, w, r),
        }
    }

    /// r·T(w) on `L` strings at once, lane `l` with the parameters `p[·][l]`, the bit speed
    /// `w[l]` (rad/s) and the ratio `r[l]`: the strings' CPU twin's law. A built-in law's lanes
    /// compute together, through [`crate::numerics`]'s exp (within 2 ulp of libm's) and tanh
    /// (within 4e-16 of tanh, absolutely); a law file's one after the other,
    /// as [`Law::torque`].
    #[inline(always)]
    pub fn torque_lanes<const L: usize>(self, p: &[[f64; L]; 6], w: &[f64; L], r: &[f64; L]) -> [f64; L] {
        match self {
            Law::File(id) => {
                let file = &crate::laws::file::registered(id).file;
                let n = self.n_params();
                std::array::from_fn(|l| {
                    let lane: [f64; 6] = std::array::from_fn(|i| p[i][l]);
                    file.torque(&lane[..n], w[l], r[l])
                })
            }
            built_in => built_in.built_in_torque_lanes(p, w, r),
        }
    }

    /// dT/dw at bit speed `w` (rad/s): the paper's analytic derivatives (a law file's symbolic
    /// one), scaled by `r`. The unit is the torque unit per rad/s (kN·m·s/rad for the paper's
    /// parameters).
    #[inline]
    pub fn dtorque_dw(self, p: &[f64], w: f64, r: f64) -> f64 {
        match self {
            Law::File(id) => crate::laws::file::registered(id).file.dtorque_dw(p, w, r),
            built_in => built_in.built_in_dtorque_dw(p, w, r),
        }
    }

    /// Torque at `w` with r = 1, and its gradient with respect to the parameters written
    /// into `grad` (length = number of parameters). Used by the least-squares Jacobian.
    pub fn torque_and_gradient(self, p: &[f64], w: f64, grad: &mut [f64]) -> f64 {
        match self {
            Law::File(id) => crate::laws::file::registered(id)
                .file
                .torque_and_gradient(p, w, 1.0, grad),
            built_in => built_in.built_in_torque_and_gradient(p, w, grad),
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
        let name = s.trim().to_ascii_lowercase();
        if let Some(law) = Law::ALL.into_iter().find(|law| law.name() == name) {
            return Ok(law);
        }
        crate::laws::file::find(&name).ok_or_else(|| {
            let built_in: Vec<&str> = Law::ALL.iter().map(|law| law.name()).collect();
            let files: Vec<&str> = crate::laws::file::registered_laws()
                .into_iter()
                .map(Law::name)
                .collect();
            let known = match built_in.split_last() {
                Some((last, rest)) if files.is_empty() => format!("{} or {last}, or a law file's law", rest.join(", ")),
                _ => format!("{} or a law file's law: {}", built_in.join(", "), files.join(", ")),
            };
            format!("unknown law '{name}' (expected {known})")
        })
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
    #[test]
    fn every_built_in_law_has_its_own_colour_blind_safe_colour_apart_from_the_data_s() {
        // Okabe & Ito (2008): black, orange, sky blue, bluish green, yellow, blue, vermillion,
        // reddish purple.
        const OKABE_ITO: [u32; 8] = [
            0x000000, 0xe69f00, 0x56b4e9, 0x009e73, 0xf0e442, 0x0072b2, 0xd55e00, 0xcc79a7,
        ];
        let colours: Vec<u32> = Law::ALL.iter().map(|law| law.colour()).collect();
        assert!(colours.iter().all(|c| OKABE_ITO.contains(c)), "{colours:06x?}");
        let distinct: std::collections::BTreeSet<u32> = colours.iter().copied().collect();
        assert_eq!(distinct.len(), colours.len());
        // The report's data: vermillion calibration circles, blue validation dots.
        assert!(!colours.contains(&0xd55e00) && !colours.contains(&0x0072b2));
        assert_eq!(Law::M3.colour_hex(), "#009e73");
    }

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
        assert_eq!(Law::M2.params()[0].unit(torque), "kN·m");
        assert_eq!(Law::M2.params()[2].unit(torque), "s/rad");
        assert_eq!(Law::M3.params()[1].unit(torque), "s^2/rad^2");
        assert_eq!(Law::M3.params()[2].unit(torque), "rad/s");
        assert_eq!(Law::M4.params()[1].unit(torque), "kN·m·s/rad");
    }

    #[test]
    fn law_lists_parse_and_reject_nonsense() {
        assert_eq!(parse_law_list("m2, M3").unwrap(), vec![Law::M2, Law::M3]);
        assert_eq!(parse_law_list("m2,m2").unwrap_err(), "law 'm2' is listed twice");
        assert!(parse_law_list("m5").unwrap_err().contains("m5"));
        for nothing in ["", " , ,"] {
            assert_eq!(
                parse_law_list(nothing).unwrap_err(),
                "no law given (expected e.g. m1,m2,m3,m4)"
            );
        }
    }

    /// The parts of a built-in law's file that carry its mathematics.
    #[derive(serde::Deserialize)]
    struct Definition {
        torque: String,
        dtorque_dw: Option<String>,
        gradient: Option<Vec<String>>,
    }

    #[test]
    fn the_built_in_laws_compute_what_their_files_say_bit_for_bit() {
        use file::expr::{Expr, Var, parse};
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        for (law, text) in Law::ALL.into_iter().zip(BUILT_IN_FILES) {
            let definition: Definition = toml::from_str(text).unwrap_or_else(|_| panic!("{law}: its file"));
            let names = law.param_names();
            let compile = |text: &str| parse(text, &names).unwrap().0;
            let torque = compile(&definition.torque);
            let slope = definition
                .dtorque_dw
                .as_deref()
                .map_or_else(|| torque.derivative(Var::Speed), compile);
            let gradient: Vec<Expr> = match &definition.gradient {
                Some(texts) => texts.iter().map(|t| compile(t)).collect(),
                None => (0..names.len()).map(|i| torque.derivative(Var::Param(i))).collect(),
            };
            // Around the paper's estimates, or around 1 for a law the paper does not have.
            let ones = vec![1.0; names.len()];
            let paper = law.paper_estimate().unwrap_or(&ones);
            let mut grad = vec![0.0; names.len()];
            for _ in 0..2_000 {
                // Parameters from a tenth to ten times the paper's, of either sign where free;
                // speeds negative, near zero and far beyond a rig's; ratios 0 to 2; N·m and kN·m.
                let unit = if rng.random_bool(0.5) { 1.0 } else { 1000.0 };
                let p: Vec<f64> = law
                    .scale_torque(paper, unit)
                    .iter()
                    .zip(law.params())
                    .map(|(v, spec)| {
                        let v = v * 10f64.powf(rng.random_range(-1.0..1.0));
                        if spec.lower.is_finite() || rng.random_bool(0.5) {
                            v
                        } else {
                            -v
                        }
                    })
                    .collect();
                let w = match rng.random_range(0..3) {
                    0 => rng.random_range(-5.0..40.0),
                    1 => rng.random_range(-1e-6..1e-6),
                    _ => 0.0,
                };
                let r = rng.random_range(0.0..2.0);
                let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
                let at = format!("{law} at p = {p:?}, w = {w}, r = {r}");
                assert!(same(law.torque(&p, w, r), torque.eval(&p, w, r)), "T of {at}");
                assert!(same(law.dtorque_dw(&p, w, r), slope.eval(&p, w, r)), "dT/dw of {at}");
                let t = law.torque_and_gradient(&p, w, &mut grad);
                assert!(same(t, torque.eval(&p, w, 1.0)), "T(r = 1) of {at}");
                for (i, (g, e)) in grad.iter().zip(&gradient).enumerate() {
                    assert!(same(*g, e.eval(&p, w, 1.0)), "∂T/∂{} of {at}", names[i]);
                }
            }
        }
    }

    #[test]
    fn paper_estimates_respect_the_bounds() {
        for law in Law::ALL {
            let Some(p) = law.paper_estimate() else { continue };
            assert_eq!(p.len(), law.n_params());
            assert!(law.bound_violation(p).is_none(), "{law}");
        }
    }
}
