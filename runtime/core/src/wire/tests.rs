//! Round trips, limits, and decoding arbitrary bytes without panicking.

use std::time::Duration;

use balancer::Rect;
use proptest::prelude::*;

use super::*;

fn tile(id: u32, w: u32, h: u32) -> TileSpec {
    TileSpec::whole(TileId(id), Rect::new(8, 16, w, h), 2.5)
}

fn result(w: u32, h: u32) -> TileResult {
    let area = u64::from(w * h);
    TileResult {
        frame: FrameId(3),
        tile: TileId(9),
        piece: Piece(5),
        rect: Rect::new(0, 0, w, h),
        pixels: (0..area * BYTES_PER_PIXEL).map(|i| i as u8).collect(),
        costs: vec![7; area as usize],
    }
}

/// One message of every kind.
fn samples() -> Vec<Message> {
    let stats = PeerStats {
        slots: 4,
        busy: Duration::from_millis(1500),
        ..PeerStats::default()
    };
    vec![
        Message::Hello {
            version: PROTOCOL_VERSION,
            peer: PeerId(2),
            slots: 8,
        },
        Message::Welcome {
            version: PROTOCOL_VERSION,
            peer: PeerId(0),
        },
        Message::Peers {
            peers: vec![PeerAddress {
                peer: PeerId(1),
                addr: "10.0.0.7:4433".into(),
            }],
        },
        Message::Scene {
            files: vec![SceneFile {
                name: "meshes/bunny.obj".into(),
                hash: [5; 32],
                bytes: b"v 0 0 0\n".to_vec(),
            }],
            params: RenderParams {
                width: 64,
                height: 48,
                samples_per_pixel: 4,
                max_depth: Some(3),
                russian_roulette_depth: None,
                seed: 9,
                all_effects: true,
            },
        },
        Message::SceneReady,
        Message::Assign {
            frame: FrameId(1),
            peers: vec![PeerId(0), PeerId(1)],
            tiles: vec![tile(1, 4, 2)],
            render_pixels: 64,
        },
        Message::StealRequest {
            frame: FrameId(2),
            remaining: vec![(FrameId(1), 0.25), (FrameId(2), 4.0)],
        },
        Message::StealGrant {
            frame: FrameId(1),
            tiles: vec![tile(4, 2, 2), tile(5, 2, 1)],
        },
        Message::StealRefuse { frame: FrameId(1) },
        Message::StealNotice {
            frame: FrameId(1),
            victim: PeerId(3),
            tiles: vec![(TileId(4), Piece::WHOLE), (TileId(5), Piece(6))],
            stolen: 2,
        },
        Message::Status {
            frame: FrameId(1),
            idle: true,
            assigned: 1,
            stolen: 2,
            done: 3,
        },
        Message::TileDone(result(3, 2)),
        Message::FrameDone { frame: FrameId(1) },
        Message::FrameStats {
            frame: FrameId(1),
            stats,
        },
        Message::Goodbye {
            reason: GoodbyeReason::BadScene,
        },
        Message::Leaving,
    ]
}

#[test]
fn every_message_survives_a_round_trip() {
    for message in samples() {
        let decoded = decode(&encode(&message), &Limits::default()).unwrap();
        assert_eq!(decoded, message);
    }
}

#[test]
fn a_different_version_is_named_as_such() {
    let hello = Message::Hello {
        version: PROTOCOL_VERSION + 1,
        peer: PeerId(1),
        slots: 1,
    };
    match decode(&encode(&hello), &Limits::default()) {
        Err(WireError::VersionMismatch { theirs, ours }) => {
            assert_eq!((theirs, ours), (PROTOCOL_VERSION + 1, PROTOCOL_VERSION));
        }
        other => panic!("expected a version mismatch, got {other:?}"),
    }
    // A future Hello may carry more fields: the version is still found.
    let mut longer = encode(&hello);
    longer.extend_from_slice(&[1, 2, 3]);
    assert!(matches!(
        decode(&longer, &Limits::default()),
        Err(WireError::VersionMismatch { .. })
    ));
}

