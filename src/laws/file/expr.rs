//! The expression language of a law file: a torque written in the bit speed `w` (rad/s), the
//! weight-on-bit ratio `r` and the law's parameters.
//!
//! Grammar (whitespace is free; `#` is not a comment inside an expression):
//!
//! ```text
//! expr    = term { ("+" | "-") term }
//! term    = unary { ("*" | "/") unary }
//! unary   = ("-" | "+") unary | power
//! power   = atom [ ("^" | "**") unary ]        right-associative: -w^2 is -(w^2)
//! atom    = number | name | name "(" expr { "," expr } ")" | "(" expr ")"
//! number  = digits [ "." digits ] [ ("e" | "E") [ "+" | "-" ] digits ]   (or ".5")
//! name    = letter { letter | digit | "_" }
//! ```
//!
//! Names: `w`, `r`, the constants `pi` and `e`, the law's parameters, and the functions `exp`,
//! `ln`, `sqrt`, `abs`, `sign`, `tanh`, `sin`, `cos` (one argument) and `pow` (two; the same as
//! `^`). A power a^b is defined for every a when b is an integer constant of at most 16 in
//! size (computed by multiplications), and for a ≥ 0 otherwise (exp2(b·log2 a), as WGSL's pow;
//! a negative a gives no value). An expression compiles three ways: the f64 CPU twin ([`Expr::eval`]), its derivatives
//! obtained symbolically ([`Expr::derivative`], simplified as they are built), and a WGSL
//! expression in f32 ([`Expr::wgsl`]) whose transcendentals are the kernels' own (exp through
//! exp2, tanh through one exp2, sin and cos reduced by π/2 with polynomials), so that the
//! accuracy does not depend on a driver's built-ins.

// Simplification tests constants for exact identities (0, 1, −1, integers), never for closeness.
#![allow(clippy::float_cmp)]

use std::fmt::Write;

/// A variable of a law: bit speed, weight-on-bit ratio, or parameter `i` of the law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Var {
    Speed,
    Ratio,
    Param(usize),
}

/// Functions of one argument.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unary {
    Neg,
    Exp,
    Ln,
    Sqrt,
    Abs,
    Sign,
    Tanh,
    Sin,
    Cos,
}

/// Operators of two arguments.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Binary {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

impl Binary {
    /// The operator as written infix (`^` for a power, which WGSL and Rust write as calls).
    pub fn symbol(self) -> &'static str {
        match self {
            Binary::Add => "+",
            Binary::Sub => "-",
            Binary::Mul => "*",
            Binary::Div => "/",
            Binary::Pow => "^",
        }
    }
}

/// A compiled expression tree.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    Const(f64),
    Var(Var),
    Unary(Unary, Box<Expr>),
    Binary(Binary, Box<Expr>, Box<Expr>),
}

/// Functions a law may call, with their arity.
pub const FUNCTIONS: [(&str, usize); 9] = [
    ("exp", 1),
    ("ln", 1),
    ("sqrt", 1),
    ("abs", 1),
    ("sign", 1),
    ("tanh", 1),
    ("sin", 1),
    ("cos", 1),
    ("pow", 2),
];

/// Names no parameter may take: the variables, the constants and the functions.
pub fn is_reserved(name: &str) -> bool {
    matches!(name, "w" | "r" | "pi" | "e") || FUNCTIONS.iter().any(|(f, _)| *f == name)
}

/// A syntax or name error at a byte offset of the expression.
#[derive(Clone, Debug, PartialEq)]
pub struct ParseError {
    pub offset: usize,
    pub message: String,
}

fn error<T>(offset: usize, message: impl Into<String>) -> Result<T, ParseError> {
    Err(ParseError {
        offset,
        message: message.into(),
    })
}

#[derive(Clone, Debug, PartialEq)]
enum Token {
    Number(f64),
    Name(String),
    Op(char),
    Pow,
    Open,
    Close,
    Comma,
    End,
}

fn tokens(text: &str) -> Result<Vec<(usize, Token)>, ParseError> {
    let bytes = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let c = text[i..].chars().next().expect("i is a char boundary");
        let start = i;
        if c.is_whitespace() {
            i += c.len_utf8();
            continue;
        }
        if c.is_ascii_digit() || (c == '.' && bytes.get(i + 1).is_some_and(u8::is_ascii_digit)) {
            let digits = |mut j: usize| {
                while j < bytes.len() && bytes[j].is_ascii_digit() {
                    j += 1;
                }
                j
            };
            i = digits(i);
            if bytes.get(i) == Some(&b'.') {
                i = digits(i + 1);
            }
            if matches!(bytes.get(i), Some(b'e' | b'E')) {
                let mut j = i + 1;
                if matches!(bytes.get(j), Some(b'+' | b'-')) {
                    j += 1;
                }
                if bytes.get(j).is_some_and(u8::is_ascii_digit) {
                    i = digits(j);
                }
            }
            let value: f64 = text[start..i]
                .parse()
                .or_else(|_| error(start, format!("'{}' is not a number", &text[start..i])))?;
            if !value.is_finite() {
                return error(start, format!("{} is too large for a number", &text[start..i]));
            }
            out.push((start, Token::Number(value)));
        } else if c.is_alphabetic() {
            while let Some(c) = text[i..].chars().next() {
                if !(c.is_alphanumeric() || c == '_') {
                    break;
                }
                i += c.len_utf8();
            }
            out.push((start, Token::Name(text[start..i].to_string())));
        } else {
            i += c.len_utf8();
            let token = match c {
                '+' | '-' | '/' => Token::Op(c),
                '*' if bytes.get(i) == Some(&b'*') => {
                    i += 1;
                    Token::Pow
                }
                '*' | '·' | '×' => Token::Op('*'),
                '−' => Token::Op('-'),
                '^' => Token::Pow,
                '(' => Token::Open,
                ')' => Token::Close,
                ',' => Token::Comma,
                _ => return error(start, format!("unexpected character '{c}'")),
            };
            out.push((start, token));
        }
    }
    out.push((text.len(), Token::End));
    Ok(out)
}

