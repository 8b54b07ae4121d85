//! What one client may hold of the server: the security headers every
//! answer carries, how many live-log streams a caller and the whole server
//! keep open, and how long a connection may stay silent.
//!
//! Streams and connections are the resources a request does not release
//! by ending: an event stream lasts as long as its job, and a connection as
//! long as its client keeps it. Each is counted or timed here so that one
//! client cannot starve the others.

use crate::routes::ApiError;
use crate::slots::{Full, Slot, Slots};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::Response;
use std::future::Future;
use std::net::SocketAddr;
use std::pin::Pin;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::time::{Instant, Sleep};

/// The pages load scripts and styles from `/static` only; the results
/// viewer draws on canvases from same-origin files and colours its legend
/// swatches with a `style` attribute (hence `style-src-attr`, never inline
/// `<style>` or script).
pub const CONTENT_SECURITY_POLICY: &str = "default-src 'self'; img-src 'self' data: blob:; style-src 'self'; \
     style-src-attr 'unsafe-inline'; object-src 'none'; base-uri 'self'; form-action 'self'; frame-ancestors 'none'";

/// Adds the security headers to an answer that does not set its own.
pub async fn security_headers(mut response: Response) -> Response {
    let headers = response.headers_mut();
    for (name, value) in [
        (header::CONTENT_SECURITY_POLICY, CONTENT_SECURITY_POLICY),
        (header::X_FRAME_OPTIONS, "DENY"),
        (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        (header::REFERRER_POLICY, "same-origin"),
    ] {
        headers.entry(name).or_insert(HeaderValue::from_static(value));
    }
    response
}

/// Live-log streams one caller (a user, or an anonymous client address) may keep open.
pub const MAX_STREAMS_PER_CALLER: usize = 8;
/// Live-log streams the server keeps open in all.
pub const MAX_STREAMS: usize = 256;

/// Counts open event streams, per caller and in all ([`crate::slots`]).
#[derive(Clone)]
pub struct StreamSlots(Slots);

/// One open stream: its place is given back when it is dropped, however
/// the stream ends (its job ended, or its client went away).
pub type StreamSlot = Slot;

impl Default for StreamSlots {
    fn default() -> StreamSlots {
        StreamSlots::new(MAX_STREAMS_PER_CALLER, MAX_STREAMS)
    }
}

impl StreamSlots {
    /// Slots for at most `max_per_caller` streams per caller and `max_total` in all.
    pub fn new(max_per_caller: usize, max_total: usize) -> StreamSlots {
        StreamSlots(Slots::new(max_per_caller, max_total))
    }

    /// A slot for `caller`, or 429 saying which limit is reached.
    pub fn take(&self, caller: &str) -> Result<StreamSlot, ApiError> {
        self.0.take(caller).map_err(|full| match full {
            Full::Caller(mine) => ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "too_many_streams",
                format!(
                    "you already follow {mine} live logs, the most one user may: close another job's page \
                     (or read this log at /api/v1/jobs/<id>/log) and try again"
                ),
            ),
            Full::All => ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "too_many_streams",
                "the server is streaming as many live logs as it can: try again in a minute \
                 (or read the log at /api/v1/jobs/<id>/log)",
            ),
        })
    }

    /// Streams open now, in all.
    pub fn open(&self) -> usize {
        self.0.taken()
    }
}

/// How long a client has, from connecting, to send its first request's
/// headers (a client that trickles them holds a connection for nothing).
pub const HEADER_READ_TIMEOUT: Duration = Duration::from_secs(30);

/// How long a connection may pass no byte either way before it is closed.
/// Longer than a runner's long poll and the event streams' keep-alive
/// comments (15 s), which are the longest silences of a working connection.
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(120);

/// A TCP listener whose connections time out: [`HEADER_READ_TIMEOUT`] for
/// the first request's headers, then an idle timeout. axum's `serve` does
/// not expose hyper's own header timeout, so the connection's reads and
/// writes are timed here.
pub struct TimedListener {
    listener: tokio::net::TcpListener,
    header_read: Duration,
    idle: Duration,
}

impl TimedListener {
    /// Wraps `listener` with timeouts `header_read` and `idle`.
    pub fn new(listener: tokio::net::TcpListener, header_read: Duration, idle: Duration) -> TimedListener {
        TimedListener { listener, header_read, idle }
    }
}

impl axum::serve::Listener for TimedListener {
    type Io = TimedStream;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (TimedStream, SocketAddr) {
        loop {
            match self.listener.accept().await {
                Ok((stream, addr)) => {
                    let _ = stream.set_nodelay(true);
                    return (TimedStream::new(stream, self.header_read, self.idle), addr);
                }
                // Out of file descriptors and the like: wait, as axum's own listener does.
                Err(e) => {
                    tracing::warn!("accepting a connection: {e}");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            }
        }
    }

    fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.listener.local_addr()
    }
}

/// A connection that fails with `TimedOut` when its deadline passes while
/// it waits: the end of the first request's headers, or the idle limit.
pub struct TimedStream {
    inner: tokio::net::TcpStream,
    idle: Duration,
    last_progress: Instant,
    /// Until the first request's headers are read.
    header_deadline: Option<Instant>,
    /// How much of `\r\n\r\n` the bytes read so far end with.
    header_end: usize,
    timer: Pin<Box<Sleep>>,
}

impl TimedStream {
    fn new(inner: tokio::net::TcpStream, header_read: Duration, idle: Duration) -> TimedStream {
        let now = Instant::now();
        TimedStream {
            inner,
            idle,
            last_progress: now,
            header_deadline: Some(now + header_read),
            header_end: 0,
            timer: Box::pin(tokio::time::sleep_until(now + idle.min(header_read))),
        }
    }

