use proptest::prelude::*;

use super::*;

fn frames(n: usize) -> Vec<WireFrame> {
    (0..n)
        .map(|i| WireFrame {
            frame_type: 1,
            seq: (i % 256) as u8,
            delta_counts: (i as i32 * 7919) % 1000 - 500,
            temps_raw: [2000 + i as i16, 1990, -4000],
            status: 0x000F,
        })
        .collect()
}

fn stream(layout: &FrameLayout, fs: &[WireFrame]) -> Vec<u8> {
    let mut out = Vec::new();
    for f in fs {
        layout.encode(f, &mut out);
    }
    out
}

fn drain(d: &mut Decoder) -> Vec<Event> {
    std::iter::from_fn(|| d.next_event()).collect()
}

fn decoded(events: &[Event]) -> Vec<WireFrame> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::Frame(f) => Some(*f),
            _ => None,
        })
        .collect()
}

#[test]
fn crc_matches_the_published_kvh_frame() {
    let hex = "FE81FF5537A96A6E38586C1FB75BF862BF803E78BB650D283B0A37AC773D0028";
    let bytes: Vec<u8> = (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).expect("hex"))
        .collect();
    assert_eq!(bytes.len(), 32);
    assert_eq!(CRC32_MPEG2.checksum(&bytes), 0x4BFA_34D8);
}

#[test]
fn default_layout_is_the_documented_twenty_bytes() {
    let l = FrameLayout::default();
    l.validate().expect("default layout is valid");
    assert_eq!(l.len(), 20);
    let mut out = Vec::new();
    l.encode(
        &WireFrame {
            frame_type: 1,
            seq: 0x42,
            delta_counts: -2,
            temps_raw: [2000, -1, 0x1234],
            status: 0x000F,
        },
        &mut out,
    );
    assert_eq!(
        &out[..16],
        &[
            0xA5, 0x5A, 0x01, 0x42, 0xFE, 0xFF, 0xFF, 0xFF, 0xD0, 0x07, 0xFF, 0xFF, 0x34, 0x12,
            0x0F, 0x00
        ]
    );
    let crc = CRC32_MPEG2.checksum(&out[..16]);
    assert_eq!(&out[16..], &crc.to_le_bytes());
}

#[test]
fn round_trip_in_both_byte_orders() {
    for big_endian in [false, true] {
        let layout = FrameLayout {
            big_endian,
            ..FrameLayout::default()
        };
        let fs = frames(600);
        let mut d = Decoder::new(layout.clone());
        d.push(&stream(&layout, &fs));
        let ev = drain(&mut d);
        assert_eq!(decoded(&ev), fs);
        assert_eq!(d.stats().frames, 600);
        assert_eq!(d.stats().lost_frames, 0);
    }
}

#[test]
fn split_at_every_byte_boundary_gives_the_same_frames() {
    let layout = FrameLayout::default();
    let fs = frames(5);
    let bytes = stream(&layout, &fs);
    for cut in 0..=bytes.len() {
        let mut d = Decoder::new(layout.clone());
        d.push(&bytes[..cut]);
        let mut ev = drain(&mut d);
        d.push(&bytes[cut..]);
        ev.extend(drain(&mut d));
        assert_eq!(decoded(&ev), fs, "cut at {cut}");
        assert_eq!(d.stats().resyncs, 0, "cut at {cut}");
    }
    // And byte by byte.
    let mut d = Decoder::new(layout);
    let mut ev = Vec::new();
    for b in &bytes {
        d.push(std::slice::from_ref(b));
        ev.extend(drain(&mut d));
    }
    assert_eq!(decoded(&ev), fs);
}

#[test]
fn starting_mid_frame_resyncs_on_the_next_sync() {
    let layout = FrameLayout::default();
    let fs = frames(4);
    let bytes = stream(&layout, &fs);
    let mut d = Decoder::new(layout);
    d.push(&bytes[7..]);
    let ev = drain(&mut d);
    assert_eq!(decoded(&ev), fs[1..].to_vec());
    assert!(ev.contains(&Event::Resync { skipped: 13 }), "{ev:?}");
}