/// Parses `text`, resolving names against `params`; every parameter used is marked in the
/// returned flags.
pub fn parse(text: &str, params: &[&str]) -> Result<(Expr, Vec<bool>), ParseError> {
    if text.len() > MAX_LENGTH {
        return error(MAX_LENGTH, format!("the expression is longer than {MAX_LENGTH} bytes"));
    }
    let mut parser = Parser {
        tokens: tokens(text)?,
        at: 0,
        params,
        used: vec![false; params.len()],
        depth: 0,
    };
    if parser.peek() == &Token::End {
        return error(0, "the expression is empty");
    }
    let expr = parser.expr()?;
    let (offset, token) = &parser.tokens[parser.at];
    if token != &Token::End {
        return error(
            *offset,
            format!("unexpected {} after a complete expression", describe(token)),
        );
    }
    Ok((expr, parser.used))
}

fn describe(token: &Token) -> String {
    match token {
        Token::Number(v) => format!("number {v}"),
        Token::Name(n) => format!("name '{n}'"),
        Token::Op(c) => format!("'{c}'"),
        Token::Pow => "'^'".into(),
        Token::Open => "'('".into(),
        Token::Close => "')'".into(),
        Token::Comma => "','".into(),
        Token::End => "end of the expression".into(),
    }
}

/// The longest expression read, and the deepest nesting (parentheses, calls, signs, powers):
/// bounds that keep the recursive parser, twin and differentiator far from the stack's end.
pub const MAX_LENGTH: usize = 10_000;
pub const MAX_DEPTH: usize = 64;

struct Parser<'a> {
    tokens: Vec<(usize, Token)>,
    at: usize,
    params: &'a [&'a str],
    used: Vec<bool>,
    depth: usize,
}

impl Parser<'_> {
    fn peek(&self) -> &Token {
        &self.tokens[self.at].1
    }

    fn next(&mut self) -> (usize, Token) {
        let t = self.tokens[self.at].clone();
        if t.1 != Token::End {
            self.at += 1;
        }
        t
    }

    fn expect(&mut self, want: Token, what: &str) -> Result<(), ParseError> {
        let (offset, token) = self.next();
        if token == want {
            Ok(())
        } else {
            error(offset, format!("expected {what}, found {}", describe(&token)))
        }
    }

    fn expr(&mut self) -> Result<Expr, ParseError> {
        let mut left = self.term()?;
        while let Token::Op(c @ ('+' | '-')) = *self.peek() {
            self.next();
            let right = self.term()?;
            left = binary(if c == '+' { Binary::Add } else { Binary::Sub }, left, right);
        }
        Ok(left)
    }

    fn term(&mut self) -> Result<Expr, ParseError> {
        let mut left = self.unary()?;
        while let Token::Op(c @ ('*' | '/')) = *self.peek() {
            self.next();
            let right = self.unary()?;
            left = binary(if c == '*' { Binary::Mul } else { Binary::Div }, left, right);
        }
        Ok(left)
    }

    fn unary(&mut self) -> Result<Expr, ParseError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return error(
                self.tokens[self.at].0,
                format!("the expression nests deeper than {MAX_DEPTH} levels"),
            );
        }
        let result = self.unary_inner();
        self.depth -= 1;
        result
    }

    fn unary_inner(&mut self) -> Result<Expr, ParseError> {
        match self.peek() {
            Token::Op('-') => {
                self.next();
                // A negated number is a negative constant (exact), so that w^-2 is a power
                // with an integer exponent.
                Ok(neg(self.unary()?))
            }
            Token::Op('+') => {
                self.next();
                self.unary()
            }
            _ => self.power(),
        }
    }

    fn power(&mut self) -> Result<Expr, ParseError> {
        let base = self.atom()?;
        if self.peek() == &Token::Pow {
            self.next();
            let exponent = self.unary()?;
            return Ok(binary(Binary::Pow, base, exponent));
        }
        Ok(base)
    }

    fn atom(&mut self) -> Result<Expr, ParseError> {
        let (offset, token) = self.next();
        match token {
            Token::Number(v) => Ok(Expr::Const(v)),
            Token::Open => {
                let e = self.expr()?;
                self.expect(Token::Close, "')'")?;
                Ok(e)
            }
            Token::Name(name) if self.peek() == &Token::Open => self.call(offset, &name),
            Token::Name(name) => self.name(offset, &name),
            other => error(
                offset,
                format!("expected a number, a name or '(', found {}", describe(&other)),
            ),
        }
    }

    fn name(&mut self, offset: usize, name: &str) -> Result<Expr, ParseError> {
        Ok(match name {
            "w" => Expr::Var(Var::Speed),
            "r" => Expr::Var(Var::Ratio),
            "pi" => Expr::Const(std::f64::consts::PI),
            "e" => Expr::Const(std::f64::consts::E),
            _ => match self.params.iter().position(|p| *p == name) {
                Some(i) => {
                    self.used[i] = true;
                    Expr::Var(Var::Param(i))
                }
                None if FUNCTIONS.iter().any(|(f, _)| *f == name) => {
                    return error(offset, format!("'{name}' is a function: write {name}(…)"));
                }
                None => {
                    return error(
                        offset,
                        format!(
                            "unknown name '{name}' (the names are w, r, pi, e{}{})",
                            if self.params.is_empty() { "" } else { ", " },
                            self.params.join(", ")
                        ),
                    );
                }
            },
        })
    }

    fn call(&mut self, offset: usize, name: &str) -> Result<Expr, ParseError> {
        let Some(&(_, arity)) = FUNCTIONS.iter().find(|(f, _)| *f == name) else {
            let names: Vec<&str> = FUNCTIONS.iter().map(|(f, _)| *f).collect();
            return error(
                offset,
                format!("unknown function '{name}' (the functions are {})", names.join(", ")),
            );
        };
        self.expect(Token::Open, "'('")?;
        let mut args = vec![self.expr()?];
        while self.peek() == &Token::Comma {
            self.next();
            args.push(self.expr()?);
        }
        self.expect(Token::Close, "')' or ','")?;
        if args.len() != arity {
            return error(
                offset,
                format!(
                    "{name} takes {arity} argument{}, got {}",
                    if arity == 1 { "" } else { "s" },
                    args.len()
                ),
            );
        }
        let mut args = args.into_iter();
        let a = args.next().expect("one argument at least");
        let unary = |op| Ok(Expr::Unary(op, Box::new(a.clone())));
        match name {
            "exp" => unary(Unary::Exp),
            "ln" => unary(Unary::Ln),
            "sqrt" => unary(Unary::Sqrt),
            "abs" => unary(Unary::Abs),
            "sign" => unary(Unary::Sign),
            "tanh" => unary(Unary::Tanh),
            "sin" => unary(Unary::Sin),
            "cos" => unary(Unary::Cos),
            _ => Ok(binary(Binary::Pow, a.clone(), args.next().expect("arity 2"))),
        }
    }
}

