//! Values made once per board version and shared: the season data the
//! boards are assembled from, and the public boards rendered from it.
//!
//! A publish changes the board version, so every reader of an open board
//! misses at once. A [`Versioned`] slot is made by its first reader and
//! awaited by the others, instead of each making its own (on 2 cores that
//! stalled a cold board for seconds at 100 connections). The caches keep
//! one slot per key and decide with [`Versioned::pick`] whether a reader
//! shares it, replaces it, or (its version read began before a publish
//! another reader already saw) makes its own without putting the older
//! version back.

use std::sync::Arc;

/// One value at one board version.
pub struct Versioned<T> {
    version: i64,
    value: tokio::sync::OnceCell<Arc<T>>,
}

/// What a reader at some version does with the slot kept under its key.
pub enum Pick<T> {
    /// The kept slot is of its version: share it.
    Share(Arc<Versioned<T>>),
    /// None is kept, or an older one: keep this new slot in its place.
    Keep(Arc<Versioned<T>>),
    /// A newer one is kept: use this new slot alone, keeping the newer.
    Alone(Arc<Versioned<T>>),
}

impl<T> Versioned<T> {
    /// An empty slot for `version`.
    pub fn new(version: i64) -> Arc<Self> {
        Arc::new(Versioned { version, value: tokio::sync::OnceCell::new() })
    }

    /// The version it holds.
    pub fn version(&self) -> i64 {
        self.version
    }

    /// What a reader at `version` does with `kept`.
    pub fn pick(kept: Option<&Arc<Self>>, version: i64) -> Pick<T> {
        match kept {
            Some(slot) if slot.version == version => Pick::Share(slot.clone()),
            Some(slot) if slot.version > version => Pick::Alone(Versioned::new(version)),
            _ => Pick::Keep(Versioned::new(version)),
        }
    }

    /// The value, made by `make` if no one has made it yet; waits while
    /// another reader makes it. If making fails or its reader goes away,
    /// the next waiter makes it: a failure is never kept.
    pub async fn get_or_try_make<E, F, Fut>(&self, make: F) -> Result<Arc<T>, E>
    where
        F: FnOnce() -> Fut,
        Fut: std::future::Future<Output = Result<T, E>>,
    {
        let value = self.value.get_or_try_init(|| async { make().await.map(Arc::new) }).await?;
        Ok(value.clone())
    }
}
