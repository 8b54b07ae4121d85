//! The control protocol between technique, manager and renderer.
//!
//! # Wire format
//!
//! Each process holds one Unix stream connection to the manager's socket
//! `<rendezvous>/control.sock`. A connection carries **frames**: a 4-byte
//! little-endian length `n` (1 ≤ n ≤ [`MAX_FRAME`]) followed by `n` bytes of
//! UTF-8 JSON, one object per frame, whose `"type"` field names the message.
//! The first frame on every connection is a [`Hello`]; the manager answers
//! with `welcome` or `error`. Every message, its fields and the order in
//! which they may come are in `sdk/PROTOCOL.md`; the golden test in
//! `tests/tests/wire_format.rs` decodes these frames without this module, so
//! drift between the two breaks the build.
//!
//! Sample data never travels in frames: it is in the shared ring
//! ([`crate::shm`]). A frame only hands a slot from one process to another.

use crate::layout::SampleLayout;
use crate::scene_info::SceneInfo;
use crate::shm::RingSpec;
use crate::tile::Tile;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::io::{self, Read, Write};

/// The protocol's name, sent in every hello.
pub const PROTOCOL_NAME: &str = "fbksd";
/// The protocol version this crate speaks. Peers must match exactly.
pub const PROTOCOL_VERSION: u32 = 1;
/// The largest frame accepted, in bytes (control messages are small; scene
/// info is the largest and stays far below this).
pub const MAX_FRAME: u32 = 1 << 20;

/// Who is connecting.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// A technique (the client).
    Technique,
    /// A renderer.
    Renderer,
}

/// The first frame on every connection.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "type", rename = "hello")]
pub struct Hello {
    /// Always [`PROTOCOL_NAME`].
    pub protocol: String,
    /// The sender's [`PROTOCOL_VERSION`].
    pub version: u32,
    /// The sender's role.
    pub role: Role,
    /// The sender's process id (for logs; never trusted).
    pub pid: u32,
    /// The session token the manager gave the technique in
    /// `FBKSD_SESSION`, proving it is the process started for this run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub session: Option<String>,
}

impl Hello {
    /// This process's hello for `role`, with the session token of the
    /// environment (`FBKSD_SESSION`) if there is one.
    pub fn new(role: Role) -> Self {
        Hello {
            protocol: PROTOCOL_NAME.into(),
            version: PROTOCOL_VERSION,
            role,
            pid: std::process::id(),
            session: std::env::var(crate::rendezvous::SESSION_ENV_VAR).ok(),
        }
    }
}

/// An amount of samples asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Amount {
    /// `n` samples for every pixel.
    Spp(u64),
    /// `n` samples anywhere in the image.
    Samples(u64),
}

/// Why the manager refused a request or ended a session.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorKind {
    /// The peer speaks another protocol or version.
    VersionMismatch,
    /// A message that is not allowed in the current state.
    Protocol,
    /// The sample layout is invalid.
    InvalidLayout,
    /// The request exceeds the remaining sample budget.
    OverBudget,
    /// The request is malformed (zero samples, INPUT without input layout, …).
    BadRequest,
    /// The renderer failed; the session cannot go on.
    RendererFailed,
    /// The result does not match the image.
    InvalidOutput,
    /// The run's time limit expired.
    Timeout,
}

/// Manager → technique.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ToTechnique {
    /// Session accepted: the scene, the budget and the result buffer.
    Welcome {
        /// Protocol version of the manager.
        version: u32,
        /// Scene info including `max_spp` and `max_samples` (the budget).
        scene_info: SceneInfo,
        /// File name of the result buffer (`width × height × 3` f32) in the rendezvous directory.
        result_file: String,
    },
    /// The layout is accepted; the ring is ready.
    LayoutSet {
        /// The ring to map.
        ring: RingSpec,
        /// Floats per sample.
        sample_size: u32,
    },
    /// Write the INPUT parameters of `tile` into `slot`, then answer `produced`.
    Produce {
        /// The slot, now owned by the technique.
        slot: u32,
        /// What the slot will hold.
        tile: Tile,
    },
    /// `slot` holds `tile`'s samples; read them, then answer `consumed`.
    Consume {
        /// The slot, now owned by the technique.
        slot: u32,
        /// What the slot holds.
        tile: Tile,
    },
    /// The current request is complete.
    EvaluateDone {
        /// Samples delivered for this request.
        delivered: u64,
        /// Samples left in the budget.
        remaining: u64,
    },
    /// The result was stored; the technique should exit.
    ResultAccepted,
    /// A refusal. Always final: the manager ends the session after sending it.
    Error {
        /// What kind of problem.
        kind: ErrorKind,
        /// A message for a person.
        message: String,
    },
}

