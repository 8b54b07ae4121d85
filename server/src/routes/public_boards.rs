//! Public leaderboards as anonymous readers get them, rendered once per
//! board version.
//!
//! The leaderboard page and its JSON are the same for every anonymous
//! reader of one query (season, sort metric, tag), and change only when
//! the board version does (a publish, a hide, a new season: every server
//! instance sees it in the database). So each is rendered once per version
//! and kept, with an ETag naming the version and the query; a reader who
//! already has it gets 304. Each request is still answered from a version
//! read that began after it arrived (one read shared by the requests
//! waiting together, [`crate::results::SharedBoardVersion`]), so another
//! instance's publish shows at once.
//!
//! Each (query, version) is rendered once: readers who miss it together
//! (a publish makes every open board miss at once) wait for the first
//! one's rendering ([`crate::versioned`]).
//!
//! A browser asks for gzip: each kept rendering keeps a gzip copy too, made
//! by its first reader who asks for gzip, instead of once per request (the
//! page is 180 KB with 20 techniques).

use crate::leaderboard::{BoardCache, BoardQuery};
use crate::routes::ApiError;
use crate::versioned::{Pick, Versioned};
use axum::body::Bytes;
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use sqlx::AnyPool;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// What a kept board is rendered as.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Rendering {
    /// The leaderboard page.
    Html,
    /// `GET /api/v1/leaderboard`.
    Json,
}

impl Rendering {
    fn content_type(self) -> &'static str {
        match self {
            Rendering::Html => "text/html; charset=utf-8",
            Rendering::Json => "application/json",
        }
    }
}

/// A kept board's rendering and query.
type Key = (Rendering, Option<i64>, Option<String>, Option<String>);

struct Kept {
    etag: HeaderValue,
    body: Bytes,
    /// The same body gzip-encoded, under its own ETag (another representation).
    gzip_etag: HeaderValue,
    /// Made when first asked for; None if it could not be (the plain body is served).
    gzip: OnceLock<Option<Bytes>>,
}

/// Renderings kept at most: a query naming no existing metric or tag still
/// renders, but past this nothing more is kept.
pub const MAX_KEPT: usize = 256;

/// The public boards rendered for anonymous readers.
#[derive(Clone, Default)]
pub struct PublicBoards(Arc<Mutex<HashMap<Key, Arc<Versioned<Kept>>>>>);

impl PublicBoards {
    /// The answer to an anonymous reader of `query` as `rendering`: the kept
    /// rendering of the current board version (304 when `request` names its
    /// ETag), or `render`'s, kept for the next reader.
    pub async fn respond(
        &self,
        boards: &BoardCache,
        pool: &AnyPool,
        rendering: Rendering,
        query: &BoardQuery,
        request: &HeaderMap,
        render: impl std::future::Future<Output = Result<String, ApiError>>,
    ) -> Result<Response, ApiError> {
        let key = (rendering, query.season, query.sort.clone(), query.tag.clone());
        let version = boards.version(pool).await?;
        let kept = self.kept(key, version, render).await?;
        let gzip = if accepts_gzip(request) { kept.gzip() } else { None };
        let (etag, body) = match gzip {
            Some(gzip) => (&kept.gzip_etag, gzip),
            None => (&kept.etag, &kept.body),
        };
        let fresh = request.get(header::IF_NONE_MATCH) == Some(etag);
        let mut response = if fresh {
            StatusCode::NOT_MODIFIED.into_response()
        } else {
            ([(header::CONTENT_TYPE, rendering.content_type())], body.clone()).into_response()
        };
        let headers = response.headers_mut();
        if gzip.is_some() && !fresh {
            // Already encoded: the compression layer leaves it as it is.
            headers.insert(header::CONTENT_ENCODING, HeaderValue::from_static("gzip"));
        }
        headers.insert(header::VARY, HeaderValue::from_static("accept-encoding"));
        headers.insert(header::ETAG, etag.clone());
        // Asked again each time (a publish changes it at once), answered by 304 while unchanged.
        headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
        Ok(response)
    }

    /// The rendering of `key` at `version`: the one kept, the one another
    /// reader is making (awaited), or `render`'s.
    async fn kept(
        &self,
        key: Key,
        version: i64,
        render: impl std::future::Future<Output = Result<String, ApiError>>,
    ) -> Result<Arc<Kept>, ApiError> {
        let slot = self.slot(&key, version);
        slot.get_or_try_make(|| async { Kept::new(&key, version, render.await?) }).await
    }

