//! Wire protocols, sans-IO: bytes in, events out. No sockets, no files,
//! no time here; drivers and simulators wrap these codecs.

pub mod acl;
pub mod espec;
pub mod frame;
pub mod scpi;
pub mod supply;
pub mod watlow;

use serde::{Deserialize, Serialize};

/// What an instrument says it is, parsed from its identity replies
/// (`*IDN?`, Espec's `TYPE?` and `ROM?`, the F4T's part number). A field
/// the instrument does not report is none.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Identity {
    /// Maker.
    pub manufacturer: Option<String>,
    /// Model (or controller type, or part number).
    pub model: Option<String>,
    /// The instrument's serial number.
    pub serial: Option<String>,
    /// Firmware version.
    pub firmware: Option<String>,
    /// The replies as received, joined by ` | `.
    pub raw: String,
}

impl Identity {
    /// In words: `Espec SCP-220,TEMP, firmware GYROBENCH-SIM,0.1`.
    pub fn describe(&self) -> String {
        let mut s = [&self.manufacturer, &self.model]
            .iter()
            .filter_map(|v| v.as_deref())
            .collect::<Vec<_>>()
            .join(" ");
        if let Some(v) = &self.serial {
            s.push_str(&format!(", serial {v}"));
        }
        if let Some(v) = &self.firmware {
            s.push_str(&format!(", firmware {v}"));
        }
        if s.is_empty() {
            s = format!("(unparsed: {})", self.raw);
        }
        s
    }
}

/// Text from an instrument, made safe to keep: control characters
/// dropped, blanks trimmed, at most 120 characters; none when empty.
pub fn clean_field(s: &str) -> Option<String> {
    let t: String = s
        .chars()
        .filter(|c| !c.is_control())
        .take(120)
        .collect::<String>()
        .trim()
        .to_owned();
    (!t.is_empty() && t != "0").then_some(t)
}
