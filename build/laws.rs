//! The built-in laws, each defined once in its file under `laws/` (the law-file language plus
//! what only a built-in law has: the printed formula, optional hand-simplified derivatives, the
//! paper's estimates, a colour), turned into the library's Rust code and the kernels' WGSL.
//!
//! - Rust (`OUT_DIR/laws.rs`, included by `src/laws/mod.rs`): the `Law` enum, the table of
//!   names, parameters, units, bounds and estimates, T(w, r) and dT/dw in f64 with libm's exp
//!   and tanh, T and ∂T/∂θ at r = 1 for least squares, and a macro that hands the CPU scorer
//!   each law's torque as a closure with the vectorisable exp and tanh.
//! - WGSL: each law's torque and slope in f32 and its case at every place the kernels list the
//!   laws (`src/eval/gpu/law_cases.rs`, the writer the host uses for law files).
//!
//! Each expression compiles as written, one IEEE operation per node in the order written, so
//! the order a file writes is the order every backend computes. A file's `dtorque_dw` and
//! `gradient` may give simpler forms of the derivatives (the paper's); they are checked here
//! against the symbolic derivatives of the torque, and the build fails where they differ.

use crate::expr::{self, Dim, Expr, Var};
use crate::law_cases::LawCases;
use serde::Deserialize;
use std::fmt::Write;
use std::path::Path;

/// The most parameters a law may have (the kernels' parameter arrays hold six).
const MAX_PARAMS: usize = 6;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLaw {
    name: String,
    title: String,
    formula: String,
    torque: String,
    dtorque_dw: Option<String>,
    gradient: Option<Vec<String>>,
    colour: String,
    prior_curve_within: Option<f64>,
    parameter: Vec<RawParam>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParam {
    name: String,
    unit: String,
    lower: Option<f64>,
    upper: Option<f64>,
    paper_estimate: Option<f64>,
}

/// A built-in law, compiled.
pub struct BuiltIn {
    path: std::path::PathBuf,
    name: String,
    title: String,
    formula: String,
    colour: u32,
    prior_curve_within: Option<f64>,
    params: Vec<Param>,
    torque: Expr,
    dtorque_dw: Expr,
    gradient: Vec<Expr>,
}

struct Param {
    name: String,
    torque_power: i32,
    inverse_speed_power: i32,
    lower: f64,
    upper: f64,
    paper_estimate: Option<f64>,
}

/// Every file of `dir` (`laws/`), in the order of their names: the order of `Law::ALL` and
/// of the kernels' law ids.
pub fn read(dir: &Path) -> Vec<BuiltIn> {
    println!("cargo::rerun-if-changed={}", dir.display());
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|entry| entry.expect("a readable directory").path())
        .filter(|path| path.extension().is_some_and(|x| x == "toml"))
        .collect();
    paths.sort();
    let laws: Vec<BuiltIn> = paths
        .iter()
        .map(|path| {
            println!("cargo::rerun-if-changed={}", path.display());
            let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            compile(path, &text).unwrap_or_else(|e| panic!("built-in law {}: {e}", path.display()))
        })
        .collect();
    assert!(!laws.is_empty(), "{}: no built-in law", dir.display());
    for (k, law) in laws.iter().enumerate() {
        assert!(
            laws[..k].iter().all(|other| other.name != law.name),
            "two built-in laws are named '{}'",
            law.name
        );
    }
    laws
}

