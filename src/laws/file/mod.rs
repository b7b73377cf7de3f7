//! A bit-rock law of the user's own, read from a law file (TOML) and compiled three ways: the
//! f64 CPU twin, WGSL for the kernels, and the derivatives dT/dw (stability) and ∂T/∂θ (least
//! squares) obtained symbolically. docs/law-files.md describes the format.
//!
//! ```toml
//! name = "stribeck"
//! description = "Stribeck friction: static, Coulomb and viscous torque"
//! torque = "r * (tc + (ts - tc) * exp(-(w / vs)^2) + cv * w)"
//!
//! [[parameter]]
//! name = "ts"
//! unit = "N·m"
//! lower = 0
//! reference = 13000
//! ```
//!
//! A law file's torque is in the torque unit of its torque-valued parameters, like the built-in
//! laws; parameter values in a file (bounds, references) are SI, N·m-based. The WGSL text is
//! checked by naga when the file is read, so a law that loads compiles on every backend.

pub mod expr;
pub mod program;

use crate::laws::{FileLaw, MAX_PARAMS, ParamSpec};
use crate::{Error, Law, Result};
use expr::{Dim, Expr, Var, parse_unit};
use serde::Deserialize;
use std::ops::Range;
use std::path::Path;
use std::sync::RwLock;
use toml::Spanned;

/// One parameter of a law file.
#[derive(Clone, Debug, PartialEq)]
pub struct LawParam {
    pub name: String,
    /// 1 for a torque-valued parameter (a torque, or a torque per speed power), 0 otherwise.
    pub torque_power: i32,
    /// Power of (rad/s)⁻¹ in the parameter's unit (`s/rad` 1, `rad/s` −1).
    pub inverse_speed_power: i32,
    /// Physical lower bound, SI (−∞ where the file gives none).
    pub lower: f64,
    /// Physical upper bound, SI (+∞ where the file gives none).
    pub upper: f64,
    /// A reference value (a published estimate), SI, where the file gives one.
    pub reference: Option<f64>,
}

impl LawParam {
    /// The parameter's SI unit, written as bitrock writes units (`N·m·s/rad`).
    pub fn unit(&self) -> String {
        self.spec("").unit("N·m")
    }

    /// The parameter as the laws describe theirs, named `name`.
    pub fn spec(&self, name: &'static str) -> ParamSpec {
        ParamSpec::new(name, self.torque_power, self.inverse_speed_power, self.lower).with_upper(self.upper)
    }
}

