//! The gyro's digital output frame: layout, encoder and a sans-IO decoder.
//!
//! Default layout (ours, `docs/protocols.md`), 20 bytes:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 2 | sync `A5 5A` |
//! | 2 | 1 | frame type |
//! | 3 | 1 | sequence counter, wraps at 255 |
//! | 4 | 4 | delta-angle counts, i32 |
//! | 8 | 2x3 | T1, T2, TK, i16, 0.01 degC |
//! | 14 | 2 | status bits |
//! | 16 | 4 | CRC-32/MPEG-2 over bytes 0-15 |
//!
//! The decoder takes bytes in any chunks and gives events: frames, resyncs,
//! CRC failures, sequence gaps and duplicates. It never panics, never stalls
//! on garbage and holds at most one frame plus one read of bytes.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

/// CRC-32/MPEG-2: poly 0x04C11DB7, init 0xFFFFFFFF, no reflection, no final XOR.
pub const CRC32_MPEG2: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_MPEG_2);

/// Checksum closing a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Checksum {
    /// CRC-32/MPEG-2 over every byte before it.
    Crc32Mpeg2,
}

/// Longest frame a layout may describe, bytes.
pub const MAX_FRAME_LEN: usize = 1024;

/// Where each field sits in a frame. Multi-byte fields share one byte order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameLayout {
    /// Sync bytes at offset 0.
    pub sync: Vec<u8>,
    /// Expected frame-type byte.
    pub frame_type: u8,
    /// Offset of the frame-type byte.
    pub type_offset: usize,
    /// Offset of the sequence counter (one byte).
    pub seq_offset: usize,
    /// Offset of the delta-angle count (i32).
    pub counts_offset: usize,
    /// Offset of T1; T2 and TK follow (i16 each).
    pub temps_offset: usize,
    /// Temperature resolution, degC per LSB.
    pub temp_lsb_c: f64,
    /// Offset of the status word (u16).
    pub status_offset: usize,
    /// Offset of the checksum; it covers every byte before it.
    pub checksum_offset: usize,
    /// Checksum algorithm.
    pub checksum: Checksum,
    /// Multi-byte fields big-endian (false: little-endian).
    pub big_endian: bool,
    /// What the status word's bits say of the unit (default: the
    /// documented frame's; left out of a file that keeps it).
    #[serde(default, skip_serializing_if = "StatusBits::is_default")]
    pub status_bits: StatusBits,
}

/// What the status word says of the unit: which bits must all be set for
/// a frame to be used (the unit lasing, dithering, its path-length control
/// in lock), and which one is the path-length control's lock, whose fall
/// is a reset (a mode hop). The documented frame's bits: 0 lasing,
/// 1 dither, 2 path-length control locked, 3 self-test passed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StatusBits {
    /// Bits that must all be set for a frame to be used (0: every frame
    /// is used; a unit whose status word says nothing of its fitness).
    pub fit_mask: u16,
    /// The bit set while the path-length control is in lock (none: the
    /// unit does not report it, and no reset is counted).
    pub path_length_lock_bit: Option<u8>,
}

impl Default for StatusBits {
    fn default() -> Self {
        Self {
            fit_mask: 0b0111,
            path_length_lock_bit: Some(2),
        }
    }
}

impl StatusBits {
    /// True for the documented frame's bits.
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// True when a frame with `status` may be used.
    pub fn fit(&self, status: u16) -> bool {
        status & self.fit_mask == self.fit_mask
    }

    /// Whether the path-length control is in lock (none: not reported).
    pub fn path_length_locked(&self, status: u16) -> Option<bool> {
        self.path_length_lock_bit.map(|b| status & (1u16 << b) != 0)
    }

