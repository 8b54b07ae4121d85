//! The manager's side of its connections: one event channel that every
//! peer message, new connection and process exit arrives on ([`Event`],
//! [`Inbox`]), the thread that accepts connections and checks their hello,
//! and the reader threads that turn frames into events. Keeping the
//! threads here leaves the run's logic in one single-threaded loop.

use crate::process::{ExitInfo, Running};
use fbksd_core::protocol::{
    read_frame, write_frame, ErrorKind, FromRenderer, FromTechnique, Hello, ToRenderer, ToTechnique, PROTOCOL_NAME,
    PROTOCOL_VERSION,
};
use fbksd_core::SceneInfo;
use std::collections::VecDeque;
use std::io::BufReader;
use std::os::unix::net::{UnixListener, UnixStream};
use std::sync::mpsc::{Receiver, Sender};
use std::time::{Duration, Instant};

/// The runner's event channel, with events set aside while waiting for a
/// particular one (so none is ever dropped).
pub(super) struct Inbox {
    pub(super) rx: Receiver<Event>,
    pub(super) deferred: VecDeque<Event>,
}

impl Inbox {
    /// The next event, or `None` when `deadline` passes first.
    pub(super) fn next(&mut self, deadline: Option<Instant>) -> Option<Event> {
        if let Some(e) = self.deferred.pop_front() {
            return Some(e);
        }
        match deadline {
            Some(d) => self.rx.recv_timeout(d.saturating_duration_since(Instant::now())).ok(),
            None => self.rx.recv().ok(),
        }
    }

    /// The first event `pick` accepts within `within`; others are kept for later.
    pub(super) fn wait_for(&mut self, within: Duration, pick: impl Fn(&Event) -> bool) -> Option<Event> {
        if let Some(i) = self.deferred.iter().position(&pick) {
            return self.deferred.remove(i);
        }
        let deadline = Instant::now() + within;
        loop {
            match self.rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Ok(e) if pick(&e) => return Some(e),
                Ok(e) => self.deferred.push_back(e),
                Err(_) => return None,
            }
        }
    }
}

pub(crate) enum Event {
    Connected(UnixStream, Hello),
    Technique(u64, Result<Option<FromTechnique>, String>),
    Renderer(u64, Result<Option<FromRenderer>, String>),
    TechniqueExited(u64, ExitInfo),
    RendererExited(u64, ExitInfo),
}

pub(crate) struct RendererConn {
    pub(super) process: Box<dyn Running>,
    pub(super) writer: UnixStream,
    pub(super) generation: u64,
    pub(super) tile_size: u32,
    pub(super) scene_info: SceneInfo,
}

impl RendererConn {
    pub(crate) fn send(&mut self, message: &ToRenderer) {
        // A failed write surfaces as the reader's end of stream or the exit event.
        let _ = write_frame(&mut self.writer, message);
    }
}

pub(super) fn accept_loop(listener: UnixListener, tx: Sender<Event>) {
    for stream in listener.incoming() {
        let Ok(mut stream) = stream else { continue };
        let tx = tx.clone();
        // Read the hello off the acceptor thread so a silent peer blocks no one.
        std::thread::spawn(move || {
            let _ = stream.set_read_timeout(Some(Duration::from_secs(10)));
            let hello = read_frame::<_, Hello>(&mut stream);
            let _ = stream.set_read_timeout(None);
            match hello {
                Ok(Some(h)) if h.protocol == PROTOCOL_NAME && h.version == PROTOCOL_VERSION => {
                    let _ = tx.send(Event::Connected(stream, h));
                }
                Ok(Some(h)) => refuse_kind(
                    &mut stream,
                    ErrorKind::VersionMismatch,
                    &format!(
                        "this manager speaks {PROTOCOL_NAME} protocol version {PROTOCOL_VERSION}; the peer speaks {:?} version {}: rebuild it against this SDK",
                        h.protocol, h.version
                    ),
                ),
                Ok(None) => {}
                Err(e) => refuse_kind(&mut stream, ErrorKind::Protocol, &format!("expected a hello frame: {e}")),
            }
        });
    }
}

pub(crate) fn refuse(stream: &mut UnixStream, why: &str) {
    refuse_kind(stream, ErrorKind::Protocol, why);
}

pub(crate) fn refuse_kind(stream: &mut UnixStream, kind: ErrorKind, why: &str) {
    let _ = write_frame(stream, &ToTechnique::Error { kind, message: why.to_string() });
}

pub(crate) fn spawn_reader<T, F>(stream: UnixStream, tx: Sender<Event>, wrap: F)
where
    T: serde::de::DeserializeOwned + Send + 'static,
    F: Fn(Result<Option<T>, String>) -> Event + Send + 'static,
{
    std::thread::spawn(move || {
        let mut reader = BufReader::new(stream);
        loop {
            let message = read_frame::<_, T>(&mut reader).map_err(|e| e.to_string());
            let stop = !matches!(message, Ok(Some(_)));
            if tx.send(wrap(message)).is_err() || stop {
                return;
            }
        }
    });
}