#[test]
fn pixel_buffers_must_fit_the_rectangle() {
    let mut short = result(3, 2);
    short.pixels.pop();
    let bytes = encode(&Message::TileDone(short));
    assert!(matches!(
        decode(&bytes, &Limits::default()),
        Err(WireError::Invalid { .. })
    ));

    let mut costly = result(3, 2);
    costly.costs = vec![0; (6 * MAX_COST_BYTES_PER_PIXEL + COST_HEADER_BYTES) as usize + 1];
    let bytes = encode(&Message::TileDone(costly));
    assert!(matches!(
        decode(&bytes, &Limits::default()),
        Err(WireError::Limit { .. })
    ));
}

#[test]
fn limits_bound_counts_and_sizes() {
    let limits = Limits {
        max_tiles_per_message: 1,
        ..Limits::default()
    };
    let grant = Message::StealGrant {
        frame: FrameId(1),
        tiles: vec![tile(1, 1, 1), tile(2, 1, 1)],
    };
    assert!(matches!(
        decode(&encode(&grant), &limits),
        Err(WireError::Limit { .. })
    ));

    let bytes = encode(&samples()[3]);
    let limits = Limits {
        max_message_bytes: bytes.len() - 1,
        ..Limits::default()
    };
    assert!(matches!(
        decode(&bytes, &limits),
        Err(WireError::TooLong { .. })
    ));

    let limits = Limits {
        max_file_bytes: 3,
        ..Limits::default()
    };
    assert!(matches!(
        decode(&bytes, &limits),
        Err(WireError::Limit { .. })
    ));

    let huge = Message::StealGrant {
        frame: FrameId(1),
        tiles: vec![tile(1, 1 << 13, 1 << 12)],
    };
    let limits = Limits {
        max_tile_pixels: 1 << 24,
        ..Limits::default()
    };
    assert!(matches!(
        decode(&encode(&huge), &limits),
        Err(WireError::Limit { .. })
    ));
}

#[test]
fn hostile_values_are_refused() {
    let refused = |message: Message| decode(&encode(&message), &Limits::default()).is_err();
    for predicted in [f64::NAN, f64::INFINITY, -1.0] {
        let spec = TileSpec {
            predicted,
            ..tile(1, 2, 2)
        };
        assert!(refused(Message::StealGrant {
            frame: FrameId(1),
            tiles: vec![spec]
        }));
    }
    assert!(refused(Message::StealRequest {
        frame: FrameId(1),
        remaining: vec![(FrameId(1), f64::NAN)]
    }));
    assert!(refused(Message::StealRequest {
        frame: FrameId(1),
        remaining: vec![(FrameId(1), 1.0); crate::wire::MAX_FRAMES_IN_FLIGHT + 1]
    }));
    let empty = TileSpec {
        rect: Rect::new(0, 0, 0, 4),
        ..tile(1, 1, 1)
    };
    assert!(refused(Message::Assign {
        frame: FrameId(1),
        peers: vec![],
        tiles: vec![empty],
        render_pixels: 1,
    }));
    let overflowing = TileSpec {
        rect: Rect::new(u32::MAX, 0, 2, 1),
        ..tile(1, 1, 1)
    };
    assert!(refused(Message::Assign {
        frame: FrameId(1),
        peers: vec![],
        tiles: vec![overflowing],
        render_pixels: 1,
    }));
    for name in [
        "../etc/passwd",
        "/abs",
        "a//b",
        "a/./b",
        "",
        "c:\\x",
        "a\0b",
    ] {
        let file = SceneFile {
            name: name.into(),
            hash: [0; 32],
            bytes: vec![],
        };
        assert!(
            refused(Message::Scene {
                files: vec![file],
                params: RenderParams::default()
            }),
            "{name:?} accepted"
        );
    }
}

#[test]
fn trailing_bytes_are_refused() {
    let mut bytes = encode(&Message::SceneReady);
    bytes.push(0);
    assert!(matches!(
        decode(&bytes, &Limits::default()),
        Err(WireError::Trailing(1))
    ));
}