    /// The bits of `fit_mask` that `status` lacks, in words (the
    /// documented frame's meanings, else the bit's number).
    pub fn unfit_words(&self, status: u16) -> Vec<String> {
        let missing = self.fit_mask & !status;
        (0..16u8)
            .filter(|b| missing & (1 << b) != 0)
            .map(|b| match b {
                _ if self.path_length_lock_bit == Some(b) => {
                    "path-length control out of lock".to_owned()
                }
                0 if self.is_default() => "not lasing".to_owned(),
                1 if self.is_default() => "dither off".to_owned(),
                _ => format!("status bit {b} clear"),
            })
            .collect()
    }
}

impl Default for FrameLayout {
    fn default() -> Self {
        Self {
            sync: vec![0xA5, 0x5A],
            frame_type: 0x01,
            type_offset: 2,
            seq_offset: 3,
            counts_offset: 4,
            temps_offset: 8,
            temp_lsb_c: 0.01,
            status_offset: 14,
            checksum_offset: 16,
            checksum: Checksum::Crc32Mpeg2,
            big_endian: false,
            status_bits: StatusBits::default(),
        }
    }
}

/// Why a layout cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid gyro frame layout: {0}")]
pub struct LayoutError(pub String);

impl FrameLayout {
    /// Total frame length, bytes.
    pub fn len(&self) -> usize {
        self.checksum_offset + 4
    }

    /// Always false: a frame has at least its checksum.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Check that fields fit before the checksum and do not overlap the sync.
    pub fn validate(&self) -> Result<(), LayoutError> {
        let s = self.sync.len();
        if s == 0 {
            return Err(LayoutError("the sync must have at least one byte".into()));
        }
        // Checked before anything is sized by it: a layout comes from files
        // (a bench, a sim serve config, a log's embedded bench).
        if self.checksum_offset > MAX_FRAME_LEN - 4 || s > MAX_FRAME_LEN {
            return Err(LayoutError(format!(
                "checksum_offset {} and a {s}-byte sync make a frame longer than {MAX_FRAME_LEN} bytes; no gyro output frame is that long",
                self.checksum_offset
            )));
        }
        let fields = [
            ("type", self.type_offset, 1),
            ("sequence", self.seq_offset, 1),
            ("counts", self.counts_offset, 4),
            ("temperatures", self.temps_offset, 6),
            ("status", self.status_offset, 2),
        ];
        let mut used = vec![false; self.checksum_offset];
        for (name, off, size) in fields {
            if off < s || off.saturating_add(size) > self.checksum_offset {
                return Err(LayoutError(format!(
                    "field {name} at {off}..{} must lie between the sync ({s} bytes) and the checksum at {}",
                    off.saturating_add(size),
                    self.checksum_offset
                )));
            }
            for u in &mut used[off..off + size] {
                if *u {
                    return Err(LayoutError(format!("field {name} overlaps another field")));
                }
                *u = true;
            }
        }
        if !(self.temp_lsb_c.is_finite() && self.temp_lsb_c > 0.0) {
            return Err(LayoutError("temp_lsb_c must be above zero".into()));
        }
        if let Some(b) = self.status_bits.path_length_lock_bit
            && b > 15
        {
            return Err(LayoutError(format!(
                "status_bits.path_length_lock_bit {b} is not a bit of the 16-bit status word (0-15)"
            )));
        }
        Ok(())
    }

    fn put_u16(&self, out: &mut [u8], off: usize, v: u16) {
        let b = if self.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        out[off..off + 2].copy_from_slice(&b);
    }

    fn get_u16(&self, b: &[u8], off: usize) -> u16 {
        let a = [b[off], b[off + 1]];
        if self.big_endian {
            u16::from_be_bytes(a)
        } else {
            u16::from_le_bytes(a)
        }
    }

    fn get_u32(&self, b: &[u8], off: usize) -> u32 {
        let a = [b[off], b[off + 1], b[off + 2], b[off + 3]];
        if self.big_endian {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        }
    }

