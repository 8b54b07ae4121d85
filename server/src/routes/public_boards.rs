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
//! A browser asks for gzip: each kept rendering keeps a gzip copy too, made
//! by its first reader who asks for gzip, instead of once per request (the
//! page is 180 KB with 20 techniques). Readers who render the same version
//! at once all share the first rendering kept, and so its one gzip copy.

use crate::leaderboard::{BoardCache, BoardQuery};
use crate::routes::ApiError;
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
    version: i64,
    etag: HeaderValue,
    body: Bytes,
    /// The same body gzip-encoded, under its own ETag (another representation).
    gzip_etag: HeaderValue,
    /// Made when first asked for; None if it could not be (the plain body is served).
    gzip: OnceLock<Option<Bytes>>,
}

impl Kept {
    fn gzip(&self) -> Option<&Bytes> {
        self.gzip.get_or_init(|| gzip(&self.body).ok().map(Bytes::from)).as_ref()
    }
}

/// Renderings kept at most: a query naming no existing metric or tag still
/// renders, but past this nothing more is kept.
pub const MAX_KEPT: usize = 256;

/// The public boards rendered for anonymous readers.
#[derive(Clone, Default)]
pub struct PublicBoards(Arc<Mutex<HashMap<Key, Arc<Kept>>>>);

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
        let kept = self.0.lock().ok().and_then(|k| k.get(&key).filter(|k| k.version == version).cloned());
        let kept = match kept {
            Some(kept) => kept,
            None => self.keep(key, version, render.await?)?,
        };
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

    fn keep(&self, key: Key, version: i64, body: String) -> Result<Arc<Kept>, ApiError> {
        use sha2::Digest;
        let query = format!("{:x}", sha2::Sha256::digest(format!("{key:?}")));
        let tag = |suffix: &str| {
            HeaderValue::from_str(&format!("\"{version}-{}{suffix}\"", &query[..16])).map_err(ApiError::internal)
        };
        let kept = Arc::new(Kept {
            version,
            etag: tag("")?,
            gzip_etag: tag("-gzip")?,
            gzip: OnceLock::new(),
            body: body.into(),
        });
        let Ok(mut all) = self.0.lock() else { return Ok(kept) };
        // Another reader kept this version first: share it (and its gzip copy).
        if let Some(first) = all.get(&key).filter(|k| k.version == version) {
            return Ok(first.clone());
        }
        // Renderings of an older version go first.
        all.retain(|_, k| k.version >= version);
        if all.len() < MAX_KEPT || all.contains_key(&key) {
            all.insert(key, kept.clone());
        }
        Ok(kept)
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
}