#[test]
fn a_claimed_length_beyond_the_input_fails_without_allocating_it() {
    // A StealGrant claiming 2^32 tiles, followed by nothing.
    let mut bytes = encode(&Message::StealGrant {
        frame: FrameId(1),
        tiles: vec![],
    });
    bytes.pop();
    bytes.extend_from_slice(&[0xff, 0xff, 0xff, 0xff, 0x0f]);
    assert!(matches!(
        decode(&bytes, &Limits::default()),
        Err(WireError::Malformed(_))
    ));
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let _ = decode(&bytes, &Limits::default());
    }

    #[test]
    fn every_truncation_fails_cleanly(which in 0..15usize, cut in any::<prop::sample::Index>()) {
        let bytes = encode(&samples()[which]);
        let cut = cut.index(bytes.len());
        prop_assert!(decode(&bytes[..cut], &Limits::default()).is_err());
    }

    #[test]
    fn corrupted_messages_never_panic(
        which in 0..15usize,
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
    ) {
        let mut bytes = encode(&samples()[which]);
        for (at, value) in flips {
            let at = at.index(bytes.len());
            bytes[at] = value;
        }
        if let Ok(message) = decode(&bytes, &Limits::default()) {
            // Whatever decodes re-encodes to something that decodes to the same message.
            prop_assert_eq!(decode(&encode(&message), &Limits::default()).unwrap(), message);
        }
    }
}

#[test]
fn the_encoded_length_is_the_encodings() {
    let rect = Rect::new(3, 5, 13, 7);
    let messages = [
        Message::TileDone(TileResult {
            frame: FrameId(300),
            tile: TileId(70_000),
            piece: Piece(1 << 40),
            rect,
            pixels: vec![0; (rect.area() * BYTES_PER_PIXEL) as usize],
            costs: vec![0; cost_map_bytes(rect, 8) as usize],
        }),
        Message::StealRefuse {
            frame: FrameId(u32::MAX),
        },
        Message::SceneReady,
    ];
    for message in &messages {
        assert_eq!(encoded_len(message), encode(message).len());
    }
    // Columns 3..16 and rows 5..12 touch two blocks of 8 each way.
    assert_eq!(cost_map_bytes(rect, 8), 16 + 8 * 4);
    assert_eq!(cost_map_bytes(Rect::new(0, 0, 8, 8), 8), 16 + 8);
}

/// Frames are `u32` end to end: a message naming a frame past `u32::MAX` (as protocol 4's `u64`
/// could) does not decode, rather than reaching a renderer as another frame.
#[test]
fn a_frame_past_u32_does_not_decode() {
    let largest = encode(&Message::StealRefuse {
        frame: FrameId(u32::MAX),
    });
    let back = decode(&largest, &Limits::default()).expect("the largest frame decodes");
    assert_eq!(
        back,
        Message::StealRefuse {
            frame: FrameId(u32::MAX)
        }
    );
    // The variant's tag, then u32::MAX + 1 as a varint: seven bits a byte, low bits first.
    let zero = encode(&Message::StealRefuse { frame: FrameId(0) });
    let mut past = zero[..zero.len() - 1].to_vec();
    past.extend([0x80, 0x80, 0x80, 0x80, 0x10]);
    assert!(decode(&past, &Limits::default()).is_err());
}

/// `tile_result_len` counts what the encoder writes for a real result of every size, across the
/// lengths where the buffers' varint prefixes grow a byte (127/128 bytes, 16383/16384, ...),
/// without building it.
#[test]
fn a_tile_results_length_is_counted_without_its_buffers() {
    for (w, h) in [
        (1, 1),
        (3, 3),
        (4, 3),
        (10, 10),
        (37, 3),
        (64, 64),
        (128, 11),
        (200, 150),
    ] {
        for block in [1, 4, 8, 16, 64] {
            let rect = Rect::new(5, 7, w, h);
            let real = TileResult {
                frame: FrameId(0),
                tile: TileId(0),
                piece: Piece::WHOLE,
                rect,
                pixels: vec![0; (rect.area() * BYTES_PER_PIXEL) as usize],
                costs: vec![0; cost_map_bytes(rect, block) as usize],
            };
            assert_eq!(
                tile_result_len(rect, block),
                encoded_len(&Message::TileDone(real)) as u64,
                "{w}x{h} in blocks of {block}"
            );
        }
    }
}