    /// Encode one frame, appending its bytes to `out`.
    pub fn encode(&self, f: &WireFrame, out: &mut Vec<u8>) {
        let start = out.len();
        out.resize(start + self.len(), 0);
        let b = &mut out[start..];
        b[..self.sync.len()].copy_from_slice(&self.sync);
        b[self.type_offset] = f.frame_type;
        b[self.seq_offset] = f.seq;
        let c = if self.big_endian {
            f.delta_counts.to_be_bytes()
        } else {
            f.delta_counts.to_le_bytes()
        };
        b[self.counts_offset..self.counts_offset + 4].copy_from_slice(&c);
        for (i, t) in f.temps_raw.iter().enumerate() {
            self.put_u16(b, self.temps_offset + 2 * i, *t as u16);
        }
        self.put_u16(b, self.status_offset, f.status);
        let crc = CRC32_MPEG2.checksum(&b[..self.checksum_offset]);
        let cb = if self.big_endian {
            crc.to_be_bytes()
        } else {
            crc.to_le_bytes()
        };
        b[self.checksum_offset..self.checksum_offset + 4].copy_from_slice(&cb);
    }

    /// Decode a frame whose checksum has been verified.
    fn fields(&self, b: &[u8]) -> WireFrame {
        let t = |i: usize| self.get_u16(b, self.temps_offset + 2 * i) as i16;
        WireFrame {
            frame_type: b[self.type_offset],
            seq: b[self.seq_offset],
            delta_counts: self.get_u32(b, self.counts_offset) as i32,
            temps_raw: [t(0), t(1), t(2)],
            status: self.get_u16(b, self.status_offset),
        }
    }

    /// Temperature in degC to the wire's integer (saturating).
    pub fn temp_to_raw(&self, temp_c: f64) -> i16 {
        (temp_c / self.temp_lsb_c)
            .round()
            .clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
    }

    /// The wire's integer to degC.
    pub fn raw_to_temp(&self, raw: i16) -> f64 {
        f64::from(raw) * self.temp_lsb_c
    }
}

/// The fields of one frame as they travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WireFrame {
    /// Frame type.
    pub frame_type: u8,
    /// Sequence counter.
    pub seq: u8,
    /// Delta-angle counts since the previous frame.
    pub delta_counts: i32,
    /// T1, T2, TK in LSBs of the layout's resolution.
    pub temps_raw: [i16; 3],
    /// Status bits.
    pub status: u16,
}

/// What the decoder found in the byte stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// A frame with a good checksum.
    Frame(WireFrame),
    /// Bytes skipped while hunting for the sync.
    Resync {
        /// How many bytes were skipped.
        skipped: usize,
    },
    /// A candidate frame whose checksum did not match (one byte is then
    /// skipped and the hunt goes on).
    BadCrc {
        /// Checksum computed over the received bytes.
        expected: u32,
        /// Checksum the frame carried.
        got: u32,
        /// Stream offset of the candidate frame.
        offset: u64,
    },
    /// Frames missing before this one, from the sequence counter.
    Gap {
        /// Number of frames lost (modulo 256).
        lost: u32,
    },
    /// A frame repeating the previous sequence number (dropped).
    Duplicate {
        /// The repeated sequence number.
        seq: u8,
    },
}

/// Link figures of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct LinkStats {
    /// Bytes received.
    pub bytes: u64,
    /// Frames accepted.
    pub frames: u64,
    /// Times the decoder had to hunt for the sync.
    pub resyncs: u64,
    /// Bytes skipped while hunting.
    pub skipped_bytes: u64,
    /// Candidate frames with a bad checksum.
    pub crc_errors: u64,
    /// Frames missing according to the sequence counter.
    pub lost_frames: u64,
    /// Duplicated frames dropped.
    pub duplicates: u64,
    /// Times the link was reopened after it dropped.
    #[serde(default)]
    pub reconnects: u64,
    /// Longest stretch without a valid frame, ms (host clock; 0 when not
    /// measured, as on the embedded bench).
    #[serde(default)]
    pub longest_gap_ms: u64,
}

