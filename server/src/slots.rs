//! Places counted per caller and in all, for what a request holds past
//! its own handler: a live log (as long as its job) or a git process that
//! streams a clone (as long as its client reads). A caller is whatever key
//! the owner of the resource chooses (a user, a job, an anonymous address,
//! or all anonymous clients together), so that one caller cannot take
//! every place. A place comes back when its [`Slot`] is dropped, however
//! its holder ends.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Counts places taken, per caller and in all.
#[derive(Clone, Debug)]
pub struct Slots(Arc<Mutex<Counts>>);

#[derive(Debug)]
struct Counts {
    per_caller: HashMap<String, usize>,
    total: usize,
    max_per_caller: usize,
    max_total: usize,
}

/// Why no place was given.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Full {
    /// The caller holds this many places already, its most.
    Caller(usize),
    /// Every place is taken.
    All,
}

/// One place taken; given back when dropped.
#[derive(Debug)]
pub struct Slot {
    slots: Slots,
    caller: String,
}

impl Slots {
    /// At most `max_per_caller` places per caller and `max_total` in all.
    pub fn new(max_per_caller: usize, max_total: usize) -> Slots {
        Slots(Arc::new(Mutex::new(Counts { per_caller: HashMap::new(), total: 0, max_per_caller, max_total })))
    }

    /// A place for `caller`, or which limit is reached.
    pub fn take(&self, caller: &str) -> Result<Slot, Full> {
        let mut counts = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let mine = counts.per_caller.get(caller).copied().unwrap_or(0);
        if mine >= counts.max_per_caller {
            return Err(Full::Caller(mine));
        }
        if counts.total >= counts.max_total {
            return Err(Full::All);
        }
        counts.total += 1;
        *counts.per_caller.entry(caller.to_string()).or_insert(0) += 1;
        Ok(Slot { slots: self.clone(), caller: caller.to_string() })
    }

    /// Places taken now, in all.
    pub fn taken(&self) -> usize {
        self.0.lock().map_or(0, |c| c.total)
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut counts = self.slots.0.lock().unwrap_or_else(|e| e.into_inner());
        counts.total = counts.total.saturating_sub(1);
        if let Some(n) = counts.per_caller.get_mut(&self.caller) {
            *n -= 1;
            if *n == 0 {
                counts.per_caller.remove(&self.caller);
            }
        }
    }
}