/// Technique → manager.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum FromTechnique {
    /// Sets the sample layout (once per session).
    SetLayout {
        /// The layout as written by the technique.
        layout: SampleLayout,
    },
    /// Requests samples.
    Evaluate {
        /// How many.
        amount: Amount,
        /// Whether the technique writes INPUT parameters (answers `produce`).
        input: bool,
    },
    /// The technique wrote the INPUT parameters of `slot`.
    Produced {
        /// The slot handed back.
        slot: u32,
    },
    /// The technique has read `slot`.
    Consumed {
        /// The slot handed back.
        slot: u32,
    },
    /// The result buffer holds the final image.
    SendResult {
        /// Width of the image written.
        width: u32,
        /// Height of the image written.
        height: u32,
        /// Channels per pixel (3).
        channels: u32,
    },
}

/// Manager → renderer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ToRenderer {
    /// Connection accepted.
    Welcome {
        /// Protocol version of the manager.
        version: u32,
    },
    /// A technique session starts with this (validated) layout and ring.
    SetLayout {
        /// The validated layout.
        layout: SampleLayout,
        /// The ring to map.
        ring: RingSpec,
    },
    /// Produce `spp` samples for every pixel, then `remaining` more anywhere.
    Evaluate {
        /// Samples per pixel (may be 0).
        spp: u64,
        /// Extra samples not tied to pixels (may be 0).
        remaining: u64,
        /// The most samples one pipe (tile) may hold.
        pipe_size: u64,
        /// Whether the technique writes INPUT parameters into each tile first.
        input: bool,
        /// Index of this request in the session, for seeding.
        request: u64,
        /// The run's sample seed: repeats of a run differ only in it. 0 (the
        /// default, left out on the wire) is every run's first repeat.
        #[serde(default, skip_serializing_if = "is_zero")]
        seed: u64,
    },
    /// Answer to `acquire`: the pipe `id` may write `slot`.
    Granted {
        /// The pipe.
        id: u64,
        /// The slot, now owned by the renderer.
        slot: u32,
    },
    /// The technique session is over; unmap the ring.
    EndSession,
    /// No more sessions: finish and exit.
    Finish,
}

/// Renderer → manager.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum FromRenderer {
    /// Sent once after `welcome`.
    Ready {
        /// Preferred tile side in pixels.
        tile_size: u32,
        /// The scene's info (without the budget keys, which the manager sets).
        scene_info: SceneInfo,
    },
    /// The layout is accepted and the ring mapped.
    LayoutAccepted,
    /// A pipe wants a slot for `tile`.
    Acquire {
        /// The pipe, unique within the session.
        id: u64,
        /// What it will write.
        tile: Tile,
    },
    /// `slot` holds `count` samples.
    Filled {
        /// The slot handed back.
        slot: u32,
        /// Samples written (must equal the tile's count).
        count: u64,
    },
    /// Every pipe of the current request has been filled.
    EvaluateDone,
    /// The renderer cannot go on.
    Failed {
        /// What went wrong.
        message: String,
    },
}

/// A frame could not be read.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// The connection failed.
    #[error("connection error: {0}")]
    Io(#[from] io::Error),
    /// The peer closed the connection inside a frame.
    #[error("connection closed in the middle of a frame")]
    Truncated,
    /// The length prefix is 0 or above [`MAX_FRAME`].
    #[error("frame length {0} is outside 1..={MAX_FRAME}")]
    BadLength(u32),
    /// The frame is not a known message.
    #[error("undecodable message ({error}): {text}")]
    Decode {
        /// The decoder's complaint.
        error: String,
        /// The start of the frame, for the log.
        text: String,
    },
}

