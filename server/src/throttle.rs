//! Rate limits on what an anonymous caller can make the server do at a
//! cost to someone: guessing passwords (log-ins, per e-mail address and
//! per client address) and sending account mail (per address and per
//! client). The limits are settings (`config::RateLimit`); a refusal is a
//! [`Limited`], answered 429 with `Retry-After` and a message saying what
//! was limited and when to retry.
//!
//! Counters live in this process's memory: a restart forgets them, and
//! several instances each allow the limit (enough against floods, which is
//! what they are for). Each limiter is a GCRA (a token bucket kept as one
//! instant per key: when the bucket is full again) over hashed keys in a
//! bounded map, so a flood of distinct addresses costs a few megabytes at
//! most and evicts only the stalest counters.

use crate::config::{Config, RateLimit};
use crate::AppState;
use axum::extract::{ConnectInfo, FromRequestParts};
use axum::http::request::Parts;
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use std::collections::HashMap;
use std::hash::BuildHasher;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Keys one limiter remembers at most; beyond, the stalest are dropped.
const MAX_KEYS: usize = 100_000;

/// The server's rate limits.
#[derive(Clone)]
pub struct Throttle(Arc<Limiters>);

struct Limiters {
    login_address: Limiter,
    login_ip: Limiter,
    mail_address: Limiter,
    mail_ip: Limiter,
}

impl Throttle {
    /// The limits `config` sets.
    pub fn new(config: &Config) -> Throttle {
        Throttle(Arc::new(Limiters {
            login_address: Limiter::new(config.login_limit_per_address),
            login_ip: Limiter::new(config.login_limit_per_ip),
            mail_address: Limiter::new(config.mail_limit_per_address),
            mail_ip: Limiter::new(config.mail_limit_per_ip),
        }))
    }

    /// Counts a log-in attempt from `ip` for `email`, or refuses it. The
    /// caller gives the address's attempt back when the password was right,
    /// so only failures lock an address.
    pub fn log_in(&self, ip: IpAddr, email: &str) -> Result<LoginAttempt, Limited> {
        self.0.login_ip.take(&ip_key(ip), "log-in attempts from your network address")?;
        let key = address_key(email);
        self.0.login_address.take(&key, "failed log-ins for this e-mail address")?;
        Ok(LoginAttempt { throttle: self.clone(), key })
    }

    /// Counts an account mail (registration, verification link, password
    /// reset) from `ip` to `email`, or refuses it. Counted whether or not a
    /// mail goes out, so the answer tells nothing about accounts.
    pub fn mail(&self, ip: IpAddr, email: &str) -> Result<(), Limited> {
        self.0.mail_ip.take(&ip_key(ip), "account mails requested from your network address")?;
        self.0.mail_address.take(&address_key(email), "mails to this e-mail address")?;
        Ok(())
    }
}

/// A counted log-in attempt.
pub struct LoginAttempt {
    throttle: Throttle,
    key: String,
}

impl LoginAttempt {
    /// The password was right: the attempt does not count against the address.
    pub fn succeeded(self) {
        self.throttle.0.login_address.give_back(&self.key);
    }
}

/// An address as limits key it: normalised like accounts do, so case and
/// spaces do not make a new counter.
fn address_key(email: &str) -> String {
    crate::accounts::Email::parse(email).map_or_else(|_| email.trim().to_lowercase(), |e| e.as_str().to_string())
}

/// A client as limits key it: IPv4, or an IPv6 /64 (one subscriber's
/// network, which hands its machine any address in it).
fn ip_key(ip: IpAddr) -> String {
    match ip {
        IpAddr::V4(v4) => v4.to_string(),
        IpAddr::V6(v6) => match v6.to_ipv4_mapped() {
            Some(v4) => v4.to_string(),
            None => {
                let s = v6.segments();
                format!("{:x}:{:x}:{:x}:{:x}::/64", s[0], s[1], s[2], s[3])
            }
        },
    }
}

/// A request refused by a rate limit.
#[derive(Debug)]
pub struct Limited {
    what: &'static str,
    retry_after: Duration,
}

impl Limited {
    /// Whole seconds to wait (rounded up, at least 1), for `Retry-After`.
    pub fn retry_after_seconds(&self) -> u64 {
        (self.retry_after.as_secs() + u64::from(self.retry_after.subsec_nanos() > 0)).max(1)
    }
    /// What was limited and when to retry.
    pub fn message(&self) -> String {
        let wait = humantime::format_duration(Duration::from_secs(self.retry_after_seconds()));
        format!("too many {}: try again in {wait}", self.what)
    }
    /// The `Retry-After` header, for answers built elsewhere (pages).
    pub fn header(&self) -> (header::HeaderName, String) {
        (header::RETRY_AFTER, self.retry_after_seconds().to_string())
    }
}

impl IntoResponse for Limited {
    fn into_response(self) -> Response {
        let body = serde_json::json!({
            "error": "rate_limited",
            "message": self.message(),
            "retry_after_seconds": self.retry_after_seconds(),
        });
        (StatusCode::TOO_MANY_REQUESTS, [self.header()], axum::Json(body)).into_response()
    }
}

/// One limit over many keys.
struct Limiter {
    limit: RateLimit,
    /// Per key hash: when its bucket is full again (GCRA's theoretical
    /// arrival time). Absent means full.
    full_at: Mutex<HashMap<u64, Instant>>,
    hasher: std::collections::hash_map::RandomState,
}