/// A law read from a law file, compiled.
#[derive(Clone, Debug, PartialEq)]
pub struct LawFile {
    pub name: String,
    pub description: Option<String>,
    /// The torque as written.
    pub formula: String,
    pub params: Vec<LawParam>,
    /// T(w, r; θ).
    pub torque: Expr,
    /// dT/dw.
    pub dtorque_dw: Expr,
    /// ∂T/∂θ_i, one per parameter.
    pub gradient: Vec<Expr>,
    /// The file's whole text: what a run stores, so that it never depends on the file again.
    pub source: String,
    /// How far the evidence's prior lets the torque reach over the record's speeds, in
    /// multiples of its largest torque ([`crate::laws::Law::prior_curve_within`]).
    pub prior_curve_within: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLaw {
    name: Spanned<String>,
    description: Option<String>,
    torque: Spanned<String>,
    prior_curve_within: Option<Spanned<f64>>,
    #[serde(default)]
    parameter: Vec<Spanned<RawParam>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParam {
    name: Spanned<String>,
    unit: Spanned<String>,
    lower: Option<Spanned<f64>>,
    upper: Option<Spanned<f64>>,
    reference: Option<Spanned<f64>>,
}

/// The most a law file may hold, bytes: its torque is at most [`expr::MAX_LENGTH`] bytes and
/// its table of at most [`MAX_PARAMS`] parameters a few hundred more; comments and blank
/// lines get generous room. The file's text is stored with every run that uses it.
pub const MAX_FILE_BYTES: u64 = 64_000;

/// The most nodes a torque's derivative may hold (an upper bound computed before it is built):
/// far above any law written by hand, far below what exhausts time or memory.
pub const MAX_DERIVATIVE_NODES: usize = 200_000;

/// Words bitrock itself uses where law names go in its outputs and flags (the mixture of laws
/// in stability maps, `--laws all`, the particle columns), which a law file may not take.
const OUTPUT_WORDS: [&str; 8] = [
    "all",
    "mixture",
    "population",
    "position",
    "law",
    "candidate",
    "rho",
    "weight",
];

/// A law file registered in this process, with the views [`Law`] hands out (it lives as long
/// as the process, so they are `'static`).
pub(crate) struct Registered {
    pub file: &'static LawFile,
    /// The torque flattened for the CPU scoring loop.
    pub program: program::Program,
    pub specs: &'static [ParamSpec],
    /// The references in kN·m-based units, where every parameter has one.
    pub reference_knm: Option<&'static [f64]>,
}

/// The laws of the law files read by this process. A law is registered once and lives as long
/// as the process (a handful per run), so that [`Law`] stays a small `Copy` value.
static REGISTRY: RwLock<Vec<&'static Registered>> = RwLock::new(Vec::new());

/// Registers `file`'s law and returns it as a [`Law`]; the same file registered twice gives the
/// same law. Refuses a second, different law under a name already registered.
pub fn register(file: LawFile) -> Result<Law> {
    let mut registry = REGISTRY.write().expect("law registry");
    if let Some(k) = registry.iter().position(|r| r.file.name == file.name) {
        if registry[k].file.source == file.source {
            return Ok(Law::File(FileLaw(k as u16)));
        }
        return Err(Error::setting(
            "law_file",
            format!(
                "two different law files define the law '{}'; give each law its own name",
                file.name
            ),
        ));
    }
    // The run store names a law file's parameter columns `<law>_<parameter>`: two laws whose
    // names meet there (law `x` with `y_z`, law `x_y` with `z`) are refused before any work.
    for other in registry.iter() {
        for p in &file.params {
            let column = store_column(&file.name, &p.name);
            if let Some(q) = other
                .file
                .params
                .iter()
                .find(|q| store_column(&other.file.name, &q.name) == column)
            {
                return Err(Error::setting(
                    "law_file",
                    format!(
                        "law '{}' parameter '{}' and law '{}' parameter '{}' would share the column '{column}' of the run store; rename one",
                        file.name, p.name, other.file.name, q.name
                    ),
                ));
            }
        }
    }
    if registry.len() >= usize::from(u16::MAX) {
        return Err(Error::setting("law_file", "too many law files in one process"));
    }
    let file: &'static LawFile = Box::leak(Box::new(file));
    let specs: Vec<ParamSpec> = file.params.iter().map(|p| p.spec(&p.name)).collect();
    let reference_knm = file
        .params
        .iter()
        .map(|p| p.reference.map(|v| if p.torque_power == 1 { v / 1000.0 } else { v }))
        .collect::<Option<Vec<f64>>>()
        .map(|v| &*Box::leak(v.into_boxed_slice()));
    let registered = Registered {
        program: program::Program::new(&file.torque),
        specs: Box::leak(specs.into_boxed_slice()),
        reference_knm,
        file,
    };
    registry.push(Box::leak(Box::new(registered)));
    Ok(Law::File(FileLaw((registry.len() - 1) as u16)))
}

/// The run store's column of parameter `param` of the law file's law `law`: `<law>_<param>`
/// (a law file's parameter names may repeat another law's).
pub fn store_column(law: &str, param: &str) -> String {
    format!("{law}_{param}")
}

/// Reads, compiles and registers the law file at `path`.
pub fn load_and_register(path: &Path) -> Result<Law> {
    register(LawFile::load(path)?)
}

pub(crate) fn registered(id: FileLaw) -> &'static Registered {
    // Asked for at every torque a fit or a simulated string evaluates: each thread reads its
    // own copy of the registry (entries are never changed or removed, only added), and takes
    // the lock only for a law registered since it last looked.
    thread_local! {
        static SEEN: std::cell::RefCell<Vec<&'static Registered>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    let k = usize::from(id.0);
    SEEN.with_borrow_mut(|seen| {
        if k >= seen.len() {
            seen.clone_from(&REGISTRY.read().expect("law registry"));
        }
        seen[k]
    })
}

/// The registered law named `name`.
pub(crate) fn find(name: &str) -> Option<Law> {
    let registry = REGISTRY.read().expect("law registry");
    registry
        .iter()
        .position(|r| r.file.name == name)
        .map(|k| Law::File(FileLaw(k as u16)))
}

/// The law files' laws among `laws`, each once, in [`Law`]'s order.
pub fn among(laws: impl IntoIterator<Item = Law>) -> Vec<Law> {
    let set: std::collections::BTreeSet<Law> = laws.into_iter().filter(|l| l.file().is_some()).collect();
    set.into_iter().collect()
}

/// The registered laws, in registration order.
pub fn registered_laws() -> Vec<Law> {
    let count = REGISTRY.read().expect("law registry").len();
    (0..count).map(|k| Law::File(FileLaw(k as u16))).collect()
}

/// A law file's `name`, checked: lower-case letters, digits and `_`, and not a built-in law's
/// nor a word of bitrock's outputs.
fn law_name(raw_name: &Spanned<String>, at: &dyn Fn(usize, String) -> Error) -> Result<String> {
    let name = raw_name.get_ref().trim().to_string();
    let name_ok = name.len() <= 24
        && name.starts_with(|c: char| c.is_ascii_lowercase())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
    if !name_ok {
        return Err(at(
            raw_name.span().start,
            format!("law name '{name}': use up to 24 lower-case letters, digits and '_', starting with a letter"),
        ));
    }
    if Law::ALL.iter().any(|law| law.name() == name.as_str()) {
        return Err(at(
            raw_name.span().start,
            format!("law name '{name}' is a built-in law's; choose another"),
        ));
    }
    if OUTPUT_WORDS.contains(&name.as_str()) {
        return Err(at(
            raw_name.span().start,
            format!("law name '{name}' is a word bitrock uses in its outputs; choose another"),
        ));
    }
    Ok(name)
}

/// One `[[parameter]]` of a law file, checked against the ones before it (`params`): its
/// name, unit, bounds and reference.
fn parameter(p: &RawParam, params: &[LawParam], at: &dyn Fn(usize, String) -> Error) -> Result<LawParam> {
    let pname = p.name.get_ref().trim().to_string();
    let ident =
        pname.starts_with(|c: char| c.is_alphabetic()) && pname.chars().all(|c| c.is_alphanumeric() || c == '_');
    if !ident {
        return Err(at(
            p.name.span().start,
            format!("parameter name '{pname}': use letters, digits and '_', starting with a letter"),
        ));
    }
    if expr::is_reserved(&pname) {
        return Err(at(
            p.name.span().start,
            format!("parameter name '{pname}' is reserved (w, r, pi, e and the functions)"),
        ));
    }
    if params.iter().any(|q| q.name == pname) {
        return Err(at(p.name.span().start, format!("parameter '{pname}' is given twice")));
    }
    let (torque_power, inverse_speed_power) =
        parse_unit(p.unit.get_ref()).ok_or_else(|| at(p.unit.span().start, unit_error(p.unit.get_ref())))?;
    let value = |v: &Option<Spanned<f64>>, default: f64, what: &str| -> Result<f64> {
        match v {
            None => Ok(default),
            Some(s) if s.get_ref().is_nan() => Err(at(s.span().start, format!("{what} of '{pname}' is not a number"))),
            Some(s) => Ok(*s.get_ref()),
        }
    };
    let lower = value(&p.lower, f64::NEG_INFINITY, "lower")?;
    if lower == f64::INFINITY {
        let start = p.lower.as_ref().map_or(0, |s| s.span().start);
        return Err(at(start, format!("lower bound of '{pname}' is +∞")));
    }
    let upper = value(&p.upper, f64::INFINITY, "upper")?;
    if let Some(s) = &p.upper
        && upper <= lower
    {
        return Err(at(
            s.span().start,
            format!("upper bound of '{pname}' = {upper} does not lie above its lower bound {lower}"),
        ));
    }
    let reference = match &p.reference {
        None => None,
        Some(s) => {
            let v = *s.get_ref();
            if !(v.is_finite() && lower <= v) {
                return Err(at(
                    s.span().start,
                    format!("reference of '{pname}' = {v} lies below its lower bound {lower}"),
                ));
            }
            if v > upper {
                return Err(at(
                    s.span().start,
                    format!("reference of '{pname}' = {v} lies above its upper bound {upper}"),
                ));
            }
            Some(v)
        }
    };
    Ok(LawParam {
        name: pname,
        torque_power,
        inverse_speed_power,
        lower,
        upper,
        reference,
    })
}

/// The torque's checks before its derivatives are built: a torque (N·m) in dimension, its
/// derivatives of a size bitrock builds, its constants within f32, and proportional to the
/// weight-on-bit ratio r. `at` places a message at the torque's text.
fn check_torque(torque: &Expr, params: &[LawParam], names: &[&str], at: &dyn Fn(String) -> Error) -> Result<()> {
    let dims: Vec<Dim> = params
        .iter()
        .map(|p| Dim::of(p.torque_power, p.inverse_speed_power))
        .collect();
    let dim = torque.dimension(&dims, names).map_err(|m| at(format!("torque: {m}")))?;
    if dim != Dim::of(1, 0) {
        return Err(at(format!(
            "torque: the expression is in {}, not a torque (N·m)",
            dim.unit()
        )));
    }
    // Derivatives are built symbolically: bounded before any is built.
    let bound = torque.derivative_size_bound();
    if bound > MAX_DERIVATIVE_NODES {
        return Err(at(format!(
            "torque: its derivatives could hold {bound} nodes, more than the {MAX_DERIVATIVE_NODES} bitrock builds (the derivative of a product of n factors grows as n²): write a repeated factor as a power (g^12) or simplify the expression"
        )));
    }
    if let Some(c) = torque.constant_beyond_f32() {
        return Err(at(format!(
            "torque: the constant {c:e} does not fit in f32, the GPU's float (|x| ≤ {:e}): rescale the law's parameters so that its constants stay within it",
            f32::MAX
        )));
    }
    // Every law in bitrock scales with the weight-on-bit ratio: T = r · T₁(w).
    let probe: Vec<f64> = params.iter().map(|p| p.reference.unwrap_or(1.0)).collect();
    let proportional = !torque.derivative(Var::Ratio).uses(Var::Ratio)
        && [0.1, 1.0, 5.0].iter().all(|&w| {
            let t = torque.eval(&probe, w, 0.0);
            t == 0.0 || !t.is_finite()
        });
    if !proportional {
        return Err(at(
            "torque: must be proportional to the weight-on-bit ratio r: write r * (…)".to_string(),
        ));
    }
    Ok(())
}

impl LawFile {
    /// Reads and compiles the law file at `path`.
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::files::read_text(path, "a law file", MAX_FILE_BYTES)?;
        Self::parse(&text, path)
    }

    /// Compiles the law file text `source`; `path` names it in errors.
    pub fn parse(source: &str, path: &Path) -> Result<Self> {
        let text = crate::files::UserFile { source, path };
        let at = |offset: usize, message: String| text.at(offset, message);
        let raw: RawLaw = text.toml()?;
        let name = law_name(&raw.name, &at)?;
        if raw.parameter.len() > MAX_PARAMS {
            return Err(at(
                raw.parameter[MAX_PARAMS].span().start,
                format!(
                    "a law takes at most {MAX_PARAMS} parameters, this file gives {}",
                    raw.parameter.len()
                ),
            ));
        }
        let mut params: Vec<LawParam> = Vec::new();
        for spanned in &raw.parameter {
            let param = parameter(spanned.get_ref(), &params, &at)?;
            params.push(param);
        }
        let formula = raw.torque.get_ref().clone();
        let names: Vec<&str> = params.iter().map(|p| p.name.as_str()).collect();
        let text_start = string_content_start(source, raw.torque.span(), &formula);
        let (torque, used) = expr::parse(&formula, &names).map_err(|e| {
            at(
                text_start.map_or(raw.torque.span().start, |s| s + e.offset),
                format!("torque: {}", e.message),
            )
        })?;
        if let Some(i) = used.iter().position(|u| !u) {
            let span = raw.parameter[i].get_ref().name.span();
            return Err(at(
                span.start,
                format!("parameter '{}' is never used in the torque", params[i].name),
            ));
        }
        let torque_at = text_start.unwrap_or(raw.torque.span().start);
        check_torque(&torque, &params, &names, &|m| at(torque_at, m))?;
        let dtorque_dw = torque.derivative(Var::Speed);
        if let Some(c) = dtorque_dw.constant_beyond_f32() {
            return Err(at(
                torque_at,
                format!(
                    "torque: its derivative dT/dw holds the constant {c:e}, which does not fit in f32, the GPU's float: rescale the law's parameters"
                ),
            ));
        }
        let gradient = (0..params.len()).map(|i| torque.derivative(Var::Param(i))).collect();
        let prior_curve_within = match raw.prior_curve_within {
            Some(k) if !(k.get_ref().is_finite() && *k.get_ref() > 0.0) => {
                return Err(at(
                    k.span().start,
                    format!(
                        "prior_curve_within = {}: give a positive number of the record's largest torques",
                        k.get_ref()
                    ),
                ));
            }
            k => k.map(Spanned::into_inner),
        };
        let law = Self {
            prior_curve_within,
            name,
            description: raw.description,
            formula,
            params,
            torque,
            dtorque_dw,
            gradient,
            source: source.to_string(),
        };
        law.check_wgsl()
            .map_err(|message| at(raw.torque.span().start, message))?;
        Ok(law)
    }

    /// The law's WGSL functions: `file_torque_<name>(p, w, r)` and `file_slope_<name>(p, w, r)`
    /// (dT/dw), f32, needing the kernels' shared functions (shaders/shared/laws.wgsl).
    pub fn wgsl(&self) -> String {
        let (torque_lets, t) = self.torque.wgsl_parts();
        let (slope_lets, d) = self.dtorque_dw.wgsl_parts();
        format!(
            "// The law '{name}' of a law file: T = {formula}\n\
             fn file_torque_{name}(p: array<f32, 6>, w: f32, r: f32) -> f32 {{\n{torque_lets}    return {t};\n}}\n\
             fn file_slope_{name}(p: array<f32, 6>, w: f32, r: f32) -> f32 {{\n{slope_lets}    return {d};\n}}\n",
            name = self.name,
            formula = self.formula.replace('\n', " "),
        )
    }

    /// Parses and validates the law's WGSL with the kernels' shared functions (naga), so that a
    /// law that loads compiles on every backend.
    fn check_wgsl(&self) -> std::result::Result<(), String> {
        let text = format!("{}\n{}", crate::laws::LAWS_WGSL, self.wgsl());
        let module = naga::front::wgsl::parse_str(&text).map_err(|e| {
            let message = e.message();
            if message.contains("internal") {
                "the torque is too large or too deeply nested for the WGSL compiler: simplify it".to_string()
            } else {
                format!("the torque does not compile to WGSL: {message}")
            }
        })?;
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
            .validate(&module)
            .map_err(|e| format!("the torque's WGSL does not validate: {}", e.as_inner()))?;
        Ok(())
    }

    /// T(w, r; θ) in f64.
    pub fn torque(&self, p: &[f64], w: f64, r: f64) -> f64 {
        self.torque.eval(p, w, r)
    }

    /// T(w, r; θ) in f32, as the GPU computes it.
    pub fn torque_f32(&self, p: &[f32], w: f32, r: f32) -> f32 {
        self.torque.eval(p, w, r)
    }

    /// dT/dw in f64.
    pub fn dtorque_dw(&self, p: &[f64], w: f64, r: f64) -> f64 {
        self.dtorque_dw.eval(p, w, r)
    }

    /// T and ∂T/∂θ written into `grad`, in f64.
    pub fn torque_and_gradient(&self, p: &[f64], w: f64, r: f64, grad: &mut [f64]) -> f64 {
        for (g, e) in grad.iter_mut().zip(&self.gradient) {
            *g = e.eval(p, w, r);
        }
        self.torque.eval(p, w, r)
    }
}

/// The byte offset in `source` where the text of the string value at `span` begins, when the
/// value is written without escapes (so expression offsets map to columns); `None` otherwise.
fn string_content_start(source: &str, span: Range<usize>, value: &str) -> Option<usize> {
    let raw = source.get(span.clone())?;
    for quote in ["\"\"\"", "'''", "\"", "'"] {
        if let Some(inner) = raw.strip_prefix(quote).and_then(|r| r.strip_suffix(quote)) {
            // A multi-line string drops the newline right after its opening quotes.
            let skip = if quote.len() == 3 && inner.starts_with('\n') {
                1
            } else {
                0
            };
            if &inner[skip..] == value {
                return Some(span.start + quote.len() + skip);
            }
            return None;
        }
    }
    None
}

fn unit_error(text: &str) -> String {
    format!(
        "unit '{text}' is not one bitrock knows: write 1, N·m, rad/s, s/rad, s^2/rad^2, rad^2/s^2, N·m·s/rad, N·m·s^2/rad^2, … (SI, N·m-based)"
    )
}

#[cfg(test)]
mod tests;