/// A binary node as written, constants folded (in f64, so that 3^2 is the integer power 9).
fn binary(op: Binary, a: Expr, b: Expr) -> Expr {
    let node = Expr::Binary(op, Box::new(a), Box::new(b));
    match &node {
        Expr::Binary(_, a, b) if matches!((&**a, &**b), (Expr::Const(_), Expr::Const(_))) => {
            Expr::Const(node.eval(&[], 0.0, 1.0))
        }
        _ => node,
    }
}

/// The integer value of `e` when it is a small integer constant (a power unrolled into
/// multiplications on both paths).
pub(crate) fn small_integer(e: &Expr) -> Option<i32> {
    match e {
        Expr::Const(c) if c.fract() == 0.0 && c.abs() <= 16.0 => Some(*c as i32),
        _ => None,
    }
}

// Constructors that simplify as they build, so that derivatives stay short: constants fold,
// 0 and 1 vanish where they are identities.
fn add(a: Expr, b: Expr) -> Expr {
    match (&a, &b) {
        (Expr::Const(x), Expr::Const(y)) => Expr::Const(x + y),
        (Expr::Const(z), _) if *z == 0.0 => b,
        (_, Expr::Const(z)) if *z == 0.0 => a,
        _ => binary(Binary::Add, a, b),
    }
}

fn sub(a: Expr, b: Expr) -> Expr {
    match (&a, &b) {
        (Expr::Const(x), Expr::Const(y)) => Expr::Const(x - y),
        (_, Expr::Const(z)) if *z == 0.0 => a,
        (Expr::Const(z), _) if *z == 0.0 => neg(b),
        _ => binary(Binary::Sub, a, b),
    }
}

fn mul(a: Expr, b: Expr) -> Expr {
    match (&a, &b) {
        (Expr::Const(x), Expr::Const(y)) => Expr::Const(x * y),
        (Expr::Const(z), _) | (_, Expr::Const(z)) if *z == 0.0 => Expr::Const(0.0),
        (Expr::Const(one), _) if *one == 1.0 => b,
        (_, Expr::Const(one)) if *one == 1.0 => a,
        (Expr::Const(m), _) if *m == -1.0 => neg(b),
        (_, Expr::Const(m)) if *m == -1.0 => neg(a),
        _ => binary(Binary::Mul, a, b),
    }
}

fn div(a: Expr, b: Expr) -> Expr {
    match (&a, &b) {
        (Expr::Const(z), _) if *z == 0.0 => Expr::Const(0.0),
        (_, Expr::Const(one)) if *one == 1.0 => a,
        _ => binary(Binary::Div, a, b),
    }
}

fn neg(a: Expr) -> Expr {
    match a {
        Expr::Const(x) => Expr::Const(-x),
        Expr::Unary(Unary::Neg, inner) => *inner,
        _ => Expr::Unary(Unary::Neg, Box::new(a)),
    }
}

fn apply(op: Unary, a: Expr) -> Expr {
    Expr::Unary(op, Box::new(a))
}

fn pow(a: Expr, b: Expr) -> Expr {
    match small_integer(&b) {
        Some(0) => Expr::Const(1.0),
        Some(1) => a,
        _ => binary(Binary::Pow, a, b),
    }
}

/// A physical dimension, torque^t · (rad/s)^(−s), both powers doubled so that a square root
/// stays exact.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dim {
    pub torque2: i32,
    pub inverse_speed2: i32,
}

impl Dim {
    pub const NONE: Dim = Dim {
        torque2: 0,
        inverse_speed2: 0,
    };

    /// The dimension of a parameter of torque power `t` and inverse-speed power `s`.
    pub fn of(t: i32, s: i32) -> Dim {
        Dim {
            torque2: 2 * t,
            inverse_speed2: 2 * s,
        }
    }

    fn scaled(self, num: i32, den: i32) -> Option<Dim> {
        let (t, s) = (self.torque2 * num, self.inverse_speed2 * num);
        (t % den == 0 && s % den == 0).then(|| Dim {
            torque2: t / den,
            inverse_speed2: s / den,
        })
    }