impl Limiter {
    fn new(limit: RateLimit) -> Limiter {
        Limiter { limit, full_at: Mutex::new(HashMap::new()), hasher: Default::default() }
    }

    /// The time one event refills.
    fn interval(&self) -> Duration {
        self.limit.window / self.limit.count.max(1)
    }

    /// Takes one event for `key`, or says how long until one is free.
    fn take(&self, key: &str, what: &'static str) -> Result<(), Limited> {
        if self.limit.count == 0 {
            return Ok(());
        }
        // Keys are hashed with a per-process random key: fixed-size entries,
        // and collisions nobody can aim for.
        let key = self.hasher.hash_one(key);
        let (now, interval) = (Instant::now(), self.interval());
        let tolerance = self.limit.window.saturating_sub(interval);
        let mut map = self.full_at.lock().unwrap_or_else(|e| e.into_inner());
        let full_at = map.get(&key).copied().unwrap_or(now).max(now);
        let ahead = full_at - now;
        if ahead > tolerance {
            return Err(Limited { what, retry_after: ahead - tolerance });
        }
        if map.len() >= MAX_KEYS && !map.contains_key(&key) {
            evict(&mut map, now);
        }
        map.insert(key, full_at + interval);
        Ok(())
    }

    /// Gives back one event of `key`.
    fn give_back(&self, key: &str) {
        if self.limit.count == 0 {
            return;
        }
        let key = self.hasher.hash_one(key);
        let now = Instant::now();
        let mut map = self.full_at.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(full_at) = map.get_mut(&key) {
            match full_at.checked_sub(self.interval()) {
                Some(earlier) if earlier > now => *full_at = earlier,
                _ => {
                    map.remove(&key);
                }
            }
        }
    }
}

/// Makes room in a full map: forgets full buckets, then if need be the
/// quarter of keys closest to full (the stalest counters), so eviction
/// runs once per many insertions.
fn evict(map: &mut HashMap<u64, Instant>, now: Instant) {
    map.retain(|_, full_at| *full_at > now);
    if map.len() >= MAX_KEYS * 3 / 4 {
        let mut times: Vec<Instant> = map.values().copied().collect();
        let cut = times.len() / 4;
        let (_, cutoff, _) = times.select_nth_unstable(cut);
        let cutoff = *cutoff;
        map.retain(|_, full_at| *full_at > cutoff);
    }
}

/// The client's network address: the connection's peer, or, when the peer
/// is one of the `trusted_proxies`, the address the outermost trusted proxy
/// saw, from the configured `client_ip_header`.
pub struct ClientIp(pub IpAddr);

impl FromRequestParts<AppState> for ClientIp {
    type Rejection = std::convert::Infallible;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Self::Rejection> {
        let peer = parts.extensions.get::<ConnectInfo<SocketAddr>>().map(|c| c.0.ip());
        let name = &state.config.client_ip_header;
        if !name.is_empty() && peer.is_some_and(|p| state.config.trusted_proxies.contain(p)) {
            let chain: Vec<IpAddr> = parts
                .headers
                .get_all(name.as_str())
                .iter()
                .filter_map(|v| v.to_str().ok())
                .flat_map(|v| v.split(','))
                .filter_map(|v| v.trim().parse::<IpAddr>().ok())
                .collect();
            // Each proxy appends the address it saw: from the right, the
            // first that is not a trusted proxy is the client (entries to
            // its left are the client's own say).
            let trusted = &state.config.trusted_proxies;
            let client = chain.iter().rev().find(|ip| !trusted.contain(**ip)).or(chain.first());
            if let Some(ip) = client {
                return Ok(ClientIp(*ip));
            }
        }
        // Without connection info (a router served another way) every
        // client shares one counter: limited, never unlimited.
        Ok(ClientIp(peer.unwrap_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_burst_of_count_then_one_per_interval() {
        let limiter = Limiter::new(RateLimit::new(3, Duration::from_secs(300)));
        for _ in 0..3 {
            limiter.take("a", "tries").unwrap();
        }
        let refused = limiter.take("a", "tries").unwrap_err();
        assert!((99..=100).contains(&refused.retry_after_seconds()), "{}", refused.retry_after_seconds());
        assert!(refused.message().starts_with("too many tries: try again in 1m 40s"), "{}", refused.message());
        limiter.take("b", "tries").expect("another key has its own bucket");
        limiter.give_back("a");
        limiter.take("a", "tries").expect("a given-back event can be taken again");
        assert!(limiter.take("a", "tries").is_err());
    }

    #[test]
    fn the_map_stays_bounded_under_a_flood_of_keys() {
        let limiter = Limiter::new(RateLimit::new(5, Duration::from_secs(3600)));
        limiter.take("victim", "tries").unwrap();
        for i in 0..MAX_KEYS * 2 {
            limiter.take(&i.to_string(), "tries").unwrap();
        }
        assert!(limiter.full_at.lock().unwrap().len() <= MAX_KEYS);
    }

    #[test]
    fn ipv6_clients_are_keyed_by_their_64() {
        let a: IpAddr = "2001:db8:1:2:aaaa::1".parse().unwrap();
        let b: IpAddr = "2001:db8:1:2:bbbb::2".parse().unwrap();
        assert_eq!(ip_key(a), ip_key(b));
        assert_eq!(ip_key("::ffff:10.0.0.1".parse().unwrap()), "10.0.0.1");
    }
}
