//! Law files on the GPU: the WGSL a law file compiles to against its f64 CPU twin, for the
//! built-in laws written as files and for random expressions. These tests need a GPU adapter,
//! as tests/it/gpu.rs's do.

use crate::gpu::require_gpu;
use bitrock::eval::gpu::law_points::{Point, torques};
use bitrock::law_file::expr::{Binary, Expr, Unary, Var, parse};
use bitrock::law_file::{LawFile, LawParam};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::path::Path;

/// f32's unit roundoff.
const U: f64 = 1.0 / 16_777_216.0;

/// The expression's f64 value and a bound on the size of what f32 rounding can do to it: every
/// operation's rounding, weighted by how much the result depends on it (a first-order forward
/// error bound, in units of the roundoff; transcendentals count a few ulps, sin and cos an
/// absolute few from their argument reduction).
fn value_and_sensitivity(e: &Expr, p: &[f64], w: f64, r: f64) -> (f64, f64) {
    match e {
        Expr::Const(c) => (*c, c.abs()),
        Expr::Var(Var::Speed) => (w, 0.0),
        Expr::Var(Var::Ratio) => (r, 0.0),
        Expr::Var(Var::Param(i)) => (p[*i], 0.0),
        Expr::Unary(op, a) => {
            let (x, m) = value_and_sensitivity(a, p, w, r);
            let v = e.eval(p, w, r);
            let s = match op {
                Unary::Neg | Unary::Abs => m,
                Unary::Sign => 0.0,
                Unary::Exp => v.abs() * (m + 4.0 + x.abs()),
                Unary::Ln => m / x.abs() + 4.0 * v.abs().max(1.0),
                Unary::Sqrt => m / (2.0 * v.abs()) + v.abs(),
                Unary::Tanh => (1.0 - v * v) * (m + 4.0 + x.abs()) + 4.0 * v.abs(),
                Unary::Sin | Unary::Cos => m + 4.0 + x.abs(),
            };
            (v, s)
        }
        Expr::Binary(op, a, b) => {
            let (x, ma) = value_and_sensitivity(a, p, w, r);
            let (y, mb) = value_and_sensitivity(b, p, w, r);
            let v = e.eval(p, w, r);
            let s = match op {
                Binary::Add | Binary::Sub => ma + mb + v.abs(),
                Binary::Mul => ma * y.abs() + x.abs() * mb + v.abs(),
                Binary::Div => ma / y.abs() + x.abs() * mb / (y * y) + v.abs(),
                Binary::Pow => {
                    let n = y.abs().max(1.0);
                    let log = x.abs().ln().abs().max(1.0);
                    (y * v / x).abs() * ma + (v * log).abs() * (mb + 4.0 * n) + 4.0 * n * v.abs()
                }
            };
            (v, s)
        }
    }
}

/// Compares the GPU's (T, dT/dw) of `law` with the twin's at `points`; returns how many
/// points were compared (those where both are finite and moderate in the f64 twin).
fn compare(law: &LawFile, points: &[Point]) -> usize {
    let gpu = torques(law, points).unwrap();
    let mut compared = 0;
    for (q, g) in points.iter().zip(&gpu) {
        let p: Vec<f64> = q.p[..law.params.len()].iter().map(|&v| f64::from(v)).collect();
        let (w, r) = (f64::from(q.w), f64::from(q.r));
        let mut all_finite = true;
        for (k, expr) in [&law.torque, &law.dtorque_dw].into_iter().enumerate() {
            let (v, s) = value_and_sensitivity(expr, &p, w, r);
            if !(v.is_finite() && s.is_finite() && s < 1e30) {
                all_finite = false;
                continue;
            }
            let got = f64::from(g[k]);
            let bound = 32.0 * U * s + 1e-30;
            assert!(
                (got - v).abs() <= bound,
                "{} ({}) at p = {p:?}, w = {w}, r = {r}: GPU {got}, twin {v}, bound {bound:e}\n{}",
                if k == 0 { "T" } else { "dT/dw" },
                law.formula,
                law.wgsl()
            );
        }
        compared += usize::from(all_finite);
    }
    compared
}