    /// The dimension written as bitrock writes units (N·m, s/rad, …).
    pub fn unit(self) -> String {
        if self.torque2 % 2 != 0 || self.inverse_speed2 % 2 != 0 {
            return format!(
                "N·m^{}·(s/rad)^{}",
                self.torque2 as f64 / 2.0,
                self.inverse_speed2 as f64 / 2.0
            );
        }
        let (t, s) = (self.torque2 / 2, self.inverse_speed2 / 2);
        if t == 0 || t == 1 {
            unit_text(t, s, "N·m")
        } else {
            format!("N^{t}·m^{t}·(s/rad)^{s}")
        }
    }
}

/// A unit of torque power `torque_power` (0 or 1) and inverse-speed power
/// `inverse_speed_power`, written with the given torque unit (`kN·m`, `N·m`): `s/rad`,
/// `N·m·s^2/rad^2`, … as bitrock writes units.
pub fn unit_text(torque_power: i32, inverse_speed_power: i32, torque_unit: &str) -> String {
    let speed = match inverse_speed_power {
        0 => String::new(),
        -1 => "rad/s".to_string(),
        1 => "s/rad".to_string(),
        p => format!("s^{p}/rad^{p}"),
    };
    match (torque_power, speed.is_empty()) {
        (0, true) => "1".to_string(),
        (0, false) => speed,
        (_, true) => torque_unit.to_string(),
        (_, false) => format!("{torque_unit}·{speed}"),
    }
}

/// (torque power, inverse-speed power) of a unit written as bitrock prints units: `1`, `N·m`,
/// `s/rad`, `rad/s`, `s^2/rad^2`, `N·m·s/rad`, … (`*` or `.` for `·`, spaces ignored).
pub fn parse_unit(text: &str) -> Option<(i32, i32)> {
    let normal: String = text
        .chars()
        .filter(|c| !c.is_whitespace())
        .map(|c| if c == '*' || c == '.' { '·' } else { c })
        .collect();
    for torque_power in [0, 1] {
        for inverse_speed_power in -3..=3 {
            let canonical = unit_text(torque_power, inverse_speed_power, "N·m");
            // rad^k/s^k reads better than s^-k/rad^-k.
            let k = -inverse_speed_power;
            let upright = canonical.replace(&format!("s^-{k}/rad^-{k}"), &format!("rad^{k}/s^{k}"));
            if normal == canonical || normal == upright {
                return Some((torque_power, inverse_speed_power));
            }
        }
    }
    None
}

impl Expr {
    /// Infix text of the expression with the parameters' `names`, for messages.
    pub fn show(&self, names: &[&str]) -> String {
        match self {
            Expr::Const(c) => format!("{c}"),
            Expr::Var(Var::Speed) => "w".into(),
            Expr::Var(Var::Ratio) => "r".into(),
            Expr::Var(Var::Param(i)) => names[*i].to_string(),
            Expr::Unary(Unary::Neg, a) => format!("-{}", a.show(names)),
            Expr::Unary(op, a) => {
                let name = format!("{op:?}").to_lowercase();
                format!("{name}({})", a.show(names))
            }
            Expr::Binary(op, a, b) => format!("({} {} {})", a.show(names), op.symbol(), b.show(names)),
        }
    }

    /// The expression's dimension, given the parameters' (`params`) and their `names` for
    /// messages; refuses sums of unlike dimensions, transcendentals of dimensioned arguments and
    /// dimensioned exponents. Numbers are dimensionless.
    pub fn dimension(&self, params: &[Dim], names: &[&str]) -> Result<Dim, String> {
        let none = |e: &Expr, what: &str| -> Result<(), String> {
            let d = e.dimension(params, names)?;
            if d == Dim::NONE {
                Ok(())
            } else {
                Err(format!(
                    "{what} {} has dimension {}; it must be dimensionless (divide by a parameter of that unit)",
                    e.show(names),
                    d.unit()
                ))
            }
        };
        Ok(match self {
            Expr::Const(_) | Expr::Var(Var::Ratio) => Dim::NONE,
            Expr::Var(Var::Speed) => Dim::of(0, -1),
            Expr::Var(Var::Param(i)) => params[*i],
            Expr::Unary(Unary::Neg | Unary::Abs, a) => a.dimension(params, names)?,
            Expr::Unary(Unary::Sign, a) => {
                a.dimension(params, names)?;
                Dim::NONE
            }
            Expr::Unary(Unary::Sqrt, a) => a
                .dimension(params, names)?
                .scaled(1, 2)
                .ok_or_else(|| format!("sqrt of {} has no dimension bitrock can write", a.show(names)))?,
            Expr::Unary(op, a) => {
                none(a, &format!("the argument of {}", format!("{op:?}").to_lowercase()))?;
                Dim::NONE
            }
            Expr::Binary(op @ (Binary::Add | Binary::Sub), a, b) => {
                let (da, db) = (a.dimension(params, names)?, b.dimension(params, names)?);
                if da != db {
                    return Err(format!(
                        "{} {} {} {}: {} is in {} and {} in {}",
                        if *op == Binary::Add { "adding" } else { "subtracting" },
                        b.show(names),
                        if *op == Binary::Add { "to" } else { "from" },
                        a.show(names),
                        a.show(names),
                        da.unit(),
                        b.show(names),
                        db.unit()
                    ));
                }
                da
            }
            Expr::Binary(Binary::Mul, a, b) => {
                let (da, db) = (a.dimension(params, names)?, b.dimension(params, names)?);
                Dim {
                    torque2: da.torque2 + db.torque2,
                    inverse_speed2: da.inverse_speed2 + db.inverse_speed2,
                }
            }
            Expr::Binary(Binary::Div, a, b) => {
                let (da, db) = (a.dimension(params, names)?, b.dimension(params, names)?);
                Dim {
                    torque2: da.torque2 - db.torque2,
                    inverse_speed2: da.inverse_speed2 - db.inverse_speed2,
                }
            }
            Expr::Binary(Binary::Pow, a, b) => {
                none(b, "the exponent")?;
                let da = a.dimension(params, names)?;
                if da == Dim::NONE {
                    return Ok(da);
                }
                // A dimensioned base needs a rational constant exponent (halves at most).
                let twice = match **b {
                    Expr::Const(c) if (2.0 * c).fract() == 0.0 && c.abs() <= 16.0 => (2.0 * c) as i32,
                    _ => {
                        return Err(format!(
                            "{} is in {}: its exponent must be a number (a multiple of 1/2)",
                            a.show(names),
                            da.unit()
                        ));
                    }
                };
                da.scaled(twice, 2)
                    .ok_or_else(|| format!("{} has no dimension bitrock can write", self.show(names)))?
            }
        })
    }