#[test]
fn one_corrupted_byte_loses_exactly_that_frame() {
    let layout = FrameLayout::default();
    let fs = frames(10);
    let mut bytes = stream(&layout, &fs);
    bytes[3 * 20 + 9] ^= 0x10;
    let mut d = Decoder::new(layout);
    d.push(&bytes);
    let ev = drain(&mut d);
    let got = decoded(&ev);
    assert_eq!(got.len(), 9);
    assert_eq!(got[3], fs[4], "resynced on the very next frame");
    assert!(ev.contains(&Event::Gap { lost: 1 }));
    assert!(
        ev.iter()
            .any(|e| matches!(e, Event::BadCrc { offset: 60, .. }))
    );
    let s = d.stats();
    assert_eq!((s.frames, s.lost_frames, s.crc_errors), (9, 1, 1));
}

#[test]
fn duplicates_are_dropped_and_counted() {
    let layout = FrameLayout::default();
    let mut fs = frames(3);
    fs.insert(2, fs[1]);
    let mut d = Decoder::new(layout.clone());
    d.push(&stream(&layout, &fs));
    let ev = drain(&mut d);
    assert_eq!(decoded(&ev).len(), 3);
    assert!(ev.contains(&Event::Duplicate { seq: 1 }));
    assert_eq!(d.stats().duplicates, 1);
}

#[test]
fn garbage_alone_is_skipped_without_stalling_or_growing() {
    let mut d = Decoder::new(FrameLayout::default());
    let garbage: Vec<u8> = (0..100_000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    for chunk in garbage.chunks(4096) {
        d.push(chunk);
        let _ = drain(&mut d);
    }
    assert_eq!(d.stats().frames, 0);
    assert!(
        d.buf.len() - d.start < 4096 + 20,
        "buffer must not grow with garbage"
    );
}

#[test]
fn invalid_layouts_are_refused() {
    let overlap = FrameLayout {
        seq_offset: 4,
        ..FrameLayout::default()
    };
    assert!(overlap.validate().is_err());
    let on_sync = FrameLayout {
        type_offset: 1,
        ..FrameLayout::default()
    };
    assert!(on_sync.validate().is_err());
    // Sizes from a hostile file are refused before anything is allocated.
    for offset in [1_000_000_000_000, usize::MAX - 2, usize::MAX] {
        let huge = FrameLayout {
            checksum_offset: offset,
            counts_offset: offset - 1,
            ..FrameLayout::default()
        };
        let err = huge.validate().expect_err("too long");
        assert!(err.to_string().contains("longer than"), "{err}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Random corruption (flipped, dropped and inserted bytes) anywhere but
    /// the last two frames: no panic, every frame is either decoded intact or
    /// counted as lost, and the stream ends in sync.
    #[test]
    fn corruption_never_loses_count(
        n in 3usize..200,
        edits in proptest::collection::vec((any::<u32>(), 0u8..3, any::<u8>()), 0..40),
        chunk in 1usize..64,
    ) {
        let layout = FrameLayout::default();
        let fs = frames(n);
        let mut bytes = stream(&layout, &fs);
        let protected = bytes.len() - 2 * layout.len();
        for (pos, kind, val) in edits {
            let p = pos as usize % protected.max(1);
            match kind {
                0 => bytes[p] ^= val | 1,
                1 => { bytes.remove(p); }
                _ => bytes.insert(p, val),
            }
        }
        let mut d = Decoder::new(layout);
        let mut got = Vec::new();
        for c in bytes.chunks(chunk) {
            d.push(c);
            got.extend(decoded(&drain(&mut d)));
        }
        // Every decoded frame is one that was sent (CRC-checked), in order.
        let mut it = fs.iter();
        for g in &got {
            prop_assert!(it.any(|f| f == g), "decoded a frame never sent: {:?}", g);
        }
        prop_assert_eq!(got.last(), fs.last());
        let s = d.stats();
        // Frames before the first one decoded cannot be known to be lost;
        // from there on (fewer than 256 frames, no full lap of the counter)
        // every frame is decoded or counted.
        prop_assert_eq!(s.frames + s.lost_frames, n as u64 - u64::from(got[0].seq));
    }
}