/// Sans-IO frame decoder: `push` bytes, then drain `next_event` until `None`
/// (= need more data).
#[derive(Debug, Clone)]
pub struct Decoder {
    layout: FrameLayout,
    buf: Vec<u8>,
    start: usize,
    /// Stream offset of `buf[start]`.
    offset: u64,
    last_seq: Option<u8>,
    pending: VecDeque<Event>,
    hunting: usize,
    stats: LinkStats,
}

impl Decoder {
    /// A decoder for `layout` (validate it first).
    pub fn new(layout: FrameLayout) -> Self {
        Self {
            buf: Vec::with_capacity(4 * layout.len()),
            layout,
            start: 0,
            offset: 0,
            last_seq: None,
            pending: VecDeque::new(),
            hunting: 0,
            stats: LinkStats::default(),
        }
    }

    /// Figures so far.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// The layout in use.
    pub fn layout(&self) -> &FrameLayout {
        &self.layout
    }

    /// Feed received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.start > 0 && self.start >= self.buf.len() / 2 {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
        self.stats.bytes += bytes.len() as u64;
    }

    fn consume(&mut self, n: usize) {
        self.start += n;
        self.offset += n as u64;
    }

    fn skip(&mut self, n: usize) {
        self.consume(n);
        self.hunting += n;
        self.stats.skipped_bytes += n as u64;
    }

    fn end_hunt(&mut self) -> Option<Event> {
        if self.hunting == 0 {
            return None;
        }
        let skipped = std::mem::take(&mut self.hunting);
        self.stats.resyncs += 1;
        Some(Event::Resync { skipped })
    }

    /// The next event, or `None` when more bytes are needed.
    pub fn next_event(&mut self) -> Option<Event> {
        if let Some(e) = self.pending.pop_front() {
            return Some(e);
        }
        let len = self.layout.len();
        let sync_len = self.layout.sync.len();
        loop {
            let avail = &self.buf[self.start..];
            // Hunt: put the first byte that could begin a sync at the front.
            match avail
                .windows(sync_len)
                .position(|w| w == self.layout.sync.as_slice())
            {
                Some(0) => {}
                Some(p) => {
                    self.skip(p);
                    continue;
                }
                None => {
                    // Keep a possible partial sync at the end.
                    let keep = partial_sync_suffix(avail, &self.layout.sync);
                    let drop = avail.len() - keep;
                    if drop > 0 {
                        self.skip(drop);
                    }
                    return None;
                }
            }
            if avail.len() < len {
                return None;
            }
            let frame = &avail[..len];
            let co = self.layout.checksum_offset;
            let expected = CRC32_MPEG2.checksum(&frame[..co]);
            let got = self.layout.get_u32(frame, co);
            if expected != got || frame[self.layout.type_offset] != self.layout.frame_type {
                let offset = self.offset;
                self.stats.crc_errors += 1;
                self.skip(1);
                return Some(Event::BadCrc {
                    expected,
                    got,
                    offset,
                });
            }
            let wf = self.layout.fields(frame);
            self.consume(len);
            if let Some(e) = self.end_hunt() {
                self.pending.push_back(e);
            }
            match self.last_seq {
                Some(last) if wf.seq == last => {
                    self.stats.duplicates += 1;
                    self.pending.push_back(Event::Duplicate { seq: wf.seq });
                    return self.pending.pop_front();
                }
                Some(last) => {
                    let lost = u32::from(wf.seq.wrapping_sub(last).wrapping_sub(1));
                    if lost > 0 {
                        self.stats.lost_frames += u64::from(lost);
                        self.pending.push_back(Event::Gap { lost });
                    }
                }
                None => {}
            }
            self.last_seq = Some(wf.seq);
            self.stats.frames += 1;
            self.pending.push_back(Event::Frame(wf));
            return self.pending.pop_front();
        }
    }
}

/// Length of the longest suffix of `data` that is a proper prefix of `sync`.
fn partial_sync_suffix(data: &[u8], sync: &[u8]) -> usize {
    (1..sync.len().min(data.len() + 1))
        .rev()
        .find(|&k| data[data.len() - k..] == sync[..k])
        .unwrap_or(0)
}

#[cfg(test)]
mod tests;