    /// The slot of `key` at `version` ([`Versioned::pick`]), kept for the
    /// readers after this one unless too many queries are.
    fn slot(&self, key: &Key, version: i64) -> Arc<Versioned<Kept>> {
        let Ok(mut all) = self.0.lock() else { return Versioned::new(version) };
        match Versioned::pick(all.get(key), version) {
            Pick::Share(slot) | Pick::Alone(slot) => slot,
            Pick::Keep(slot) => {
                // Renderings of an older version go first.
                all.retain(|_, kept| kept.version() >= version);
                if all.len() < MAX_KEPT || all.contains_key(key) {
                    all.insert(key.clone(), slot.clone());
                }
                slot
            }
        }
    }
}

impl Kept {
    fn new(key: &Key, version: i64, body: String) -> Result<Kept, ApiError> {
        use sha2::Digest;
        let query = format!("{:x}", sha2::Sha256::digest(format!("{key:?}")));
        let tag = |suffix: &str| {
            HeaderValue::from_str(&format!("\"{version}-{}{suffix}\"", &query[..16])).map_err(ApiError::internal)
        };
        Ok(Kept { etag: tag("")?, gzip_etag: tag("-gzip")?, gzip: OnceLock::new(), body: body.into() })
    }

    fn gzip(&self) -> Option<&Bytes> {
        self.gzip.get_or_init(|| gzip(&self.body).ok().map(Bytes::from)).as_ref()
    }
}

/// Whether the request's `Accept-Encoding` takes gzip (named, with a
/// quality above 0).
fn accepts_gzip(request: &HeaderMap) -> bool {
    request.get_all(header::ACCEPT_ENCODING).iter().filter_map(|v| v.to_str().ok()).flat_map(|v| v.split(',')).any(
        |item| {
            let mut parts = item.split(';').map(str::trim);
            let named = parts.next().is_some_and(|name| name.eq_ignore_ascii_case("gzip"));
            let refused = parts
                .filter_map(|p| p.strip_prefix("q=").or_else(|| p.strip_prefix("Q=")))
                .any(|q| q.parse::<f32>().map_or(true, |q| q <= 0.0));
            named && !refused
        },
    )
}

/// `body` gzip-encoded at the best ratio: done once per kept rendering.
fn gzip(body: &[u8]) -> std::io::Result<Vec<u8>> {
    use std::io::Write;
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    encoder.write_all(body)?;
    encoder.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gzip_is_taken_when_named_with_a_quality_above_zero() {
        let takes = |value: &str| {
            let mut headers = HeaderMap::new();
            headers.insert(header::ACCEPT_ENCODING, HeaderValue::from_str(value).unwrap());
            accepts_gzip(&headers)
        };
        assert!(takes("gzip, deflate, br") && takes("br;q=1.0, GZIP;q=0.5") && takes("gzip"));
        assert!(!takes("gzip;q=0") && !takes("gzip; q=0.000") && !takes("br, deflate") && !takes("x-gzip-not"));
        assert!(!accepts_gzip(&HeaderMap::new()), "no header: the body as it is");
    }

    /// A publish makes every reader of an open board miss at once.
    #[tokio::test]
    async fn readers_who_miss_together_share_one_rendering() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let boards = PublicBoards::default();
        let renders = Arc::new(AtomicUsize::new(0));
        let key: Key = (Rendering::Html, None, None, None);
        let readers: Vec<_> = (0..50)
            .map(|_| {
                let (boards, renders, key) = (boards.clone(), renders.clone(), key.clone());
                tokio::spawn(async move {
                    let render = async {
                        renders.fetch_add(1, Ordering::SeqCst);
                        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
                        Ok("the board at version 7".to_string())
                    };
                    boards.kept(key, 7, render).await.map(|kept| kept.body.clone())
                })
            })
            .collect();
        for reader in readers {
            assert_eq!(reader.await.unwrap().unwrap(), "the board at version 7");
        }
        assert_eq!(renders.load(Ordering::SeqCst), 1, "rendered once for 50 readers");

        // A failed rendering is not kept: the next reader renders again.
        let failed = boards.kept(key.clone(), 8, async { Err(ApiError::internal("the database went away")) }).await;
        assert!(failed.is_err());
        let next = boards.kept(key.clone(), 8, async { Ok("the board at version 8".to_string()) }).await;
        assert_eq!(next.unwrap().body, "the board at version 8");

        // A reader whose version read began before a publish does not put the older board back.
        let late = boards.kept(key.clone(), 7, async { Ok("the board at version 7, late".to_string()) }).await;
        assert_eq!(late.unwrap().body, "the board at version 7, late");
        let current = boards.kept(key, 8, async { Ok("rendered again".to_string()) }).await;
        assert_eq!(current.unwrap().body, "the board at version 8", "version 8 is still the one kept");
    }
}
