//! Golden test of the wire format in `sdk/PROTOCOL.md`, decoded without the
//! protocol module: frames are split by hand (u32 little-endian length +
//! UTF-8 JSON) and compared as plain JSON values with the document's
//! examples. In the other direction, hand-written frames must decode to the
//! expected messages. Any drift between encoder and document fails here.

use fbksd_core::layout::{ElementIo, SampleLayout};
use fbksd_core::protocol::*;
use fbksd_core::shm::RingSpec;
use fbksd_core::{SceneInfo, Tile, TileRect};
use serde_json::{json, Value};

/// The independent decoder: one frame's JSON, checking the length prefix.
fn split_frame(bytes: &[u8]) -> Value {
    assert!(bytes.len() >= 4, "a frame has a 4-byte length");
    let len = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as usize;
    assert_eq!(len, bytes.len() - 4, "length prefix counts the JSON bytes exactly");
    let text = std::str::from_utf8(&bytes[4..]).expect("frames are UTF-8");
    serde_json::from_str(text).expect("frames are JSON")
}

fn encoded<T: serde::Serialize>(message: &T) -> Value {
    let mut bytes = Vec::new();
    write_frame(&mut bytes, message).unwrap();
    split_frame(&bytes)
}

/// Each message encodes to its JSON, and that JSON, framed by hand, decodes back.
fn round_trip<T>(cases: Vec<(T, Value)>)
where
    T: serde::Serialize + serde::de::DeserializeOwned + PartialEq + std::fmt::Debug,
{
    for (message, expected) in cases {
        assert_eq!(encoded(&message), expected);
        let back: T = read_frame(&mut &frame(&expected.to_string())[..]).unwrap().unwrap();
        assert_eq!(back, message);
    }
}

fn frame(text: &str) -> Vec<u8> {
    let mut bytes = (text.len() as u32).to_le_bytes().to_vec();
    bytes.extend_from_slice(text.as_bytes());
    bytes
}

#[test]
fn the_byte_layout_of_a_frame() {
    let mut bytes = Vec::new();
    write_frame(&mut bytes, &FromTechnique::Consumed { slot: 3 }).unwrap();
    let text = br#"{"type":"consumed","slot":3}"#;
    assert_eq!(&bytes[..4], &(text.len() as u32).to_le_bytes());
    assert_eq!(&bytes[4..], text);
}