fn point(p: &[f64], w: f64, r: f64) -> Point {
    let mut q = [0.0f32; 6];
    for (a, b) in q.iter_mut().zip(p) {
        *a = *b as f32;
    }
    Point {
        p: q,
        w: w as f32,
        r: r as f32,
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_built_in_laws_as_files_agree_on_the_gpu_with_their_twins() {
    require_gpu();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws");
    for file in ["tucker_wang", "navarro_suarez", "gaussian_tanh", "cubic", "stribeck"] {
        let law = LawFile::load(&dir.join(format!("{file}.toml"))).unwrap();
        let reference: Vec<f64> = law
            .params
            .iter()
            .map(|p| p.reference.unwrap_or(if p.torque_power == 1 { 8_000.0 } else { 0.5 }))
            .collect();
        let mut points = Vec::new();
        for scale in [1.0, 0.3, 2.0] {
            let p: Vec<f64> = reference.iter().map(|v| v * scale).collect();
            for i in 0..200 {
                // Backwards through zero to fast: −2 … 20 rad/s.
                let w = -2.0 + 22.0 * f64::from(i) / 199.0;
                points.push(point(&p, w, if i % 2 == 0 { 1.0 } else { 0.83 }));
            }
        }
        let compared = compare(&law, &points);
        assert_eq!(compared, points.len(), "{file}");
    }
}

/// A random expression in the law file grammar, over the parameters a, b, c, w and r; which
/// parameters it uses are marked in `used`.
fn random_expression(rng: &mut StdRng, depth: u32, used: &mut [bool; 3]) -> String {
    if depth == 0 || rng.random::<f64>() < 0.25 {
        return match rng.random_range(0..6) {
            0 => "w".into(),
            1 => "r".into(),
            k @ 2..=4 => {
                used[k - 2] = true;
                ["a", "b", "c"][k - 2].into()
            }
            _ => format!("{:.2}", rng.random_range(-3.0..3.0)),
        };
    }
    let mut sub = |rng: &mut StdRng| random_expression(rng, depth - 1, used);
    match rng.random_range(0..14) {
        0 => format!("({} + {})", sub(rng), sub(rng)),
        1 => format!("({} - {})", sub(rng), sub(rng)),
        2 | 3 => format!("{} * {}", sub(rng), sub(rng)),
        4 => format!("{} / (1.5 + {}^2)", sub(rng), sub(rng)),
        5 => format!("({})^{}", sub(rng), rng.random_range(-2..=3)),
        6 => format!("pow(abs({}) + 0.5, {:.2})", sub(rng), rng.random_range(-1.5..2.5)),
        7 => format!("exp({} / 4)", sub(rng)),
        8 => format!("ln(abs({}) + 0.25)", sub(rng)),
        9 => format!("sqrt(abs({}))", sub(rng)),
        10 => format!("tanh({})", sub(rng)),
        11 => format!("sin({})", sub(rng)),
        12 => format!("cos({})", sub(rng)),
        _ => format!("-{}", sub(rng)),
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn random_expressions_agree_on_the_gpu_with_their_twins() {
    require_gpu();
    let mut rng = StdRng::seed_from_u64(28);
    let (mut laws, mut compared, mut total) = (0, 0, 0);
    while laws < 150 {
        let mut used = [false; 3];
        let text = random_expression(&mut rng, 4, &mut used);
        let names: Vec<&str> = ["a", "b", "c"]
            .into_iter()
            .zip(used)
            .filter(|(_, u)| *u)
            .map(|(n, _)| n)
            .collect();
        // The compiler alone: random expressions are neither torques nor proportional to r,
        // which a law file's checks would refuse.
        let (torque, _) = parse(&text, &names).unwrap_or_else(|e| panic!("{e:?}\n{text}"));
        let law = LawFile {
            name: "random".into(),
            description: None,
            formula: text.clone(),
            params: names
                .iter()
                .map(|n| LawParam {
                    name: n.to_string(),
                    torque_power: 0,
                    inverse_speed_power: 0,
                    lower: f64::NEG_INFINITY,
                    reference: None,
                })
                .collect(),
            dtorque_dw: torque.derivative(Var::Speed),
            gradient: Vec::new(),
            torque,
            source: text.clone(),
        };
        let points: Vec<Point> = (0..64)
            .map(|_| {
                let p: Vec<f64> = names.iter().map(|_| rng.random_range(-2.0..2.0)).collect();
                point(&p, rng.random_range(-3.0..6.0), rng.random_range(0.5..1.5))
            })
            .collect();
        compared += compare(&law, &points);
        total += points.len();
        laws += 1;
    }
    // Most points give finite values; the comparison is not vacuous.
    eprintln!("{compared} of {total} points compared over {laws} random laws");
    assert!(compared * 10 >= total * 8, "{compared} of {total}");
}
