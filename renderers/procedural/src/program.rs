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

use crate::syntax::{BinOp, Expr, Pos, SourceError, Stmt};
use fbksd_core::{Feature, RandomParameter};
use std::collections::HashMap;

/// Samples evaluated together.
pub const LANES: usize = 64;
/// A lane mask.
pub type Mask = u64;
/// Every lane.
pub const ALL: Mask = u64::MAX;
/// Iterations a loop may run in one batch before it is an error.
pub const MAX_LOOP_ITERATIONS: u64 = 10_000_000;

type Lanes = [f64; LANES];

#[derive(Debug, Clone, Copy, PartialEq)]
enum Fn1 {
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
enum Fn2 {
    Op(BinOp),
    Atan2,
    Min,
    Max,
    Hypot,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Fn3 {
    Clamp,
    InRange,
}

const FUNCTIONS_1: &[(&str, Fn1)] = &[
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

#[derive(Debug, Clone, Copy)]
enum Symbol {
    Constant(usize),
    Parameter(RandomParameter, usize),
    Feature(usize),
    Scalar(usize),
    Array(usize, usize),
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

struct Compiler {
    scopes: Vec<HashMap<String, Symbol>>,
    slots: usize,
    constants: Vec<(usize, f64)>,
    constant_slots: HashMap<u64, usize>,
    parameters: [Option<usize>; 7],
    features: Vec<(Feature, u8, usize)>,
    /// Temporary slots are numbered by depth and offset at the end.
    max_depth: usize,
    loop_depth: usize,
}

const TEMP_BASE: usize = 1 << 24;

impl Compiler {
    fn constant(&mut self, value: f64) -> usize {
        if let Some(&s) = self.constant_slots.get(&value.to_bits()) {
            return s;
        }
        let s = self.new_slot(1);
        self.constants.push((s, value));
        self.constant_slots.insert(value.to_bits(), s);
        s
    }

    fn new_slot(&mut self, n: usize) -> usize {
        let s = self.slots;
        self.slots += n;
        s
    }

    fn temp(&mut self, depth: usize) -> usize {
        self.max_depth = self.max_depth.max(depth + 1);
        TEMP_BASE + depth
    }

    fn lookup(&mut self, name: &str, pos: Pos) -> Result<Symbol, SourceError> {
        for scope in self.scopes.iter().rev() {
            if let Some(s) = scope.get(name) {
                return Ok(*s);
            }
        }
        if let Some(p) = RandomParameter::from_name(name) {
            let slot = match self.parameters[p.index()] {
                Some(s) => s,
                None => {
                    let s = self.new_slot(1);
                    self.parameters[p.index()] = Some(s);
                    s
                }
            };
            return Ok(Symbol::Parameter(p, slot));
        }
        let (base, number) = match name.strip_suffix("_1") {
            Some(b) if Feature::from_name(b).is_some_and(Feature::is_numbered) => (b, 1u8),
            _ => (name, 0u8),
        };
        if let Some(f) = Feature::from_name(base) {
            if let Some(&(_, _, s)) = self.features.iter().find(|(g, n, _)| *g == f && *n == number) {
                return Ok(Symbol::Feature(s));
            }
            let s = self.new_slot(1);
            self.features.push((f, number, s));
            return Ok(Symbol::Feature(s));
        }
        let constant = match name {
            "pi" => Some(std::f64::consts::PI),
            "epsilon" => Some(f64::EPSILON),
            "inf" => Some(f64::INFINITY),
            "true" => Some(1.0),
            "false" => Some(0.0),
            _ => None,
        };
        if let Some(v) = constant {
            return Ok(Symbol::Constant(self.constant(v)));
        }
        Err(SourceError::new(
            pos,
            format!("unknown name '{name}': not declared with 'var', not a random parameter, feature or constant"),
        ))
    }

    fn expr(&mut self, e: &Expr, depth: usize) -> Result<CExpr, SourceError> {
        let op = |dst, op| Ok(CExpr::Op { dst, op: Box::new(op) });
        match e {
            Expr::Num(n) => Ok(CExpr::Slot(self.constant(*n))),
            Expr::Name(name, pos) => match self.lookup(name, *pos)? {
                Symbol::Constant(s) | Symbol::Parameter(_, s) | Symbol::Feature(s) | Symbol::Scalar(s) => {
                    Ok(CExpr::Slot(s))
                }
                Symbol::Array(..) => {
                    Err(SourceError::new(*pos, format!("'{name}' is an array: index it, as in {name}[0]")))
                }
            },
            Expr::Index(name, index, pos) => {
                let Symbol::Array(base, len) = self.lookup(name, *pos)? else {
                    return Err(SourceError::new(*pos, format!("'{name}' is not an array")));
                };
                // A constant index reads the element's slot directly.
                if let Some(k) = constant_index(index) {
                    return if k >= 0.0 && (k as usize) < len {
                        Ok(CExpr::Slot(base + k as usize))
                    } else {
                        Err(SourceError::new(*pos, format!("index {k} is outside '{name}' (size {len})")))
                    };
                }
                let index = self.expr(index, depth + 1)?;
                let dst = self.temp(depth);
                op(dst, Op::Gather { base, len, index })
            }
            Expr::Neg(a) => {
                let a = self.expr(a, depth + 1)?;
                let dst = self.temp(depth);
                op(dst, Op::Call1(Fn1::Neg, a))
            }
            Expr::Not(a) => {
                let a = self.expr(a, depth + 1)?;
                let dst = self.temp(depth);
                op(dst, Op::Call1(Fn1::Not, a))
            }
            // Small constant powers as products: exact, branch-free, fast.
            Expr::Binary(BinOp::Pow, l, r) if matches!(**r, Expr::Num(n) if n == 2.0 || n == 3.0 || n == 0.5) => {
                let Expr::Num(n) = **r else { unreachable!() };
                let f = if n == 2.0 {
                    Fn1::Square
                } else if n == 3.0 {
                    Fn1::Cube
                } else {
                    Fn1::Sqrt
                };
                let l = self.expr(l, depth + 1)?;
                let dst = self.temp(depth);
                op(dst, Op::Call1(f, l))
            }
            Expr::Binary(b, l, r) => {
                let l = self.expr(l, depth + 1)?;
                let r = self.expr(r, depth + 2)?;
                let dst = self.temp(depth);
                op(dst, Op::Call2(Fn2::Op(*b), l, r))
            }
            Expr::Ternary(c, a, b) => {
                let c = self.expr(c, depth + 1)?;
                let a = self.expr(a, depth + 2)?;
                let b = self.expr(b, depth + 3)?;
                let dst = self.temp(depth);
                op(dst, Op::Select(c, a, b))
            }
            Expr::Call(name, args, pos) => self.call(name, args, *pos, depth),
            Expr::Assign { target, op: aop, value, pos } => {
                // x op= v is x := x op v.
                let value = match aop {
                    None => (**value).clone(),
                    Some(b) => Expr::Binary(*b, target.clone(), value.clone()),
                };
                match &**target {
                    Expr::Name(name, npos) => {
                        let slot = match self.lookup(name, *npos)? {
                            Symbol::Scalar(s) | Symbol::Feature(s) => s,
                            Symbol::Parameter(p, _) => {
                                return Err(SourceError::new(
                                    *pos,
                                    format!("{p} is a random parameter: it can be read, not assigned"),
                                ))
                            }
                            Symbol::Constant(_) => {
                                return Err(SourceError::new(
                                    *pos,
                                    format!("'{name}' is a constant: it can be read, not assigned"),
                                ))
                            }
                            Symbol::Array(..) => {
                                return Err(SourceError::new(
                                    *pos,
                                    format!("'{name}' is an array: assign its elements, as in {name}[0] := …"),
                                ))
                            }
                        };
                        let value = self.expr(&value, depth + 1)?;
                        let dst = self.temp(depth);
                        op(dst, Op::Store { target: slot, value, keep: true })
                    }
                    Expr::Index(name, index, ipos) => {
                        let Symbol::Array(base, len) = self.lookup(name, *ipos)? else {
                            return Err(SourceError::new(*ipos, format!("'{name}' is not an array")));
                        };
                        if let Some(k) = constant_index(index) {
                            if k < 0.0 || k as usize >= len {
                                return Err(SourceError::new(
                                    *ipos,
                                    format!("index {k} is outside '{name}' (size {len})"),
                                ));
                            }
                        }
                        let index = self.expr(index, depth + 1)?;
                        let value = self.expr(&value, depth + 2)?;
                        let dst = self.temp(depth);
                        op(dst, Op::Scatter { base, len, index, value, keep: true })
                    }
                    _ => unreachable!("the parser only builds assignments to names and elements"),
                }
            }
        }
    }

    fn call(&mut self, name: &str, args: &[Expr], pos: Pos, depth: usize) -> Result<CExpr, SourceError> {
        let arity = |n: usize| -> Result<(), SourceError> {
            if args.len() == n {
                Ok(())
            } else {
                Err(SourceError::new(
                    pos,
                    format!("{name}() takes {n} argument{}, got {}", if n == 1 { "" } else { "s" }, args.len()),
                ))
            }
        };
        let op = |dst, op| Ok(CExpr::Op { dst, op: Box::new(op) });
        if let Some((_, f)) = FUNCTIONS_1.iter().find(|(n, _)| *n == name) {
            arity(1)?;
            let a = self.expr(&args[0], depth + 1)?;
            let dst = self.temp(depth);
            return op(dst, Op::Call1(*f, a));
        }
        let two = match name {
            "atan2" => Some(Fn2::Atan2),
            "pow" => Some(Fn2::Op(BinOp::Pow)),
            "hypot" => Some(Fn2::Hypot),
            "mod" => Some(Fn2::Op(BinOp::Mod)),
            _ => None,
        };
        if let Some(f) = two {
            arity(2)?;
            let a = self.expr(&args[0], depth + 1)?;
            let b = self.expr(&args[1], depth + 2)?;
            let dst = self.temp(depth);
            return op(dst, Op::Call2(f, a, b));
        }
        match name {
            // Variadic: folded left into binary nodes, f(f(a, b), c)…; avg divides the sum.
            "min" | "max" | "sum" | "avg" => {
                if args.is_empty() {
                    return Err(SourceError::new(pos, format!("{name}() needs at least one argument")));
                }
                let pairwise = if name == "avg" { "\0sum".to_string() } else { format!("\0{name}") };
                let folded = args[1..]
                    .iter()
                    .fold(args[0].clone(), |acc, a| Expr::Call(pairwise.clone(), vec![acc, a.clone()], pos));
                let whole = if name == "avg" {
                    Expr::Binary(BinOp::Div, Box::new(folded), Box::new(Expr::Num(args.len() as f64)))
                } else {
                    folded
                };
                self.expr(&whole, depth)
            }
            "\0min" | "\0max" | "\0sum" => {
                let f = match name {
                    "\0min" => Fn2::Min,
                    "\0max" => Fn2::Max,
                    _ => Fn2::Op(BinOp::Add),
                };
                let a = self.expr(&args[0], depth + 1)?;
                let b = self.expr(&args[1], depth + 2)?;
                let dst = self.temp(depth);
                op(dst, Op::Call2(f, a, b))
            }
            "clamp" | "inrange" => {
                arity(3)?;
                let a = self.expr(&args[0], depth + 1)?;
                let b = self.expr(&args[1], depth + 2)?;
                let c = self.expr(&args[2], depth + 3)?;
                let dst = self.temp(depth);
                op(dst, Op::Call3(if name == "clamp" { Fn3::Clamp } else { Fn3::InRange }, a, b, c))
            }
            "if" => {
                arity(3)?;
                self.expr(
                    &Expr::Ternary(Box::new(args[0].clone()), Box::new(args[1].clone()), Box::new(args[2].clone())),
                    depth,
                )
            }
            _ => Err(SourceError::new(
                pos,
                format!("unknown function '{name}' (known: {})", function_names().join(", ")),
            )),
        }
    }

    fn stmts(&mut self, stmts: &[Stmt]) -> Result<Vec<CStmt>, SourceError> {
        self.scopes.push(HashMap::new());
        let out = stmts.iter().map(|s| self.stmt(s)).collect::<Result<Vec<_>, _>>();
        self.scopes.pop();
        Ok(out?.into_iter().flatten().collect())
    }

    fn stmt(&mut self, s: &Stmt) -> Result<Vec<CStmt>, SourceError> {
        Ok(match s {
            Stmt::Var { name, size, init, pos } => {
                if self.scopes.last().unwrap().contains_key(name) {
                    return Err(SourceError::new(*pos, format!("'{name}' is already declared in this scope")));
                }
                if RandomParameter::from_name(name).is_some()
                    || Feature::from_name(name.trim_end_matches("_1")).is_some()
                {
                    return Err(SourceError::new(
                        *pos,
                        format!("'{name}' is a random parameter or feature name; choose another"),
                    ));
                }
                // Initial values are compiled before the name exists (`var x := x` is an error).
                let values = init.iter().map(|e| self.expr(e, 1)).collect::<Result<Vec<_>, _>>()?;
                let n = size.unwrap_or(1);
                let base = self.new_slot(n);
                let symbol = if size.is_some() { Symbol::Array(base, n) } else { Symbol::Scalar(base) };
                self.scopes.last_mut().unwrap().insert(name.clone(), symbol);
                let zero = self.constant(0.0);
                (0..n)
                    .map(|i| {
                        let value = values.get(i).cloned().unwrap_or(CExpr::Slot(zero));
                        let dst = self.temp(0);
                        CStmt::Eval(CExpr::Op { dst, op: Box::new(Op::Store { target: base + i, value, keep: false }) })
                    })
                    .collect()
            }
            Stmt::Expr(e) => {
                let mut compiled = self.expr(e, 0)?;
                // A statement's own assignment: its value is not used.
                if let CExpr::Op { op, .. } = &mut compiled {
                    if let Op::Store { keep, .. } | Op::Scatter { keep, .. } = &mut **op {
                        *keep = false;
                    }
                }
                vec![CStmt::Eval(compiled)]
            }
            Stmt::Block(b) => self.stmts(b)?,
            Stmt::If { cond, then, otherwise } => {
                vec![CStmt::If {
                    cond: self.expr(cond, 0)?,
                    then: self.stmts(then)?,
                    otherwise: self.stmts(otherwise)?,
                }]
            }
            Stmt::While { cond, body, step, pos } => {
                let cond = self.expr(cond, 0)?;
                self.loop_depth += 1;
                let body = self.stmts(body);
                self.loop_depth -= 1;
                let step = step.as_ref().map(|e| self.expr(e, 0)).transpose()?;
                vec![CStmt::While { cond, body: body?, step, pos: *pos }]
            }
            Stmt::Break(pos) | Stmt::Continue(pos) if self.loop_depth == 0 => {
                return Err(SourceError::new(*pos, "'break' and 'continue' belong inside a loop"))
            }
            Stmt::Break(_) => vec![CStmt::Break],
            Stmt::Continue(_) => vec![CStmt::Continue],
        })
    }
}

impl Program {
    /// Compiles a program. `constants` are read-only names (the scene
    /// header's `width`, `height`, `spp`).
    pub fn compile(stmts: &[Stmt], constants: &[(&str, f64)]) -> Result<Program, SourceError> {
        let mut c = Compiler {
            scopes: vec![HashMap::new()],
            slots: 0,
            constants: Vec::new(),
            constant_slots: HashMap::new(),
            parameters: [None; 7],
            features: Vec::new(),
            max_depth: 0,
            loop_depth: 0,
        };
        for (name, value) in constants {
            let s = c.new_slot(1);
            c.constants.push((s, *value));
            c.scopes[0].insert(name.to_string(), Symbol::Constant(s));
        }
        let zero = c.constant(0.0);
        let mut stmts = c.stmts(stmts)?;
        // Temporaries go after every named slot.
        let temp_base = c.slots;
        for s in &mut stmts {
            relocate_stmt(s, temp_base);
        }
        Ok(Program {
            stmts,
            zero,
            slots: temp_base + c.max_depth + 4,
            constants: c.constants,
            parameters: c.parameters,
            features: c.features,
        })
    }

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

    /// The program cut down to what computes `wanted` features: statements
    /// that write nothing later needed are dropped, also inside `if`
    /// branches (loops are kept or dropped whole).
    pub fn specialise(&self, wanted: &[(Feature, u8)]) -> Program {
        let mut live: Vec<bool> = vec![false; self.slots];
        for (f, n) in wanted {
            if let Some(s) = self.feature_slot(*f, *n) {
                live[s] = true;
            }
        }
        Program { stmts: slice(&self.stmts, &mut live), ..self.clone() }
    }

    /// Number of statements, nested ones included (for tests of specialisation).
    pub fn statement_count(&self) -> usize {
        fn count(stmts: &[CStmt]) -> usize {
            stmts
                .iter()
                .map(|s| match s {
                    CStmt::If { then, otherwise, .. } => 1 + count(then) + count(otherwise),
                    CStmt::While { body, .. } => 1 + count(body),
                    _ => 1,
                })
                .sum()
        }
        count(&self.stmts)
    }
}

/// The statements of `stmts` that contribute to slots in `live`, which
/// grows by what they read (a backward pass; conservative: never shrinks).
fn slice(stmts: &[CStmt], live: &mut [bool]) -> Vec<CStmt> {
    let mut kept = Vec::new();
    for stmt in stmts.iter().rev() {
        if let CStmt::If { cond, then, otherwise } = stmt {
            let (mut live_then, mut live_else) = (live.to_vec(), live.to_vec());
            let (then, otherwise) = (slice(then, &mut live_then), slice(otherwise, &mut live_else));
            if then.is_empty() && otherwise.is_empty() {
                continue;
            }
            for ((l, t), e) in live.iter_mut().zip(&live_then).zip(&live_else) {
                *l = *l || *t || *e;
            }
            let (mut reads, mut writes) = (Vec::new(), Vec::new());
            expr_slots(cond, &mut reads, &mut writes);
            for r in reads.into_iter().chain(writes) {
                live[r] = true;
            }
            kept.push(CStmt::If { cond: cond.clone(), then, otherwise });
            continue;
        }
        let (mut reads, mut writes) = (Vec::new(), Vec::new());
        stmt_slots(stmt, &mut reads, &mut writes);
        if writes.iter().any(|w| live[*w]) {
            for r in reads {
                live[r] = true;
            }
            kept.push(stmt.clone());
        }
    }
    kept.reverse();
    kept
}

/// The index of `a[k]` when `k` is a literal (possibly negated), floored.
fn constant_index(index: &Expr) -> Option<f64> {
    match index {
        Expr::Num(k) => Some(k.floor()),
        Expr::Neg(inner) => match **inner {
            Expr::Num(k) => Some((-k).floor()),
            _ => None,
        },
        _ => None,
    }
}

fn relocate(e: &mut CExpr, base: usize) {
    let fix = |s: &mut usize| {
        if *s >= TEMP_BASE {
            *s = *s - TEMP_BASE + base;
        }
    };
    match e {
        CExpr::Slot(s) => fix(s),
        CExpr::Op { dst, op } => {
            fix(dst);
            match &mut **op {
                Op::Call1(_, a) => relocate(a, base),
                Op::Call2(_, a, b) => {
                    relocate(a, base);
                    relocate(b, base);
                }
                Op::Call3(_, a, b, c) | Op::Select(a, b, c) => {
                    relocate(a, base);
                    relocate(b, base);
                    relocate(c, base);
                }
                Op::Gather { index, .. } => relocate(index, base),
                Op::Store { value, .. } => relocate(value, base),
                Op::Scatter { index, value, .. } => {
                    relocate(index, base);
                    relocate(value, base);
                }
            }
        }
    }
}

fn relocate_stmt(s: &mut CStmt, base: usize) {
    match s {
        CStmt::Eval(e) => relocate(e, base),
        CStmt::If { cond, then, otherwise } => {
            relocate(cond, base);
            then.iter_mut().chain(otherwise.iter_mut()).for_each(|s| relocate_stmt(s, base));
        }
        CStmt::While { cond, body, step, .. } => {
            relocate(cond, base);
            body.iter_mut().for_each(|s| relocate_stmt(s, base));
            if let Some(step) = step {
                relocate(step, base);
            }
        }
        CStmt::Break | CStmt::Continue => {}
    }
}

fn expr_slots(e: &CExpr, reads: &mut Vec<usize>, writes: &mut Vec<usize>) {
    let CExpr::Op { op, .. } = e else {
        if let CExpr::Slot(s) = e {
            reads.push(*s);
        }
        return;
    };
    match &**op {
        Op::Call1(_, a) => expr_slots(a, reads, writes),
        Op::Call2(_, a, b) => {
            expr_slots(a, reads, writes);
            expr_slots(b, reads, writes);
        }
        Op::Call3(_, a, b, c) | Op::Select(a, b, c) => {
            expr_slots(a, reads, writes);
            expr_slots(b, reads, writes);
            expr_slots(c, reads, writes);
        }
        Op::Gather { base, len, index } => {
            reads.extend(*base..*base + *len);
            expr_slots(index, reads, writes);
        }
        Op::Store { target, value, .. } => {
            writes.push(*target);
            expr_slots(value, reads, writes);
        }
        Op::Scatter { base, len, index, value, .. } => {
            writes.extend(*base..*base + *len);
            // An element write keeps the other elements: the array is read too.
            reads.extend(*base..*base + *len);
            expr_slots(index, reads, writes);
            expr_slots(value, reads, writes);
        }
    }
}

fn stmt_slots(s: &CStmt, reads: &mut Vec<usize>, writes: &mut Vec<usize>) {
    match s {
        CStmt::Eval(e) => expr_slots(e, reads, writes),
        CStmt::If { cond, then, otherwise } => {
            expr_slots(cond, reads, writes);
            then.iter().chain(otherwise).for_each(|s| stmt_slots(s, reads, writes));
            // A conditional write keeps the old value in other lanes.
            let w = writes.clone();
            reads.extend(w);
        }
        CStmt::While { cond, body, step, .. } => {
            expr_slots(cond, reads, writes);
            body.iter().for_each(|s| stmt_slots(s, reads, writes));
            if let Some(step) = step {
                expr_slots(step, reads, writes);
            }
            let w = writes.clone();
            reads.extend(w);
        }
        CStmt::Break | CStmt::Continue => {}
    }
}

/// Runs a program on batches of [`LANES`] samples. One per thread.
pub struct Machine<'p> {
    program: &'p Program,
    slots: Vec<Lanes>,
}

#[derive(Default)]
struct LoopState {
    broken: Mask,
    continued: Mask,
}

impl<'p> Machine<'p> {
    /// A machine with the program's constants loaded.
    pub fn new(program: &'p Program) -> Self {
        let mut slots = vec![[0.0; LANES]; program.slots];
        for (s, v) in &program.constants {
            slots[*s] = [*v; LANES];
        }
        Machine { program, slots }
    }

    /// The lanes of a slot (parameters are written here before [`Self::run`]).
    pub fn slot_mut(&mut self, slot: usize) -> &mut [f64; LANES] {
        &mut self.slots[slot]
    }

    /// The lanes of a slot (features are read here after [`Self::run`]).
    pub fn slot(&self, slot: usize) -> &[f64; LANES] {
        &self.slots[slot]
    }

    /// Loads the random parameters of `params.len()` (≤ [`LANES`]) samples
    /// into the first lanes and runs the program on them.
    pub fn run_samples(&mut self, params: &[[f64; 7]]) -> Result<(), RuntimeError> {
        let n = params.len();
        debug_assert!(n <= LANES);
        for (d, slot) in self.program.parameters.iter().enumerate() {
            if let Some(slot) = slot {
                let lanes = &mut self.slots[*slot];
                for (lane, p) in params.iter().enumerate() {
                    lanes[lane] = p[d];
                }
            }
        }
        self.run(if n == LANES { ALL } else { (1u64 << n) - 1 })
    }

    /// Runs the program on the lanes in `mask`.
    pub fn run(&mut self, mask: Mask) -> Result<(), RuntimeError> {
        for (_, _, s) in &self.program.features {
            self.slots[*s] = [0.0; LANES];
        }
        let program = self.program;
        self.block(&program.stmts, mask, &mut LoopState::default())
    }

    fn block(&mut self, stmts: &[CStmt], mask: Mask, state: &mut LoopState) -> Result<(), RuntimeError> {
        for stmt in stmts {
            let live = mask & !(state.broken | state.continued);
            if live == 0 {
                return Ok(());
            }
            match stmt {
                CStmt::Eval(e) => {
                    self.eval(e, live);
                }
                CStmt::If { cond, then, otherwise } => {
                    let c = self.truth(cond, live);
                    if live & c != 0 {
                        self.block(then, live & c, state)?;
                    }
                    if live & !c != 0 && !otherwise.is_empty() {
                        self.block(otherwise, live & !c, state)?;
                    }
                }
                CStmt::While { cond, body, step, pos } => {
                    let mut active = live;
                    let mut iterations = 0u64;
                    loop {
                        active &= self.truth(cond, active);
                        if active == 0 {
                            break;
                        }
                        iterations += 1;
                        if iterations > MAX_LOOP_ITERATIONS {
                            return Err(RuntimeError {
                                pos: *pos,
                                message: format!("loop ran more than {MAX_LOOP_ITERATIONS} times (endless loop?)"),
                            });
                        }
                        let mut inner = LoopState::default();
                        self.block(body, active, &mut inner)?;
                        active &= !inner.broken;
                        if let Some(step) = step {
                            self.eval(step, active);
                        }
                    }
                }
                CStmt::Break => state.broken |= live,
                CStmt::Continue => state.continued |= live,
            }
        }
        Ok(())
    }

    fn truth(&mut self, e: &CExpr, mask: Mask) -> Mask {
        let s = self.eval(e, mask);
        self.truth_of(s)
    }

    fn truth_of(&self, s: usize) -> Mask {
        let v = &self.slots[s];
        let mut m = 0u64;
        for (i, x) in v.iter().enumerate() {
            m |= ((*x != 0.0) as u64) << i;
        }
        m
    }

    /// Evaluates `e` and returns the slot holding its lanes.
    fn eval(&mut self, e: &CExpr, mask: Mask) -> usize {
        let (dst, op) = match e {
            CExpr::Slot(s) => return *s,
            CExpr::Op { dst, op } => (*dst, &**op),
        };
        match op {
            Op::Call1(f, a) => {
                let a = self.eval(a, mask);
                let (a, out) = self.pair(a, dst);
                apply1(*f, a, out);
            }
            Op::Call2(f, a, b) => {
                let a = self.eval(a, mask);
                let b = self.eval(b, mask);
                let (a, b, out) = self.triple(a, b, dst);
                apply2(*f, a, b, out);
            }
            Op::Call3(f, a, b, c) => {
                let (a, b, c) = (self.eval(a, mask), self.eval(b, mask), self.eval(c, mask));
                let (a, b, c) = (self.slots[a], self.slots[b], self.slots[c]);
                let out = &mut self.slots[dst];
                for i in 0..LANES {
                    out[i] = match f {
                        Fn3::Clamp => b[i].max(a[i]).min(c[i]),
                        Fn3::InRange => (a[i] <= b[i] && b[i] <= c[i]) as u8 as f64,
                    };
                }
            }
            Op::Select(c, a, b) => {
                let bits = self.truth(c, mask);
                // Each branch runs only for its own lanes (branches may assign);
                // a branch no lane takes is skipped.
                let zero = self.program.zero;
                let a = if mask & bits != 0 { self.eval(a, mask & bits) } else { zero };
                let b = if mask & !bits != 0 { self.eval(b, mask & !bits) } else { zero };
                let p = self.slots.as_mut_ptr();
                // SAFETY: dst is this operation's own temporary, distinct from a and b.
                let (a, b, out) = unsafe { (&*p.add(a), &*p.add(b), &mut *p.add(dst)) };
                // Select by the condition as it was before the branches ran
                // (a branch may assign to a variable the condition reads).
                for i in 0..LANES {
                    out[i] = if (bits >> i) & 1 == 1 { a[i] } else { b[i] };
                }
            }
            Op::Gather { base, len, index } => {
                let index = self.eval(index, mask);
                for i in 0..LANES {
                    let k = self.slots[index][i].floor();
                    self.slots[dst][i] =
                        if k >= 0.0 && (k as usize) < *len { self.slots[base + k as usize][i] } else { f64::NAN };
                }
            }
            Op::Store { target, value, keep } => {
                let v = self.eval(value, mask);
                if v != *target {
                    let (value, out) = self.pair(v, *target);
                    store(out, value, mask);
                }
                if !keep {
                    return *target;
                }
                self.slots[dst] = self.slots[*target];
            }
            Op::Scatter { base, len, index, value, keep } => {
                let index = self.eval(index, mask);
                let value = self.eval(value, mask);
                for i in (0..LANES).filter(|i| (mask >> i) & 1 == 1) {
                    let k = self.slots[index][i].floor();
                    if k >= 0.0 && (k as usize) < *len {
                        self.slots[base + k as usize][i] = self.slots[value][i];
                    }
                }
                if !keep {
                    return value;
                }
                // The value lives in a temporary a sibling may reuse: copy it.
                self.slots[dst] = self.slots[value];
            }
        }
        dst
    }

    /// `(&a, &mut out)` for two distinct slots.
    fn pair(&mut self, a: usize, out: usize) -> (&Lanes, &mut Lanes) {
        debug_assert_ne!(a, out);
        let p = self.slots.as_mut_ptr();
        // SAFETY: `a != out` (temporaries are allocated by depth, so an
        // operation's own slot differs from its operands'), both in bounds.
        unsafe { (&*p.add(a), &mut *p.add(out)) }
    }

    /// `(&a, &b, &mut out)` where `out` differs from `a` and `b` (which may be equal).
    fn triple(&mut self, a: usize, b: usize, out: usize) -> (&Lanes, &Lanes, &mut Lanes) {
        debug_assert!(a != out && b != out);
        assert!(a < self.slots.len() && b < self.slots.len() && out < self.slots.len());
        let p = self.slots.as_mut_ptr();
        // SAFETY: as in `pair`; two shared borrows of one slot are fine.
        unsafe { (&*p.add(a), &*p.add(b), &mut *p.add(out)) }
    }
}

fn store(out: &mut Lanes, value: &Lanes, mask: Mask) {
    if mask == ALL {
        *out = *value;
    } else {
        for i in 0..LANES {
            if (mask >> i) & 1 == 1 {
                out[i] = value[i];
            }
        }
    }
}

fn truthy(x: f64) -> bool {
    x != 0.0
}

fn bool_f(b: bool) -> f64 {
    b as u8 as f64
}

#[inline]
fn apply1(f: Fn1, a: &Lanes, out: &mut Lanes) {
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
fn apply2(f: Fn2, a: &Lanes, b: &Lanes, out: &mut Lanes) {
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