    /// The expression's value in `T`: f64 (the CPU twin) or f32 (the precision the GPU computes
    /// in, to measure what a law loses there). `p` holds the law's parameters.
    pub fn eval<T: num_traits::Float>(&self, p: &[T], w: T, r: T) -> T {
        match self {
            Expr::Const(c) => T::from(*c).unwrap_or_else(T::nan),
            Expr::Var(Var::Speed) => w,
            Expr::Var(Var::Ratio) => r,
            Expr::Var(Var::Param(i)) => p[*i],
            Expr::Unary(op, a) => {
                let x = a.eval(p, w, r);
                match op {
                    Unary::Neg => -x,
                    Unary::Exp => x.exp(),
                    Unary::Ln => x.ln(),
                    Unary::Sqrt => x.sqrt(),
                    Unary::Abs => x.abs(),
                    // sign(0) = 0, as WGSL's sign.
                    Unary::Sign => {
                        if x.is_zero() || x.is_nan() {
                            x
                        } else {
                            x.signum()
                        }
                    }
                    Unary::Tanh => x.tanh(),
                    Unary::Sin => x.sin(),
                    Unary::Cos => x.cos(),
                }
            }
            Expr::Binary(op, a, b) => {
                let x = a.eval(p, w, r);
                if let (Binary::Pow, Some(n)) = (op, small_integer(b)) {
                    return x.powi(n);
                }
                let y = b.eval(p, w, r);
                match op {
                    Binary::Add => x + y,
                    Binary::Sub => x - y,
                    Binary::Mul => x * y,
                    Binary::Div => x / y,
                    // WGSL's pow is exp2(y·log2 x): no value for x < 0.
                    Binary::Pow if x < T::zero() => T::nan(),
                    Binary::Pow => x.powf(y),
                }
            }
        }
    }

    /// True when `var` occurs in the expression.
    pub fn uses(&self, var: Var) -> bool {
        match self {
            Expr::Const(_) => false,
            Expr::Var(v) => *v == var,
            Expr::Unary(_, a) => a.uses(var),
            Expr::Binary(_, a, b) => a.uses(var) || b.uses(var),
        }
    }

    /// The derivative with respect to `var`, symbolically, simplified as it is built.
    pub fn derivative(&self, var: Var) -> Expr {
        match self {
            Expr::Const(_) => Expr::Const(0.0),
            Expr::Var(v) => Expr::Const(if *v == var { 1.0 } else { 0.0 }),
            Expr::Unary(op, a) => {
                let da = a.derivative(var);
                if da == Expr::Const(0.0) {
                    return da;
                }
                let a = (**a).clone();
                let outer = match op {
                    Unary::Neg => return neg(da),
                    Unary::Exp => apply(Unary::Exp, a),
                    Unary::Ln => return div(da, a),
                    Unary::Sqrt => return div(da, mul(Expr::Const(2.0), apply(Unary::Sqrt, a))),
                    Unary::Abs => apply(Unary::Sign, a),
                    Unary::Sign => return Expr::Const(0.0),
                    Unary::Tanh => {
                        let t = apply(Unary::Tanh, a);
                        sub(Expr::Const(1.0), mul(t.clone(), t))
                    }
                    Unary::Sin => apply(Unary::Cos, a),
                    Unary::Cos => neg(apply(Unary::Sin, a)),
                };
                mul(outer, da)
            }
            Expr::Binary(op, a, b) => {
                let (da, db) = (a.derivative(var), b.derivative(var));
                // Sums need no copy of their operands: a left-nested sum of n terms stays O(n).
                match op {
                    Binary::Add => return add(da, db),
                    Binary::Sub => return sub(da, db),
                    _ => {}
                }
                let (a, b) = ((**a).clone(), (**b).clone());
                match op {
                    Binary::Add | Binary::Sub => unreachable!("returned above"),
                    Binary::Mul => add(mul(da, b.clone()), mul(a, db)),
                    Binary::Div => sub(div(da, b.clone()), div(mul(a, db), mul(b.clone(), b))),
                    Binary::Pow if db == Expr::Const(0.0) => {
                        // d(a^c) = c a^(c-1) da, for a constant c (or any b free of var).
                        let lowered = match &b {
                            Expr::Const(c) => Expr::Const(c - 1.0),
                            _ => sub(b.clone(), Expr::Const(1.0)),
                        };
                        mul(mul(b, pow(a, lowered)), da)
                    }
                    Binary::Pow => {
                        // d(a^b) = a^b (db ln a + b da / a).
                        let whole = pow(a.clone(), b.clone());
                        mul(whole, add(mul(db, apply(Unary::Ln, a.clone())), div(mul(b, da), a)))
                    }
                }
            }
        }
    }