fn compile(path: &Path, text: &str) -> Result<BuiltIn, String> {
    let raw: RawLaw = toml::from_str(text).map_err(|e| e.to_string())?;
    let name_ok = raw.name.chars().next().is_some_and(|c| c.is_ascii_lowercase())
        && raw.name.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit());
    if !name_ok {
        return Err(format!(
            "name '{}': lower-case letters and digits, a letter first",
            raw.name
        ));
    }
    if raw.parameter.is_empty() || raw.parameter.len() > MAX_PARAMS {
        return Err(format!("1 to {MAX_PARAMS} parameters, not {}", raw.parameter.len()));
    }
    let colour = raw
        .colour
        .strip_prefix('#')
        .filter(|hex| hex.len() == 6)
        .and_then(|hex| u32::from_str_radix(hex, 16).ok())
        .ok_or_else(|| format!("colour '{}': write #rrggbb", raw.colour))?;
    if let Some(k) = raw.prior_curve_within
        && !(k.is_finite() && k > 0.0)
    {
        return Err(format!("prior_curve_within = {k}: a positive number"));
    }
    let mut params = Vec::new();
    for p in &raw.parameter {
        if expr::is_reserved(&p.name) || !p.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(format!("parameter name '{}' is reserved or not an identifier", p.name));
        }
        let (torque_power, inverse_speed_power) =
            expr::parse_unit(&p.unit).ok_or_else(|| format!("parameter {}: unit '{}' unknown", p.name, p.unit))?;
        params.push(Param {
            name: p.name.clone(),
            torque_power,
            inverse_speed_power,
            lower: p.lower.unwrap_or(f64::NEG_INFINITY),
            upper: p.upper.unwrap_or(f64::INFINITY),
            paper_estimate: p.paper_estimate,
        });
    }
    let names: Vec<&str> = params.iter().map(|p| p.name.as_str()).collect();
    let parse = |what: &str, text: &str| -> Result<Expr, String> {
        expr::parse(text, &names)
            .map(|(e, _)| e)
            .map_err(|e| format!("{what}, at byte {}: {}", e.offset, e.message))
    };
    let (torque, used) =
        expr::parse(&raw.torque, &names).map_err(|e| format!("torque, at byte {}: {}", e.offset, e.message))?;
    if let Some(k) = used.iter().position(|u| !u) {
        return Err(format!("the torque does not use parameter {}", names[k]));
    }
    let dims: Vec<Dim> = params
        .iter()
        .map(|p| Dim::of(p.torque_power, p.inverse_speed_power))
        .collect();
    let dim = torque.dimension(&dims, &names)?;
    if dim != Dim::of(1, 0) {
        return Err(format!("the torque is in {}, not N·m", dim.unit()));
    }
    let symbolic_slope = torque.derivative(Var::Speed);
    let symbolic_gradient: Vec<Expr> = (0..params.len()).map(|i| torque.derivative(Var::Param(i))).collect();
    let dtorque_dw = match &raw.dtorque_dw {
        Some(text) => parse("dtorque_dw", text)?,
        None => symbolic_slope.clone(),
    };
    let gradient = match &raw.gradient {
        Some(texts) if texts.len() != params.len() => {
            return Err(format!(
                "gradient: {} expressions for {} parameters",
                texts.len(),
                params.len()
            ));
        }
        Some(texts) => texts
            .iter()
            .zip(&names)
            .map(|(text, name)| parse(&format!("gradient, ∂T/∂{name}"), text))
            .collect::<Result<Vec<_>, _>>()?,
        None => symbolic_gradient.clone(),
    };
    let law = BuiltIn {
        path: path.to_path_buf(),
        name: raw.name,
        title: raw.title,
        formula: raw.formula,
        colour,
        prior_curve_within: raw.prior_curve_within,
        params,
        torque,
        dtorque_dw,
        gradient,
    };
    law.check(&symbolic_slope, &symbolic_gradient)?;
    Ok(law)
}