    fn saw(&mut self, bytes: &[u8]) {
        self.last_progress = Instant::now();
        if self.header_deadline.is_none() {
            return;
        }
        for &b in bytes {
            self.header_end = match (self.header_end, b) {
                (0 | 2, b'\r') => self.header_end + 1,
                (1 | 3, b'\n') => self.header_end + 1,
                (_, b'\r') => 1,
                _ => 0,
            };
            if self.header_end == 4 {
                self.header_deadline = None;
                return;
            }
        }
    }

    /// Pending until the deadline; then the error that closes the connection.
    fn wait(&mut self, cx: &mut Context<'_>) -> Poll<std::io::Error> {
        let idle_end = self.last_progress + self.idle;
        let deadline = self.header_deadline.map_or(idle_end, |h| h.min(idle_end));
        if self.timer.deadline() != deadline {
            self.timer.as_mut().reset(deadline);
        }
        match self.timer.as_mut().poll(cx) {
            Poll::Ready(()) => {
                let what = if self.header_deadline.is_some_and(|h| h <= Instant::now()) {
                    "the request's headers took too long"
                } else {
                    "the connection was idle too long"
                };
                Poll::Ready(std::io::Error::new(std::io::ErrorKind::TimedOut, what))
            }
            Poll::Pending => Poll::Pending,
        }
    }
}

impl AsyncRead for TimedStream {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        match Pin::new(&mut self.inner).poll_read(cx, buf) {
            Poll::Ready(Ok(())) => {
                let this = &mut *self;
                this.saw(&buf.filled()[before..]);
                Poll::Ready(Ok(()))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => self.wait(cx).map(Err),
        }
    }
}

impl AsyncWrite for TimedStream {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, data: &[u8]) -> Poll<std::io::Result<usize>> {
        match Pin::new(&mut self.inner).poll_write(cx, data) {
            Poll::Ready(Ok(n)) => {
                self.last_progress = Instant::now();
                Poll::Ready(Ok(n))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => self.wait(cx).map(Err),
        }
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        match Pin::new(&mut self.inner).poll_write_vectored(cx, bufs) {
            Poll::Ready(Ok(n)) => {
                self.last_progress = Instant::now();
                Poll::Ready(Ok(n))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => self.wait(cx).map(Err),
        }
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    #[test]
    fn stream_slots_refuse_over_either_limit_and_come_back_when_dropped() {
        let slots = StreamSlots::new(2, 3);
        let a1 = slots.take("a").unwrap();
        let _a2 = slots.take("a").unwrap();
        let refused = slots.take("a").expect_err("a third stream of one caller");
        assert_eq!(refused.status, StatusCode::TOO_MANY_REQUESTS);
        assert!(refused.message.contains("close another job's page"), "{}", refused.message);
        let _b1 = slots.take("b").unwrap();
        let full = slots.take("c").expect_err("over the server's limit");
        assert!(full.message.contains("as many live logs as it can"), "{}", full.message);
        drop(a1);
        assert_eq!(slots.open(), 2);
        let _c1 = slots.take("c").expect("a closed stream frees its slot");
        assert!(slots.take("a").is_err(), "the server is full again");
    }

    /// A server on port 0 with short timeouts, answering "ok".
    async fn timed_server(header_read: Duration, idle: Duration) -> SocketAddr {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let router = axum::Router::new().route("/", axum::routing::get(|| async { "ok" }));
        tokio::spawn(async move { axum::serve(TimedListener::new(listener, header_read, idle), router).await });
        addr
    }

    /// Reads until the server closes the connection; what it sent and how long it took.
    async fn until_closed(stream: &mut tokio::net::TcpStream) -> (String, Duration) {
        let start = Instant::now();
        let mut text = Vec::new();
        let read = tokio::time::timeout(Duration::from_secs(10), stream.read_to_end(&mut text)).await;
        assert!(read.is_ok(), "the server never closed the connection");
        (String::from_utf8_lossy(&text).into_owned(), start.elapsed())
    }

    #[tokio::test]
    async fn a_client_that_trickles_its_headers_or_goes_silent_is_cut_off() {
        let addr = timed_server(Duration::from_millis(600), Duration::from_millis(1500)).await;

        // Slow headers: one line, then nothing more; closed at the header deadline.
        let mut slow = tokio::net::TcpStream::connect(addr).await.unwrap();
        slow.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n").await.unwrap();
        let (text, took) = until_closed(&mut slow).await;
        assert!(!text.contains("ok"), "{text}");
        assert!(took < Duration::from_millis(1400), "closed after {took:?}, at the header deadline");

        // A complete request is answered; the silent connection then closes when idle.
        let mut idle = tokio::net::TcpStream::connect(addr).await.unwrap();
        idle.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n").await.unwrap();
        let (text, took) = until_closed(&mut idle).await;
        assert!(text.starts_with("HTTP/1.1 200") && text.ends_with("ok"), "{text}");
        assert!(took >= Duration::from_millis(1200), "kept alive until idle, closed after {took:?}");

        // A connection that keeps talking outlives the header deadline.
        let mut busy = tokio::net::TcpStream::connect(addr).await.unwrap();
        for _ in 0..3 {
            busy.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n").await.unwrap();
            let mut answer = [0u8; 512];
            let n = busy.read(&mut answer).await.unwrap();
            assert!(String::from_utf8_lossy(&answer[..n]).starts_with("HTTP/1.1 200"));
            tokio::time::sleep(Duration::from_millis(400)).await;
        }
    }
}