    /// The expression in WGSL, f32: the `let` statements it needs (one per line, none for a
    /// small expression) followed by the value. Parameters are `p[i]`, speed `w`, ratio `r`;
    /// needs the kernels' `exp_f32`, `tanh_f32`, `sin_f32` and `cos_f32`
    /// (shaders/shared/laws.wgsl).
    pub fn wgsl(&self) -> String {
        let (lets, value) = self.wgsl_parts();
        lets + &value
    }

    /// [`Self::wgsl`] as (`let` statements, value): subexpressions nested deeper than
    /// [`WGSL_MAX_NESTING`], and an unrolled power's base longer than [`WGSL_INLINE_REPEAT`],
    /// are bound to `let`s, so the text is linear in the expression's size and no WGSL
    /// compiler meets a deep nesting.
    pub fn wgsl_parts(&self) -> (String, String) {
        let mut lets = String::new();
        let mut count = 0;
        let (value, _) = self.write_wgsl(&mut lets, &mut count);
        (lets, value)
    }

    /// (text, nesting) of this node, hoisting into `lets` as needed.
    fn write_wgsl(&self, lets: &mut String, count: &mut usize) -> (String, usize) {
        match self {
            Expr::Const(c) => {
                let v = *c as f32;
                // `{:?}` prints a shortest round-trip form with a point or exponent ("1.0",
                // "1e-5"), both WGSL float literals.
                let text = format!("{:?}", v.abs());
                if v < 0.0 { (format!("(-{text})"), 0) } else { (text, 0) }
            }
            Expr::Var(Var::Speed) => ("w".into(), 0),
            Expr::Var(Var::Ratio) => ("r".into(), 0),
            Expr::Var(Var::Param(i)) => (format!("p[{i}]"), 0),
            Expr::Unary(op, a) => {
                let name = match op {
                    Unary::Neg => "-",
                    Unary::Exp => "exp_f32",
                    Unary::Ln => "log",
                    Unary::Sqrt => "sqrt",
                    Unary::Abs => "abs",
                    Unary::Sign => "sign",
                    Unary::Tanh => "tanh_f32",
                    Unary::Sin => "sin_f32",
                    Unary::Cos => "cos_f32",
                };
                let (ta, da) = a.write_wgsl(lets, count);
                hoist(lets, count, format!("{name}({ta})"), da + 1, false)
            }
            Expr::Binary(Binary::Pow, a, b) => match small_integer(b) {
                Some(n) => {
                    let (mut ta, mut da) = a.write_wgsl(lets, count);
                    if ta.len() > WGSL_INLINE_REPEAT && n.unsigned_abs() > 1 {
                        (ta, da) = hoist(lets, count, ta, da, true);
                    }
                    // Unrolled: a^n = a·a·…·a, 1 / that for n < 0 (powi's value up to rounding).
                    let mut text = String::from(if n < 0 { "(1.0 / (" } else { "(" });
                    if n == 0 {
                        text.push_str("1.0");
                    }
                    for k in 0..n.unsigned_abs() {
                        if k > 0 {
                            text.push_str(" * ");
                        }
                        write!(text, "({ta})").unwrap();
                    }
                    text.push_str(if n < 0 { "))" } else { ")" });
                    hoist(lets, count, text, da + 2, false)
                }
                None => {
                    let (ta, da) = a.write_wgsl(lets, count);
                    let (tb, db) = b.write_wgsl(lets, count);
                    hoist(lets, count, format!("pow({ta}, {tb})"), da.max(db) + 1, false)
                }
            },
            Expr::Binary(op, a, b) => {
                let (ta, da) = a.write_wgsl(lets, count);
                let (tb, db) = b.write_wgsl(lets, count);
                hoist(
                    lets,
                    count,
                    format!("({ta} {} {tb})", op.symbol()),
                    da.max(db) + 1,
                    false,
                )
            }
        }
    }

    /// The expression at r = 1, simplified as it is rebuilt (`r·x` becomes `x`, `−r·x` becomes
    /// `−x`): the same IEEE operations as the expression evaluated at r = 1, less the exact
    /// multiplications by ±1. The kernels and the CPU scorer compute torques at r = 1 and
    /// multiply by r themselves.
    pub fn at_unit_ratio(&self) -> Expr {
        match self {
            Expr::Var(Var::Ratio) => Expr::Const(1.0),
            Expr::Const(_) | Expr::Var(_) => self.clone(),
            Expr::Unary(Unary::Neg, a) => neg(a.at_unit_ratio()),
            Expr::Unary(op, a) => apply(*op, a.at_unit_ratio()),
            Expr::Binary(op, a, b) => {
                let (a, b) = (a.at_unit_ratio(), b.at_unit_ratio());
                match op {
                    Binary::Add => add(a, b),
                    Binary::Sub => sub(a, b),
                    Binary::Mul => mul(a, b),
                    Binary::Div => div(a, b),
                    Binary::Pow => pow(a, b),
                }
            }
        }
    }

