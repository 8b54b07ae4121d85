//! The functions and operators the language knows, by name and by lane.
//!
//! Kept apart from the compiler and the machine so the language's
//! vocabulary and its numeric meaning (ExprTk's: 1/0 truth values, C
//! `fmod`, `sgn`, `sinc`, …) live in one table each: the compiler looks
//! names up here, the machine applies them here, and adding a function
//! touches only this file and the compiler's arity rules.

use super::{Lanes, LANES};
use crate::syntax::BinOp;

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Fn1 {
    Square,
    Cube,
    Neg,
    Not,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Sinh,
    Cosh,
    Tanh,
    Exp,
    Expm1,
    Log,
    Log1p,
    Log2,
    Log10,
    Sqrt,
    Cbrt,
    Abs,
    Floor,
    Ceil,
    Round,
    Trunc,
    Frac,
    Sgn,
    Deg2Rad,
    Rad2Deg,
    Erf,
    Erfc,
    Sinc,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Fn2 {
    Op(BinOp),
    Atan2,
    Min,
    Max,
    Hypot,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Fn3 {
    Clamp,
    InRange,
}

pub(super) const FUNCTIONS_1: &[(&str, Fn1)] = &[
    ("sin", Fn1::Sin),
    ("cos", Fn1::Cos),
    ("tan", Fn1::Tan),
    ("asin", Fn1::Asin),
    ("acos", Fn1::Acos),
    ("atan", Fn1::Atan),
    ("sinh", Fn1::Sinh),
    ("cosh", Fn1::Cosh),
    ("tanh", Fn1::Tanh),
    ("exp", Fn1::Exp),
    ("expm1", Fn1::Expm1),
    ("log", Fn1::Log),
    ("log1p", Fn1::Log1p),
    ("log2", Fn1::Log2),
    ("log10", Fn1::Log10),
    ("sqrt", Fn1::Sqrt),
    ("cbrt", Fn1::Cbrt),
    ("abs", Fn1::Abs),
    ("floor", Fn1::Floor),
    ("ceil", Fn1::Ceil),
    ("round", Fn1::Round),
    ("trunc", Fn1::Trunc),
    ("frac", Fn1::Frac),
    ("sgn", Fn1::Sgn),
    ("deg2rad", Fn1::Deg2Rad),
    ("rad2deg", Fn1::Rad2Deg),
    ("erf", Fn1::Erf),
    ("erfc", Fn1::Erfc),
    ("sinc", Fn1::Sinc),
    ("not", Fn1::Not),
];

/// Every function name the language knows, for error messages.
pub fn function_names() -> Vec<&'static str> {
    let mut names: Vec<&str> = FUNCTIONS_1.iter().map(|(n, _)| *n).collect();
    names.extend(["atan2", "pow", "hypot", "mod", "min", "max", "sum", "avg", "clamp", "inrange", "if"]);
    names.sort_unstable();
    names
}

fn truthy(x: f64) -> bool {
    x != 0.0
}

fn bool_f(b: bool) -> f64 {
    b as u8 as f64
}

#[inline]
pub(super) fn apply1(f: Fn1, a: &Lanes, out: &mut Lanes) {
    macro_rules! each {
        ($x:ident => $e:expr) => {
            for i in 0..LANES {
                let $x = a[i];
                out[i] = $e;
            }
        };
    }
    match f {
        Fn1::Square => each!(x => x * x),
        Fn1::Cube => each!(x => x * x * x),
        Fn1::Neg => each!(x => -x),
        Fn1::Not => each!(x => bool_f(!truthy(x))),
        Fn1::Sin => each!(x => x.sin()),
        Fn1::Cos => each!(x => x.cos()),
        Fn1::Tan => each!(x => x.tan()),
        Fn1::Asin => each!(x => x.asin()),
        Fn1::Acos => each!(x => x.acos()),
        Fn1::Atan => each!(x => x.atan()),
        Fn1::Sinh => each!(x => x.sinh()),
        Fn1::Cosh => each!(x => x.cosh()),
        Fn1::Tanh => each!(x => x.tanh()),
        Fn1::Exp => each!(x => x.exp()),
        Fn1::Expm1 => each!(x => x.exp_m1()),
        Fn1::Log => each!(x => x.ln()),
        Fn1::Log1p => each!(x => x.ln_1p()),
        Fn1::Log2 => each!(x => x.log2()),
        Fn1::Log10 => each!(x => x.log10()),
        Fn1::Sqrt => each!(x => x.sqrt()),
        Fn1::Cbrt => each!(x => x.cbrt()),
        Fn1::Abs => each!(x => x.abs()),
        Fn1::Floor => each!(x => x.floor()),
        Fn1::Ceil => each!(x => x.ceil()),
        Fn1::Round => each!(x => x.round()),
        Fn1::Trunc => each!(x => x.trunc()),
        Fn1::Frac => each!(x => x - x.trunc()),
        Fn1::Sgn => each!(x => if x > 0.0 { 1.0 } else if x < 0.0 { -1.0 } else { 0.0 }),
        Fn1::Deg2Rad => each!(x => x.to_radians()),
        Fn1::Rad2Deg => each!(x => x.to_degrees()),
        Fn1::Erf => each!(x => libm::erf(x)),
        Fn1::Erfc => each!(x => libm::erfc(x)),
        Fn1::Sinc => each!(x => if x == 0.0 { 1.0 } else { x.sin() / x }),
    }
}

#[inline]
pub(super) fn apply2(f: Fn2, a: &Lanes, b: &Lanes, out: &mut Lanes) {
    macro_rules! each {
        (($x:ident, $y:ident) => $e:expr) => {
            for i in 0..LANES {
                let ($x, $y) = (a[i], b[i]);
                out[i] = $e;
            }
        };
    }
    match f {
        Fn2::Op(op) => match op {
            BinOp::Add => each!((x, y) => x + y),
            BinOp::Sub => each!((x, y) => x - y),
            BinOp::Mul => each!((x, y) => x * y),
            BinOp::Div => each!((x, y) => x / y),
            BinOp::Mod => each!((x, y) => x % y),
            BinOp::Pow => each!((x, y) => x.powf(y)),
            BinOp::Lt => each!((x, y) => bool_f(x < y)),
            BinOp::Le => each!((x, y) => bool_f(x <= y)),
            BinOp::Gt => each!((x, y) => bool_f(x > y)),
            BinOp::Ge => each!((x, y) => bool_f(x >= y)),
            BinOp::Eq => each!((x, y) => bool_f(x == y)),
            BinOp::Ne => each!((x, y) => bool_f(x != y)),
            BinOp::And => each!((x, y) => bool_f(truthy(x) && truthy(y))),
            BinOp::Or => each!((x, y) => bool_f(truthy(x) || truthy(y))),
            BinOp::Xor => each!((x, y) => bool_f(truthy(x) != truthy(y))),
            BinOp::Nand => each!((x, y) => bool_f(!(truthy(x) && truthy(y)))),
            BinOp::Nor => each!((x, y) => bool_f(!(truthy(x) || truthy(y)))),
        },
        Fn2::Atan2 => each!((x, y) => x.atan2(y)),
        Fn2::Min => each!((x, y) => x.min(y)),
        Fn2::Max => each!((x, y) => x.max(y)),
        Fn2::Hypot => each!((x, y) => x.hypot(y)),
    }
}
