//! Running a compiled program on a batch of 64 samples.
//!
//! The machine is the hot loop: it owns the slot rows and the lane masks
//! and nothing else, so that it can run with no allocation and no look-up.
//! It is the only place that handles the per-sample control flow (masks
//! split by `if`, retired by `break`/`continue`) and the only `unsafe`
//! (disjoint borrows of slot rows, justified where they are taken).

use super::builtins::{apply1, apply2, Fn3};
use super::{CExpr, CStmt, Lanes, Mask, Op, Program, RuntimeError, ALL, LANES, MAX_LOOP_ITERATIONS};

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