#[test]
fn hello() {
    let hello = Hello { protocol: "fbksd".into(), version: 1, role: Role::Technique, pid: 42, session: None };
    assert_eq!(
        encoded(&hello),
        json!({"type": "hello", "protocol": "fbksd", "version": 1, "role": "technique", "pid": 42})
    );
    let with_token = Hello { session: Some("00ff".into()), ..hello };
    assert_eq!(
        encoded(&with_token),
        json!({"type": "hello", "protocol": "fbksd", "version": 1, "role": "technique", "pid": 42, "session": "00ff"})
    );
    let back: Hello =
        read_frame(&mut &frame(r#"{"type":"hello","protocol":"fbksd","version":1,"role":"renderer","pid":7}"#)[..])
            .unwrap()
            .unwrap();
    assert_eq!(back.role, Role::Renderer);
}

#[test]
fn technique_messages() {
    let layout = SampleLayout::new().with_io("IMAGE_X", ElementIo::Input).with_number("NORMAL_X", 1);
    let cases: Vec<(FromTechnique, Value)> = vec![
        (
            FromTechnique::SetLayout { layout },
            json!({"type": "set_layout", "layout": {"entries": [
                {"name": "IMAGE_X", "number": 0, "io": "input"},
                {"name": "NORMAL_X", "number": 1, "io": "output"}], "roughness_threshold": 0.1}}),
        ),
        (
            FromTechnique::Evaluate { amount: Amount::Spp(16), input: false },
            json!({"type": "evaluate", "amount": {"spp": 16}, "input": false}),
        ),
        (
            FromTechnique::Evaluate { amount: Amount::Samples(1000), input: true },
            json!({"type": "evaluate", "amount": {"samples": 1000}, "input": true}),
        ),
        (FromTechnique::Produced { slot: 1 }, json!({"type": "produced", "slot": 1})),
        (FromTechnique::Consumed { slot: 2 }, json!({"type": "consumed", "slot": 2})),
        (
            FromTechnique::SendResult { width: 640, height: 480, channels: 3 },
            json!({"type": "send_result", "width": 640, "height": 480, "channels": 3}),
        ),
    ];
    round_trip(cases);
    // A layout entry may omit number and io (defaults 0 and output).
    let short: FromTechnique = read_frame(
        &mut &frame(r#"{"type":"set_layout","layout":{"entries":[{"name":"COLOR_R"}],"roughness_threshold":0.1}}"#)[..],
    )
    .unwrap()
    .unwrap();
    assert_eq!(short, FromTechnique::SetLayout { layout: SampleLayout::new().with("COLOR_R") });
}

#[test]
fn manager_to_technique_messages() {
    let mut info = SceneInfo::new();
    info.set("width", 2).set("height", 1).set("max_spp", 4).set("has_dof", false).set("shutter_close", 1.0);
    let tile = Tile::Pixels { rect: TileRect { x0: 0, y0: 16, x1: 16, y1: 32 }, spp: 4 };
    let cases: Vec<(ToTechnique, Value)> = vec![
        (
            ToTechnique::Welcome { version: 1, scene_info: info, result_file: "result-1.f32".into() },
            json!({"type": "welcome", "version": 1, "result_file": "result-1.f32",
                   "scene_info": {"width": 2, "height": 1, "max_spp": 4, "has_dof": false, "shutter_close": 1.0}}),
        ),
        (
            ToTechnique::LayoutSet {
                ring: RingSpec { session: 1, slot_count: 6, slot_bytes: 8388608 },
                sample_size: 3,
            },
            json!({"type": "layout_set", "ring": {"session": 1, "slot_count": 6, "slot_bytes": 8388608}, "sample_size": 3}),
        ),
        (
            ToTechnique::Produce { slot: 0, tile },
            json!({"type": "produce", "slot": 0, "tile": {"kind": "pixels", "x0": 0, "y0": 16, "x1": 16, "y1": 32, "spp": 4}}),
        ),
        (
            ToTechnique::Consume { slot: 5, tile: Tile::Samples { count: 9 } },
            json!({"type": "consume", "slot": 5, "tile": {"kind": "samples", "count": 9}}),
        ),
        (
            ToTechnique::EvaluateDone { delivered: 10, remaining: 2 },
            json!({"type": "evaluate_done", "delivered": 10, "remaining": 2}),
        ),
        (ToTechnique::ResultAccepted, json!({"type": "result_accepted"})),
        (
            ToTechnique::Error { kind: ErrorKind::OverBudget, message: "no".into() },
            json!({"type": "error", "kind": "over_budget", "message": "no"}),
        ),
    ];
    round_trip(cases);
}

#[test]
fn renderer_messages() {
    let ring = RingSpec { session: 2, slot_count: 4, slot_bytes: 4096 };
    let to: Vec<(ToRenderer, Value)> = vec![
        (ToRenderer::Welcome { version: 1 }, json!({"type": "welcome", "version": 1})),
        (
            ToRenderer::SetLayout { layout: SampleLayout::new().with("DEPTH"), ring },
            json!({"type": "set_layout", "layout": {"entries": [{"name": "DEPTH", "number": 0, "io": "output"}], "roughness_threshold": 0.1},
                   "ring": {"session": 2, "slot_count": 4, "slot_bytes": 4096}}),
        ),
        (
            ToRenderer::Evaluate { spp: 2, remaining: 5, pipe_size: 1024, input: false, request: 0, seed: 0 },
            json!({"type": "evaluate", "spp": 2, "remaining": 5, "pipe_size": 1024, "input": false, "request": 0}),
        ),
        (ToRenderer::Granted { id: 9, slot: 3 }, json!({"type": "granted", "id": 9, "slot": 3})),
        (ToRenderer::EndSession, json!({"type": "end_session"})),
        (ToRenderer::Finish, json!({"type": "finish"})),
    ];
    round_trip(to);
    let mut info = SceneInfo::new();
    info.set("width", 8).set("height", 8);
    let from: Vec<(FromRenderer, Value)> = vec![
        (
            FromRenderer::Ready { tile_size: 16, scene_info: info },
            json!({"type": "ready", "tile_size": 16, "scene_info": {"width": 8, "height": 8}}),
        ),
        (FromRenderer::LayoutAccepted, json!({"type": "layout_accepted"})),
        (
            FromRenderer::Acquire { id: 9, tile: Tile::Samples { count: 100 } },
            json!({"type": "acquire", "id": 9, "tile": {"kind": "samples", "count": 100}}),
        ),
        (FromRenderer::Filled { slot: 3, count: 100 }, json!({"type": "filled", "slot": 3, "count": 100})),
        (FromRenderer::EvaluateDone, json!({"type": "evaluate_done"})),
        (FromRenderer::Failed { message: "oops".into() }, json!({"type": "failed", "message": "oops"})),
    ];
    round_trip(from);
}
