//! Watlow F4T over Modbus: register map and value encoding.
//!
//! Values are IEEE-754 float32 in two holding registers, low word first.
//! Addresses are Modbus PDU register addresses (what `pymodbus`
//! `read_holding_registers(2820, count=2)` asks for). Loop n adds
//! `160 * (n - 1)`. The transport is tokio-modbus; this module is the map.

/// Process value of loop 1, degC (read-only).
pub const PV: u16 = 2820;
/// Constant set point of loop 1, degC (read/write).
pub const SET_POINT: u16 = 2782;
/// Current (working) set point of loop 1, degC (read-only).
pub const CURRENT_SET_POINT: u16 = 2810;
/// Set-point range low, degC.
pub const SP_RANGE_LOW: u16 = 2774;
/// Set-point range high, degC.
pub const SP_RANGE_HIGH: u16 = 2776;
/// Control mode of loop 1 (enumeration in one register).
pub const CONTROL_MODE: u16 = 2730;
/// Profile state (149 running, 146 paused).
pub const PROFILE_STATE: u16 = 16568;

/// The controller's part number: [`PART_NUMBER_LEN`] registers from here,
/// one ASCII character in each (zeros ignored), as the F4T's Modbus map
/// gives it.
pub const PART_NUMBER: u16 = 16;
/// Registers of the part number.
pub const PART_NUMBER_LEN: u16 = 15;

/// Offset between loops.
pub const LOOP_STRIDE: u16 = 160;

/// Control mode values.
pub mod mode {
    /// Loop off.
    pub const OFF: u16 = 62;
    /// Automatic (closed loop on the set point).
    pub const AUTO: u16 = 10;
    /// Manual (open loop).
    pub const MANUAL: u16 = 54;
}

/// Profile state values.
pub mod profile {
    /// A profile runs.
    pub const RUNNING: u16 = 149;
    /// A profile is paused.
    pub const PAUSED: u16 = 146;
    /// No profile (ours: the F4T reports "off" this way).
    pub const OFF: u16 = 62;
}

/// Register address of `base` for loop `n` (1-based).
pub fn for_loop(base: u16, n: u16) -> u16 {
    base + LOOP_STRIDE * n.saturating_sub(1)
}

/// A float32 as two registers, low word first.
pub fn encode_f32(v: f32) -> [u16; 2] {
    let bits = v.to_bits();
    [(bits & 0xFFFF) as u16, (bits >> 16) as u16]
}

/// Two registers (low word first) as a float32; `None` unless finite.
pub fn decode_f32(words: &[u16]) -> Option<f32> {
    let [lo, hi] = words else { return None };
    let v = f32::from_bits(u32::from(*lo) | (u32::from(*hi) << 16));
    v.is_finite().then_some(v)
}

/// The part number in its registers (one character a register).
pub fn decode_string(words: &[u16]) -> String {
    words
        .iter()
        .filter(|w| **w != 0)
        .filter_map(|w| char::from_u32(u32::from(*w)))
        .collect()
}

/// The registers holding `s` (one character a register, zero-padded to
/// `len`).
pub fn encode_string(s: &str, len: usize) -> Vec<u16> {
    let mut v: Vec<u16> = s.bytes().map(u16::from).take(len).collect();
    v.resize(len, 0);
    v
}

/// The identity in the part number registers; the F4T's serial number and
/// firmware sit in registers this driver does not read.
pub fn parse_identity(words: &[u16]) -> super::Identity {
    let part = decode_string(words);
    super::Identity {
        manufacturer: Some("Watlow".into()),
        model: super::clean_field(&part),
        serial: None,
        firmware: None,
        raw: format!("part number {part}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_are_low_word_first() {
        // 25.0 = 0x41C80000: low word 0x0000, high word 0x41C8.
        assert_eq!(encode_f32(25.0), [0x0000, 0x41C8]);
        assert_eq!(decode_f32(&[0x0000, 0x41C8]), Some(25.0));
        assert_eq!(decode_f32(&encode_f32(-40.5)), Some(-40.5));
        assert_eq!(decode_f32(&[0x0000, 0x7FC0]), None, "NaN is not a value");
        assert_eq!(decode_f32(&[1]), None);
        assert_eq!(for_loop(PV, 2), 2980);
    }

    proptest::proptest! {
        #[test]
        fn decode_never_panics_and_round_trips(lo: u16, hi: u16) {
            if let Some(v) = decode_f32(&[lo, hi]) {
                proptest::prop_assert_eq!(encode_f32(v), [lo, hi]);
            }
        }
    }

    #[test]
    fn the_part_number_reads_back_from_its_registers() {
        let words = encode_string("F4T1L1AA1A1SIMA", usize::from(PART_NUMBER_LEN));
        assert_eq!(words.len(), 15);
        assert_eq!(words[0], u16::from(b'F'));
        let id = parse_identity(&words);
        assert_eq!(id.model.as_deref(), Some("F4T1L1AA1A1SIMA"));
        let short = encode_string("F4T", 15);
        assert_eq!(decode_string(&short), "F4T", "zeros ignored");
    }
}