    /// The expression as Rust source in f64 (the built-in laws' code, written by the build):
    /// parameter `i` is `p{i}`, the speed `w`, the ratio `r`; exp and tanh are the functions
    /// named by `exp` and `tanh` (libm's, or [`crate::numerics`]' vectorisable ones), the others
    /// libm's. One IEEE operation per node, in the order written: the value of [`Self::eval`]
    /// (bit for bit, with libm's exp and tanh).
    pub fn rust(&self, exp: &str, tanh: &str) -> String {
        match self {
            Expr::Const(c) if *c < 0.0 => format!("(-{:?}_f64)", -c),
            Expr::Const(c) => format!("{c:?}_f64"),
            Expr::Var(Var::Speed) => "w".into(),
            Expr::Var(Var::Ratio) => "r".into(),
            Expr::Var(Var::Param(i)) => format!("p{i}"),
            Expr::Unary(op, a) => {
                let a = a.rust(exp, tanh);
                match op {
                    Unary::Neg => format!("(-{a})"),
                    Unary::Exp => format!("{exp}({a})"),
                    Unary::Tanh => format!("{tanh}({a})"),
                    Unary::Ln => format!("f64::ln({a})"),
                    Unary::Sqrt => format!("f64::sqrt({a})"),
                    Unary::Abs => format!("f64::abs({a})"),
                    Unary::Sin => format!("f64::sin({a})"),
                    Unary::Cos => format!("f64::cos({a})"),
                    // sign(0) = 0, as WGSL's sign.
                    Unary::Sign => {
                        format!("{{ let v: f64 = {a}; if v == 0.0 || v.is_nan() {{ v }} else {{ v.signum() }} }}")
                    }
                }
            }
            Expr::Binary(Binary::Pow, a, b) => match small_integer(b) {
                Some(n) => format!("f64::powi({}, {n})", a.rust(exp, tanh)),
                // WGSL's pow is exp2(y·log2 x): no value for x < 0.
                None => format!(
                    "{{ let (x, y): (f64, f64) = ({}, {}); if x < 0.0 {{ f64::NAN }} else {{ x.powf(y) }} }}",
                    a.rust(exp, tanh),
                    b.rust(exp, tanh)
                ),
            },
            Expr::Binary(op, a, b) => format!("({} {} {})", a.rust(exp, tanh), op.symbol(), b.rust(exp, tanh)),
        }
    }

    /// An upper bound on the size of [`Self::derivative`]`(var)`, in one pass over the tree
    /// (simplification only shrinks the result): a product of n factors has a derivative of
    /// order n² nodes, which is refused by its bound before any of it is built.
    pub fn derivative_size_bound(&self) -> usize {
        self.sizes().1
    }

    /// (size, bound on the derivative's size).
    fn sizes(&self) -> (usize, usize) {
        let add = |terms: &[usize]| terms.iter().fold(0usize, |acc, &t| acc.saturating_add(t));
        match self {
            Expr::Const(_) | Expr::Var(_) => (1, 1),
            Expr::Unary(op, a) => {
                let (sa, da) = a.sizes();
                let outer = match op {
                    Unary::Neg | Unary::Sign => 0,
                    Unary::Tanh => add(&[2 * sa, 5]),
                    Unary::Sqrt => add(&[sa, 3]),
                    _ => add(&[sa, 2]),
                };
                (add(&[sa, 1]), add(&[outer, da, 1]))
            }
            Expr::Binary(op, a, b) => {
                let ((sa, da), (sb, db)) = (a.sizes(), b.sizes());
                let d = match op {
                    Binary::Add | Binary::Sub => add(&[da, db, 1]),
                    Binary::Mul => add(&[da, sb, sa, db, 3]),
                    Binary::Div => add(&[da, sb, sa, db, sb, sb, 5]),
                    Binary::Pow => add(&[sa, sb, sa, sb, da, db, sa, sb, 9]),
                };
                (add(&[sa, sb, 1]), d)
            }
        }
    }

    /// The first constant (folded constants included) that does not fit in an f32, the GPU's
    /// float: its value.
    pub fn constant_beyond_f32(&self) -> Option<f64> {
        match self {
            Expr::Const(c) if c.abs() > f64::from(f32::MAX) => Some(*c),
            Expr::Const(_) | Expr::Var(_) => None,
            Expr::Unary(_, a) => a.constant_beyond_f32(),
            Expr::Binary(_, a, b) => a.constant_beyond_f32().or_else(|| b.constant_beyond_f32()),
        }
    }
}

/// (text, nesting) of a WGSL subexpression: itself, or, nested [`WGSL_MAX_NESTING`] deep (or
/// when `force`d), a new `let` in `lets` holding it.
fn hoist(lets: &mut String, count: &mut usize, text: String, depth: usize, force: bool) -> (String, usize) {
    if depth < WGSL_MAX_NESTING && !force {
        return (text, depth);
    }
    let name = format!("t{count}");
    *count += 1;
    writeln!(lets, "    let {name} = {text};").unwrap();
    (name, 0)
}

/// Nesting of a WGSL subexpression beyond which it is bound to a `let`.
pub const WGSL_MAX_NESTING: usize = 24;
/// Characters beyond which an unrolled power's base is bound to a `let` instead of repeated.
pub const WGSL_INLINE_REPEAT: usize = 48;

#[cfg(test)]
mod tests {
    use super::*;

    fn compile(text: &str) -> Expr {
        parse(text, &["a", "b"]).unwrap().0
    }

    #[test]
    fn precedence_and_associativity_follow_arithmetic() {
        let v = |t: &str| compile(t).eval(&[2.0, 3.0], 0.5, 1.0f64);
        assert_eq!(v("1 + 2 * 3"), 7.0);
        assert_eq!(v("(1 + 2) * 3"), 9.0);
        assert_eq!(v("8 / 4 / 2"), 1.0);
        assert_eq!(v("10 - 4 - 3"), 3.0);
        assert_eq!(v("2 ^ 3 ^ 2"), 512.0);
        assert_eq!(v("-a^2"), -4.0);
        assert_eq!(v("a ** b"), 8.0);
        assert_eq!(v("2^-1"), 0.5);
        assert_eq!(v("pow(a, b) - a·b"), 2.0);
        assert_eq!(v("1.5e1 + .5 + 2E-1"), 15.7);
        assert_eq!(v("r * w * a"), 1.0);
        assert!((v("exp(ln(b)) + sqrt(a*a) + abs(-1) + sign(-3)") - 5.0).abs() < 1e-15);
        assert!((v("sin(pi/2) + cos(0) + tanh(0) + e") - (2.0 + std::f64::consts::E)).abs() < 1e-15);
    }

