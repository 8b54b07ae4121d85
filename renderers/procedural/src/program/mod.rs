//! Compiling a parsed scene program, and running it on 64 samples at once.
//!
//! Compilation resolves every name to a **slot** — a row of [`LANES`]
//! doubles, one per sample of a batch — so running needs no string look-up
//! and no allocation. Expression temporaries get slots by depth at compile
//! time. Control flow is per sample: each statement runs under a 64-bit
//! mask of live lanes; `if` splits the mask, loops run while any lane is
//! live, `break`/`continue` retire lanes. Stores honour the mask; pure
//! arithmetic runs on all lanes (so loops over lanes vectorise).
//!
//! Semantics (ExprTk's where it has them): all values are doubles; `true`
//! is 1 and `false` 0, any non-zero (NaN included) is true; `and`/`or`
//! evaluate both operands; `%` is C `fmod`; division by zero gives ±inf or
//! NaN (IEEE); `frac(x) = x − trunc(x)`; `round` rounds half away from zero;
//! `clamp(lo, x, hi)`; reading an array out of range gives NaN and writing
//! out of range does nothing; a feature read before it is assigned is 0; a
//! loop that runs more than [`MAX_LOOP_ITERATIONS`] times is a runtime error.
//!
//! The compiled form (`CExpr`, `Op`, `CStmt`) is defined here because both
//! halves read it: `compile` produces and rewrites it, `machine` runs it;
//! `builtins` holds the functions both of them name.

mod builtins;
mod compile;
mod machine;

pub use builtins::function_names;
pub use machine::Machine;

use crate::syntax::Pos;
use builtins::{Fn1, Fn2, Fn3};
use fbksd_core::{Feature, RandomParameter};

/// Samples evaluated together.
pub const LANES: usize = 64;
/// A lane mask.
pub type Mask = u64;
/// Every lane.
pub const ALL: Mask = u64::MAX;
/// Iterations a loop may run in one batch before it is an error.
pub const MAX_LOOP_ITERATIONS: u64 = 10_000_000;

type Lanes = [f64; LANES];

/// A compiled expression: either a slot read directly, or an operation that
/// writes its result into its own temporary slot `dst`.
#[derive(Debug, Clone)]
enum CExpr {
    Slot(usize),
    Op { dst: usize, op: Box<Op> },
}

#[derive(Debug, Clone)]
enum Op {
    Call1(Fn1, CExpr),
    Call2(Fn2, CExpr, CExpr),
    Call3(Fn3, CExpr, CExpr, CExpr),
    Select(CExpr, CExpr, CExpr),
    Gather {
        base: usize,
        len: usize,
        index: CExpr,
    },
    /// `keep`: the assignment's value is used by an enclosing expression,
    /// so it is copied into the operation's own slot (a later assignment to
    /// the same variable must not change it, as in `(x := 2) + (x := 3)`).
    Store {
        target: usize,
        value: CExpr,
        keep: bool,
    },
    Scatter {
        base: usize,
        len: usize,
        index: CExpr,
        value: CExpr,
        keep: bool,
    },
}

#[derive(Debug, Clone)]
enum CStmt {
    Eval(CExpr),
    If { cond: CExpr, then: Vec<CStmt>, otherwise: Vec<CStmt> },
    While { cond: CExpr, body: Vec<CStmt>, step: Option<CExpr>, pos: Pos },
    Break,
    Continue,
}

/// A compiled program, ready to be specialised for a layout and run.
#[derive(Debug, Clone)]
pub struct Program {
    stmts: Vec<CStmt>,
    /// A slot holding 0 in every lane.
    zero: usize,
    slots: usize,
    constants: Vec<(usize, f64)>,
    parameters: [Option<usize>; 7],
    features: Vec<(Feature, u8, usize)>,
}

/// A runtime error with the source position of its cause.
#[derive(Debug, Clone, PartialEq)]
pub struct RuntimeError {
    /// Where.
    pub pos: Pos,
    /// What.
    pub message: String,
}

impl Program {
    /// Whether the program reads (or names) a random parameter.
    pub fn uses(&self, p: RandomParameter) -> bool {
        self.parameters[p.index()].is_some()
    }

    /// The slot of a random parameter, if the program uses it.
    pub fn parameter_slot(&self, p: RandomParameter) -> Option<usize> {
        self.parameters[p.index()]
    }

    /// The slot of a feature, if the program names it.
    pub fn feature_slot(&self, f: Feature, number: u8) -> Option<usize> {
        self.features.iter().find(|(g, n, _)| *g == f && *n == number).map(|(_, _, s)| *s)
    }

    /// The features the program assigns or reads.
    pub fn features(&self) -> impl Iterator<Item = (Feature, u8)> + '_ {
        self.features.iter().map(|(f, n, _)| (*f, *n))
    }
}
