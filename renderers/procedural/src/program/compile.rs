//! From the parsed program to slots: the compiler, and the passes over its
//! output.
//!
//! Everything that needs names, scopes or the shape of the source happens
//! here, once per scene, so that the machine never looks a string up. The
//! same place owns the passes that rewrite compiled statements (moving
//! temporaries after the named slots, cutting a program down to the
//! features a layout wants), since they depend on how slots were handed out.

use super::builtins::{function_names, Fn1, Fn2, Fn3, FUNCTIONS_1};
use super::{CExpr, CStmt, Op, Program};
use crate::syntax::{BinOp, Expr, Pos, SourceError, Stmt};
use fbksd_core::{Feature, RandomParameter};
use std::collections::HashMap;

#[derive(Debug, Clone, Copy)]
enum Symbol {
    Constant(usize),
    Parameter(RandomParameter, usize),
    Feature(usize),
    Scalar(usize),
    Array(usize, usize),
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