fn is_zero(v: &u64) -> bool {
    *v == 0
}

/// Writes one message as a frame (a single `write_all`).
pub fn write_frame<W: Write, T: Serialize>(writer: &mut W, message: &T) -> io::Result<()> {
    let mut buf = vec![0u8; 4];
    serde_json::to_writer(&mut buf, message).map_err(io::Error::other)?;
    let len = (buf.len() - 4) as u32;
    buf[..4].copy_from_slice(&len.to_le_bytes());
    writer.write_all(&buf)?;
    writer.flush()
}

/// Reads one frame's bytes; `Ok(None)` on a clean end of stream.
pub fn read_frame_bytes<R: Read>(reader: &mut R) -> Result<Option<Vec<u8>>, FrameError> {
    let mut len = [0u8; 4];
    let mut got = 0;
    while got < 4 {
        match reader.read(&mut len[got..]) {
            Ok(0) if got == 0 => return Ok(None),
            Ok(0) => return Err(FrameError::Truncated),
            Ok(n) => got += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e.into()),
        }
    }
    let len = u32::from_le_bytes(len);
    if len == 0 || len > MAX_FRAME {
        return Err(FrameError::BadLength(len));
    }
    let mut body = vec![0u8; len as usize];
    reader.read_exact(&mut body).map_err(|e| match e.kind() {
        io::ErrorKind::UnexpectedEof => FrameError::Truncated,
        _ => FrameError::Io(e),
    })?;
    Ok(Some(body))
}

/// Reads and decodes one message; `Ok(None)` on a clean end of stream.
pub fn read_frame<R: Read, T: DeserializeOwned>(reader: &mut R) -> Result<Option<T>, FrameError> {
    let Some(body) = read_frame_bytes(reader)? else {
        return Ok(None);
    };
    decode(&body).map(Some)
}

/// Decodes a frame body.
pub fn decode<T: DeserializeOwned>(body: &[u8]) -> Result<T, FrameError> {
    serde_json::from_slice(body).map_err(|e| FrameError::Decode {
        error: e.to_string(),
        text: String::from_utf8_lossy(&body[..body.len().min(200)]).into_owned(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_through_a_pipe() {
        let mut buf = Vec::new();
        write_frame(&mut buf, &FromTechnique::Consumed { slot: 3 }).unwrap();
        write_frame(&mut buf, &Hello::new(Role::Renderer)).unwrap();
        let mut r = &buf[..];
        assert_eq!(read_frame::<_, FromTechnique>(&mut r).unwrap(), Some(FromTechnique::Consumed { slot: 3 }));
        let hello: Hello = read_frame(&mut r).unwrap().unwrap();
        assert_eq!(hello.role, Role::Renderer);
        assert!(read_frame::<_, Hello>(&mut r).unwrap().is_none());
    }

    #[test]
    fn truncated_and_oversized_frames_are_errors() {
        let mut buf = Vec::new();
        write_frame(&mut buf, &FromTechnique::Consumed { slot: 3 }).unwrap();
        let cut = &buf[..buf.len() - 1];
        assert!(matches!(read_frame::<_, FromTechnique>(&mut &cut[..]), Err(FrameError::Truncated)));
        let huge = (MAX_FRAME + 1).to_le_bytes();
        assert!(matches!(read_frame::<_, FromTechnique>(&mut &huge[..]), Err(FrameError::BadLength(_))));
    }

    #[test]
    fn unknown_message_is_a_decode_error_with_text() {
        let mut buf = Vec::new();
        write_frame(&mut buf, &serde_json::json!({"type": "launch_missiles"})).unwrap();
        let e = read_frame::<_, FromTechnique>(&mut &buf[..]).unwrap_err().to_string();
        assert!(e.contains("launch_missiles"), "{e}");
    }
}