impl BuiltIn {
    /// The torque proportional to r, and the derivatives the file gives equal to the symbolic
    /// ones, at parameter sets around the paper's estimates (or around 1) and speeds from
    /// 0.05 to 30 rad/s.
    fn check(&self, slope: &Expr, gradient: &[Expr]) -> Result<(), String> {
        let centre: Vec<f64> = self.params.iter().map(|p| p.paper_estimate.unwrap_or(1.0)).collect();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()));
        for scale in [1.0, 0.7, 1.3] {
            let p: Vec<f64> = centre
                .iter()
                .enumerate()
                .map(|(i, v)| v * if i % 2 == 0 { scale } else { 2.0 - scale })
                .collect();
            for w in [0.05, 0.3, 1.0, 2.5, 7.0, 30.0] {
                let (t1, t2) = (self.torque.eval(&p, w, 1.0), self.torque.eval(&p, w, 0.5));
                if !close(t1, 2.0 * t2) {
                    return Err(format!(
                        "the torque is not proportional to r (at w = {w}: {t1} against 2 × {t2})"
                    ));
                }
                for r in [1.0, 0.8] {
                    let (given, want) = (self.dtorque_dw.eval(&p, w, r), slope.eval(&p, w, r));
                    if !close(given, want) {
                        return Err(format!(
                            "dtorque_dw is not the torque's derivative: {given} against {want} at w = {w}, r = {r}, parameters {p:?}"
                        ));
                    }
                    for ((g, d), param) in self.gradient.iter().zip(gradient).zip(&self.params) {
                        let (given, want) = (g.eval(&p, w, r), d.eval(&p, w, r));
                        if !close(given, want) {
                            return Err(format!(
                                "gradient: ∂T/∂{} is {given} against {want} at w = {w}, r = {r}, parameters {p:?}",
                                param.name
                            ));
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// The `Law` variant: the name with its first letter in capitals (`m1` → `M1`).
    fn variant(&self) -> String {
        let mut variant = self.name.clone();
        variant[..1].make_ascii_uppercase();
        variant
    }

    /// `let pK = p[K];` for every parameter `exprs` use (locals keep the loops free of bounds
    /// checks, so that they vectorise).
    fn locals(&self, exprs: &[&Expr], indent: &str) -> String {
        self.locals_at(exprs, indent, "")
    }

    /// [`Self::locals`] read at `index` of each parameter's array (`let pK = p[K][l];`).
    fn locals_at(&self, exprs: &[&Expr], indent: &str, index: &str) -> String {
        let mut out = String::new();
        for i in 0..self.params.len() {
            if exprs.iter().any(|e| e.uses(Var::Param(i))) {
                writeln!(out, "{indent}let p{i} = p[{i}]{index};").unwrap();
            }
        }
        out
    }
}

fn float(v: f64) -> String {
    if v == f64::INFINITY {
        "f64::INFINITY".into()
    } else if v == f64::NEG_INFINITY {
        "f64::NEG_INFINITY".into()
    } else {
        format!("{v:?}")
    }
}

/// Lints that the generated code's plain, fully parenthesised form would trip.
const ALLOW: &str = "#[allow(unused_parens, clippy::double_parens, clippy::neg_multiply, clippy::precedence)]";

/// The library's Rust for the built-in laws.
pub fn rust(laws: &[BuiltIn]) -> String {
    let n = laws.len();
    let mut out = String::from("// Written by build.rs (build/laws.rs) from laws/*.toml.\n\n");
    out.push_str(
        "/// A bit-rock interaction law: one of the built-in laws (`laws/*.toml`), or one read from a\n\
         /// law file ([`crate::laws::file`]), named in files and on the command line by its name\n\
         /// either way.\n\
         #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]\n\
         #[serde(into = \"String\", try_from = \"String\")]\n\
         pub enum Law {\n",
    );
    for law in laws {
        writeln!(out, "    /// {}: `{}`.\n    {},", law.title, law.formula, law.variant()).unwrap();
    }
    out.push_str(
        "    /// A law read from a law file and registered in this process\n    /// ([`crate::laws::file::register`]).\n    File(FileLaw),\n}\n\n",
    );
    writeln!(
        out,
        "/// The built-in laws as their files define them, in the order of [`Law::ALL`]."
    )
    .unwrap();
    writeln!(out, "pub(crate) const BUILT_INS: [BuiltIn; {n}] = [").unwrap();
    for law in laws {
        let specs: Vec<String> = law
            .params
            .iter()
            .map(|p| {
                let spec = format!(
                    "ParamSpec::new({:?}, {}, {}, {})",
                    p.name,
                    p.torque_power,
                    p.inverse_speed_power,
                    float(p.lower)
                );
                if p.upper.is_finite() {
                    format!("{spec}.with_upper({})", float(p.upper))
                } else {
                    spec
                }
            })
            .collect();
        let paper: Option<Vec<String>> = law.params.iter().map(|p| p.paper_estimate.map(float)).collect();
        writeln!(
            out,
            "    BuiltIn {{\n        name: {:?},\n        title: {:?},\n        formula: {:?},\n        params: &[{}],\n        paper_estimate: {},\n        colour: {:#08x},\n        prior_curve_within: {},\n    }},",
            law.name,
            law.title,
            law.formula,
            specs.join(", "),
            match paper {
                Some(values) => format!("Some(&[{}])", values.join(", ")),
                None => "None".into(),
            },
            law.colour,
            law.prior_curve_within.map_or("None".into(), |k| format!("Some({})", float(k)))
        )
        .unwrap();
    }
    out.push_str("];\n\n");
    let files: Vec<String> = laws
        .iter()
        .map(|l| format!("include_str!({:?})", l.path.display().to_string()))
        .collect();
    writeln!(
        out,
        "/// The built-in laws' files, in the order of [`Law::ALL`]: what the tests check the compiled\n/// code against.\n#[cfg(test)]\npub(crate) const BUILT_IN_FILES: [&str; {n}] = [{}];\n",
        files.join(", ")
    )
    .unwrap();
    let list: Vec<&str> = laws.iter().map(|l| l.name.as_str()).collect();
    writeln!(
        out,
        "/// The built-in laws' names, comma-separated, as a string literal (`\"{list}\"`): for help\n/// texts and defaults, with `concat!`.\n#[macro_export]\nmacro_rules! built_in_law_list {{\n    () => {{\n        \"{list}\"\n    }};\n}}\n",
        list = list.join(",")
    )
    .unwrap();
    out.push_str("impl Law {\n");
    let variants: Vec<String> = laws.iter().map(|l| format!("Law::{}", l.variant())).collect();
    writeln!(
        out,
        "    /// The built-in laws, in the order of their files.\n    pub const ALL: [Law; {n}] = [{}];\n",
        variants.join(", ")
    )
    .unwrap();
    out.push_str("    /// The place in [`Law::ALL`] of a built-in law; `None` for a law file's.\n    const fn built_in_index(self) -> Option<usize> {\n        match self {\n");
    for (k, v) in variants.iter().enumerate() {
        writeln!(out, "            {v} => Some({k}),").unwrap();
    }
    out.push_str("            Law::File(_) => None,\n        }\n    }\n\n");

    let function = |out: &mut String, doc: &str, signature: &str, arm: &dyn Fn(&BuiltIn) -> String| {
        writeln!(
            out,
            "    /// {doc}\n    {ALLOW}\n    {}{signature} {{\n        match self {{",
            // A signature may give its own inlining.
            if signature.contains("#[inline") {
                ""
            } else {
                "#[inline]\n    "
            }
        )
        .unwrap();
        for law in laws {
            writeln!(
                out,
                "            Law::{} => {{\n{}            }}",
                law.variant(),
                arm(law)
            )
            .unwrap();
        }
        out.push_str(
            "            Law::File(_) => unreachable!(\"a law file's law is not built in\"),\n        }\n    }\n\n",
        );
    };
    function(
        &mut out,
        "T(w, r) of a built-in law in f64.",
        "fn built_in_torque(self, p: &[f64], w: f64, r: f64) -> f64",
        &|law| {
            format!(
                "{}                {}\n",
                law.locals(&[&law.torque], "                "),
                law.torque.rust("f64::exp", "f64::tanh")
            )
        },
    );
    function(
        &mut out,
        "r·T(w) of a built-in law on `L` lanes at once (lane `l` reads `p[·][l]`, `w[l]`, `r[l]`),\n    /// with the vectorisable exp and tanh of [`crate::numerics`]: the strings' CPU twin's law.",
        "#[inline(always)]\n    #[allow(clippy::needless_range_loop)]\n    fn built_in_torque_lanes<const L: usize>(self, p: &[[f64; L]; 6], w: &[f64; L], r: &[f64; L]) -> [f64; L]",
        &|law| {
            format!(
                "                let mut out = [0.0; L];\n                for l in 0..L {{\n                    let (w, r) = (w[l], r[l]);\n{}                    out[l] = {};\n                }}\n                out\n",
                law.locals_at(&[&law.torque], "                    ", "[l]"),
                law.torque.rust("crate::numerics::exp", "crate::numerics::tanh")
            )
        },
    );
    function(
        &mut out,
        "dT/dw of a built-in law in f64.",
        "fn built_in_dtorque_dw(self, p: &[f64], w: f64, r: f64) -> f64",
        &|law| {
            format!(
                "{}                {}\n",
                law.locals(&[&law.dtorque_dw], "                "),
                law.dtorque_dw.rust("f64::exp", "f64::tanh")
            )
        },
    );
    function(
        &mut out,
        "T at r = 1 of a built-in law, its gradient with respect to the parameters into `grad`.",
        "fn built_in_torque_and_gradient(self, p: &[f64], w: f64, grad: &mut [f64]) -> f64",
        &|law| {
            let torque = law.torque.at_unit_ratio();
            let gradient: Vec<Expr> = law.gradient.iter().map(Expr::at_unit_ratio).collect();
            let mut all: Vec<&Expr> = gradient.iter().collect();
            all.push(&torque);
            let mut body = law.locals(&all, "                ");
            for (i, g) in gradient.iter().enumerate() {
                writeln!(body, "                grad[{i}] = {};", g.rust("f64::exp", "f64::tanh")).unwrap();
            }
            writeln!(body, "                {}", torque.rust("f64::exp", "f64::tanh")).unwrap();
            body
        },
    );
    out.push_str("}\n\n");

    out.push_str(
        "/// `$body` with `$torque` bound to the built-in law `$law`'s torque at r = 1, a closure\n\
         /// over the speed (rad/s) on the parameters `$p`, with the vectorisable exp and tanh of\n\
         /// [`crate::numerics`]: the CPU scorer's inner loop.\n\
         macro_rules! with_built_in_torque {\n    ($law:expr, $p:expr, |$torque:ident| $body:expr) => {\n        match $law {\n",
    );
    for law in laws {
        let torque = law.torque.at_unit_ratio();
        writeln!(
            out,
            "            Law::{} => {{\n                let p: &[f64] = $p;\n{}                {ALLOW}\n                let $torque = |w: f64| {};\n                $body\n            }}",
            law.variant(),
            law.locals(&[&torque], "                "),
            torque.rust("$crate::numerics::exp", "$crate::numerics::tanh")
        )
        .unwrap();
    }
    out.push_str(
        "            Law::File(_) => unreachable!(\"a law file's law is not built in\"),\n        }\n    };\n}\npub(crate) use with_built_in_torque;\n",
    );
    out
}

/// The built-in laws' WGSL: their functions and cases, to splice into every kernel.
pub fn wgsl_cases(laws: &[BuiltIn], scores: bool) -> LawCases {
    let mut cases = LawCases::default();
    for (id, law) in laws.iter().enumerate() {
        let name = &law.name;
        let (torque_lets, torque) = law.torque.at_unit_ratio().wgsl_parts();
        let (slope_lets, slope) = law.dtorque_dw.at_unit_ratio().wgsl_parts();
        writeln!(
            cases.functions,
            "// {name}, {}: T = {} (r = 1).\nfn torque_{name}(p: array<f32, 6>, w: f32) -> f32 {{\n{torque_lets}    return {torque};\n}}\nfn slope_{name}(p: array<f32, 6>, w: f32) -> f32 {{\n{slope_lets}    return {slope};\n}}",
            law.title, law.formula
        )
        .unwrap();
        cases.add(
            id,
            &format!("quad_{name}"),
            &|p, w| format!("torque_{name}({p}, {w})"),
            &format!("slope_{name}(p, w)"),
            scores,
        );
    }
    cases
}
