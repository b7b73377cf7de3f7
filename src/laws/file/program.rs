//! A law file's torque flattened for the CPU scoring loop: one instruction per node of its
//! expression, each applied to a block of speeds at once.

use super::expr::{Binary, Expr, Unary, Var, small_integer};

/// Samples a [`Program`] evaluates per instruction.
pub const BLOCK: usize = 64;

/// An operand of a [`Program`] instruction: a register, a constant, a parameter or the speed.
#[derive(Clone, Copy, Debug)]
enum Operand {
    Register(usize),
    Const(f64),
    Param(usize),
    Speed,
}

/// An expression flattened for the CPU scoring loop: one instruction per node, each applied to
/// a block of [`BLOCK`] speeds at once (loops the compiler vectorises), exp and tanh the
/// vectorisable [`crate::numerics`] ones the built-in laws' CPU scoring uses. `r` is 1: the
/// scoring loop multiplies by r (a law file's torque is proportional to it).
#[derive(Clone, Debug)]
pub struct Program {
    steps: Vec<(Step, Operand, Operand)>,
    result: Operand,
}

#[derive(Clone, Copy, Debug)]
enum Step {
    Unary(Unary),
    Binary(Binary),
    /// a^n, n a small integer (multiplications, as [`Expr::eval`]'s powi).
    PowI(i32),
}

impl Program {
    /// `expr` with r = 1, flattened.
    pub fn new(expr: &Expr) -> Self {
        let mut steps = Vec::new();
        let result = Self::flatten(expr, &mut steps);
        Self { steps, result }
    }

    fn flatten(e: &Expr, steps: &mut Vec<(Step, Operand, Operand)>) -> Operand {
        match e {
            Expr::Const(c) => Operand::Const(*c),
            Expr::Var(Var::Speed) => Operand::Speed,
            Expr::Var(Var::Ratio) => Operand::Const(1.0),
            Expr::Var(Var::Param(i)) => Operand::Param(*i),
            Expr::Unary(op, a) => {
                let a = Self::flatten(a, steps);
                steps.push((Step::Unary(*op), a, a));
                Operand::Register(steps.len() - 1)
            }
            Expr::Binary(Binary::Pow, a, b) if small_integer(b).is_some() => {
                let a = Self::flatten(a, steps);
                let n = small_integer(b).expect("checked");
                steps.push((Step::PowI(n), a, a));
                Operand::Register(steps.len() - 1)
            }
            Expr::Binary(op, a, b) => {
                let a = Self::flatten(a, steps);
                let b = Self::flatten(b, steps);
                steps.push((Step::Binary(*op), a, b));
                Operand::Register(steps.len() - 1)
            }
        }
    }

    /// The torques at `w` (up to [`BLOCK`] speeds) with parameters `p`, into `out`; `registers`
    /// is scratch space kept between calls. Inlined, so that the CPU scorer's AVX2 build of its
    /// loop (`eval::cpu`) covers these loops too.
    #[inline(always)]
    pub fn eval_block(&self, p: &[f64], w: &[f64], out: &mut [f64], registers: &mut Vec<[f64; BLOCK]>) {
        let n = w.len();
        registers.resize(self.steps.len(), [0.0; BLOCK]);
        let mut speed = [0.0; BLOCK];
        speed[..n].copy_from_slice(w);
        // Each instruction writes its own register from earlier ones (post-order).
        for (k, &(step, a, b)) in self.steps.iter().enumerate() {
            let (done, rest) = registers.split_at_mut(k);
            let z = &mut rest[0];
            let (mut a_buf, mut b_buf) = ([0.0; BLOCK], [0.0; BLOCK]);
            let x = operand(done, a, p, &speed, &mut a_buf);
            macro_rules! each {
                ($f:expr) => {
                    for l in 0..BLOCK {
                        z[l] = $f(x[l]);
                    }
                };
            }
            match step {
                Step::Unary(Unary::Neg) => each!(|v: f64| -v),
                Step::Unary(Unary::Exp) => each!(crate::numerics::exp),
                Step::Unary(Unary::Ln) => each!(f64::ln),
                Step::Unary(Unary::Sqrt) => each!(f64::sqrt),
                Step::Unary(Unary::Abs) => each!(f64::abs),
                Step::Unary(Unary::Sign) => each!(|v: f64| if v == 0.0 || v.is_nan() { v } else { v.signum() }),
                Step::Unary(Unary::Tanh) => each!(crate::numerics::tanh),
                Step::Unary(Unary::Sin) => each!(f64::sin),
                Step::Unary(Unary::Cos) => each!(f64::cos),
                Step::PowI(e) => each!(|v: f64| v.powi(e)),
                Step::Binary(op) => {
                    let y = operand(done, b, p, &speed, &mut b_buf);
                    for l in 0..BLOCK {
                        z[l] = match op {
                            Binary::Add => x[l] + y[l],
                            Binary::Sub => x[l] - y[l],
                            Binary::Mul => x[l] * y[l],
                            Binary::Div => x[l] / y[l],
                            // WGSL's pow is exp2(y·log2 x): no value for x < 0.
                            Binary::Pow if x[l] < 0.0 => f64::NAN,
                            Binary::Pow => x[l].powf(y[l]),
                        };
                    }
                }
            }
        }
        let mut buf = [0.0; BLOCK];
        let result = operand(registers, self.result, p, &speed, &mut buf);
        out[..n].copy_from_slice(&result[..n]);
    }
}

/// The block of values of operand `o`: a register of `done`, or `buf` filled with a constant,
/// a parameter or the speeds.
#[inline(always)]
fn operand<'a>(
    done: &'a [[f64; BLOCK]],
    o: Operand,
    p: &[f64],
    speed: &[f64; BLOCK],
    buf: &'a mut [f64; BLOCK],
) -> &'a [f64; BLOCK] {
    match o {
        Operand::Register(k) => &done[k],
        Operand::Const(c) => {
            *buf = [c; BLOCK];
            buf
        }
        Operand::Param(i) => {
            *buf = [p[i]; BLOCK];
            buf
        }
        Operand::Speed => {
            *buf = *speed;
            buf
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laws::file::expr::parse;

    fn compile(text: &str) -> Expr {
        parse(text, &["a", "b"]).unwrap().0
    }

    #[test]
    fn a_program_gives_the_twin_s_values_block_by_block() {
        let texts = [
            "a * (tanh(b * w) + 2 * w / (1 + b * w^2))",
            "(a - b) * exp(-b * w) + b",
            "sqrt(a + w^2) * ln(b + w) / (1 + abs(w - 0.7)) - sign(w - 1) * cos(w) * sin(b)",
            "pow(w, a) - w^-3 + (w - 2)^3 + pow(w - 2, 0.5)",
        ];
        let p = [1.3, 0.6];
        let w: Vec<f64> = (0..150).map(|i| -0.5 + 0.05 * f64::from(i)).collect();
        let mut registers = Vec::new();
        for text in texts {
            let e = compile(text);
            let program = Program::new(&e);
            let mut got = vec![0.0; w.len()];
            for (ws, out) in w.chunks(BLOCK).zip(got.chunks_mut(BLOCK)) {
                program.eval_block(&p, ws, out, &mut registers);
            }
            for (&x, g) in w.iter().zip(&got) {
                let want = e.eval(&p, x, 1.0);
                // exp and tanh are numerics' (within a few ulp of libm).
                let close = (want.is_nan() && g.is_nan()) || (g - want).abs() <= 1e-13 * want.abs().max(1.0);
                assert!(close, "{text} at w = {x}: {g} against {want}");
            }
        }
    }
}