    #[test]
    fn errors_name_the_offset_and_what_is_wrong() {
        let err = |t: &str| parse(t, &["a", "b"]).unwrap_err();
        let e = err("a + q");
        assert_eq!(e.offset, 4);
        assert!(
            e.message.contains("unknown name 'q'") && e.message.contains("a, b"),
            "{e:?}"
        );
        let e = err("a * foo(w)");
        assert_eq!(e.offset, 4);
        assert!(e.message.contains("unknown function 'foo'"), "{e:?}");
        let e = err("b + exp(w, a)");
        assert_eq!((e.offset, e.message.as_str()), (4, "exp takes 1 argument, got 2"));
        let e = err("pow(w)");
        assert_eq!((e.offset, e.message.as_str()), (0, "pow takes 2 arguments, got 1"));
        assert_eq!(err("(a + b").offset, 6);
        assert_eq!(err("a b").offset, 2);
        assert_eq!(err("a + $").offset, 4);
        assert_eq!(err("a + ").offset, 4);
        assert_eq!(err("").message, "the expression is empty");
        assert!(err("tanh + 1").message.contains("is a function"));
        assert!(err("1e999").message.contains("too large"));
        // Hostile depth and length: refused, not a stack overflow.
        let deep = format!("{}w{}", "(".repeat(100_000), ")".repeat(100_000));
        assert!(
            err(&deep).message.contains("the expression is longer than"),
            "{:?}",
            err(&deep)
        );
        let nested = format!("{}w{}", "(".repeat(1_000), ")".repeat(1_000));
        assert!(
            err(&nested).message.contains("nests deeper than 64"),
            "{:?}",
            err(&nested)
        );
        assert!(err(&"-".repeat(5_000)).message.contains("nests deeper"));
        assert!(parse(&format!("{}w{}", "(".repeat(60), ")".repeat(60)), &[]).is_ok());
    }

    #[test]
    fn used_parameters_are_marked() {
        let (_, used) = parse("a * w", &["a", "b"]).unwrap();
        assert_eq!(used, vec![true, false]);
    }

    /// Central difference of `e` in `var` at (p, w, r), step h.
    fn finite_difference(e: &Expr, var: Var, p: &[f64], w: f64, r: f64, h: f64) -> f64 {
        let at = |d: f64| {
            let mut q = p.to_vec();
            let (mut w2, mut r2) = (w, r);
            match var {
                Var::Speed => w2 += d,
                Var::Ratio => r2 += d,
                Var::Param(i) => q[i] += d,
            }
            e.eval(&q, w2, r2)
        };
        (at(h) - at(-h)) / (2.0 * h)
    }

    #[test]
    fn derivatives_match_central_differences() {
        let texts = [
            "a * (tanh(b * w) + 2 * w / (1 + b * w^2))",
            "(a - b) * exp(-b * w) + b",
            "a * exp(-b * (w - 0.1)^2) + 3 - a * tanh(b * w)",
            "r * (a + w * (b + w * (0.3 + w * -0.01)))",
            "sqrt(a + w^2) * ln(b + w) / (1 + abs(w - 0.7))",
            "a^b * sin(w) - cos(b * w) + pow(w, a)",
            "a / w - b * w^-2 + e^(w / a)",
        ];
        let p = [1.3, 0.6];
        for text in texts {
            let e = compile(text);
            for var in [Var::Speed, Var::Ratio, Var::Param(0), Var::Param(1)] {
                let d = e.derivative(var);
                for w in [0.35, 1.1, 2.9] {
                    let exact = d.eval(&p, w, 0.8);
                    let numeric = finite_difference(&e, var, &p, w, 0.8, 1e-6);
                    let scale = exact.abs().max(1.0);
                    assert!(
                        (exact - numeric).abs() < 1e-7 * scale,
                        "d/d{var:?} of {text} at w = {w}: {exact} against {numeric}"
                    );
                }
            }
        }
    }

    #[test]
    fn simplification_keeps_derivatives_short() {
        let d = compile("a + b * w").derivative(Var::Speed);
        assert_eq!(d, Expr::Var(Var::Param(1)));
        let d = compile("3 * w^2").derivative(Var::Speed);
        assert_eq!(d.wgsl(), "(3.0 * (2.0 * w))");
        assert_eq!(compile("a").derivative(Var::Speed), Expr::Const(0.0));
    }

    #[test]
    fn wgsl_text_spells_constants_powers_and_functions() {
        assert_eq!(compile("-2.5e-7 * w").wgsl(), "((-2.5e-7) * w)");
        assert_eq!(compile("-(2 * w)").wgsl(), "-((2.0 * w))");
        // Constants fold as they are read: 3^2 is the integer power 9.
        assert_eq!(compile("(0 - 2.5) * w^3").wgsl(), "((-2.5) * ((w) * (w) * (w)))");
        assert_eq!(compile("w^3^2"), compile("w^9"));
        // A real power of a negative base has no value, on both paths.
        assert!(compile("pow(w - 1, a)").eval(&[1.5, 0.0], 0.5, 1.0f64).is_nan());
        assert_eq!(compile("w^-2").wgsl(), "(1.0 / ((w) * (w)))");
        assert_eq!(compile("w^0").wgsl(), "(1.0)");
        assert_eq!(compile("pow(w, a)").wgsl(), "pow(w, p[0])");
        assert_eq!(
            compile("exp(tanh(sin(cos(ln(w)))))").wgsl(),
            "exp_f32(tanh_f32(sin_f32(cos_f32(log(w)))))"
        );
    }
}
