//! Fault injection: the faults a run can meet ([`Fault`], one model for
//! the embedded bench and the served simulators) and the switches the
//! served simulators play them with (what each device does wrong).

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize, Ordering};
use std::time::Duration;

pub use gyrobench_model::fault::{Fault, FaultSpecError};

/// Why a bench cannot play a fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Unplayable {
    /// A fault of the controller itself (its process or its log), which
    /// the embedded bench plays, not a device.
    #[error(
        "{} is a fault of the controller (its process or its log), not of a device: `gyrobench run --inject` plays it on the embedded bench{}",
        .fault.name(),
        .served.as_ref().map_or(String::new(), |p| format!("; sim serve plays {p}"))
    )]
    OfTheController {
        /// The fault.
        fault: Fault,
        /// The faults a served bench plays, in words, when the question
        /// was one before serving.
        served: Option<String>,
    },
    /// `unit-lost` on a bench of one unit.
    #[error(
        "unit-lost loses a batch's last unit: it needs a serve file with two slots or more{}",
        .example.map_or(String::new(), |e| format!(" ({e})"))
    )]
    OneUnit {
        /// A serve file with several units, when one can be named.
        example: Option<&'static str>,
    },
}

/// Counts per frame of a gyro whose output is stuck.
pub const STUCK_COUNTS: i32 = 3;

/// Counts per frame of a gyro whose output is saturated.
pub const SATURATED_COUNTS: i32 = i32::MAX;

/// Frames between two corrupted ones under [`Fault::GyroCorrupt`].
pub const CORRUPT_EVERY_FRAMES: u32 = 50;

/// A network outage (a switch rebooting, a cable pulled): while it lasts,
/// the device's connections are dropped and new ones closed at once.
#[derive(Debug, Default)]
pub struct Outage(Mutex<Option<tokio::time::Instant>>);

impl Outage {
    /// Start an outage of `d` (wall time) now.
    pub fn start(&self, d: Duration) {
        let mut until = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        *until = Some(tokio::time::Instant::now() + d);
    }

    /// True while the outage lasts.
    pub fn active(&self) -> bool {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .is_some_and(|u| tokio::time::Instant::now() < u)
    }
}

/// Faults of a request/reply instrument (chamber, table).
#[derive(Debug, Default)]
pub struct DeviceFaults {
    /// Swallow the next n requests (no reply).
    pub no_reply: AtomicU32,
    /// Garble the next n replies.
    pub garble: AtomicU32,
    /// Answer the next n requests with the instrument's error reply.
    pub error_reply: AtomicU32,
    /// Drop the connection at the next request (the listener keeps
    /// accepting, so a reconnect works).
    pub disconnect: AtomicBool,
    /// Answer nothing at all until cleared.
    pub silent: AtomicBool,
    /// Unreachable for a while.
    pub outage: Outage,
}

/// What to do with one request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Answer normally.
    Normal,
    /// Say nothing.
    NoReply,
    /// Answer with garbage.
    Garble,
    /// Answer with the instrument's error reply.
    ErrorReply,
    /// Close the connection.
    Disconnect,
}

fn take(counter: &AtomicU32) -> bool {
    counter
        .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1))
        .is_ok()
}

impl DeviceFaults {
    /// The action for the next request, consuming one-shot faults.
    pub fn next_action(&self) -> Action {
        if self.silent.load(Ordering::Relaxed) {
            Action::NoReply
        } else if self.disconnect.swap(false, Ordering::Relaxed) {
            Action::Disconnect
        } else if take(&self.no_reply) {
            Action::NoReply
        } else if take(&self.garble) {
            Action::Garble
        } else if take(&self.error_reply) {
            Action::ErrorReply
        } else {
            Action::Normal
        }
    }
}

/// Faults of the gyro's output stream.
#[derive(Debug, Default)]
pub struct GyroFaults {
    /// Flip one bit in every n-th byte (0 = off).
    pub corrupt_every: AtomicU32,
    /// Drop every n-th byte (0 = off).
    pub drop_every: AtomicU32,
    /// Send nothing until cleared.
    pub silent: AtomicBool,
    /// Unreachable for a while.
    pub outage: Outage,
    /// A batch's unit whose line sends nothing more, by index (0: none;
    /// the first unit's line takes `silent` instead).
    pub lost_line: AtomicUsize,
}

/// Faults of every simulated device.
#[derive(Debug, Default)]
pub struct Faults {
    /// Climatic chamber (Espec and Watlow servers).
    pub chamber: DeviceFaults,
    /// Motion simulator.
    pub table: DeviceFaults,
    /// Power supply.
    pub supply: DeviceFaults,
    /// Gyro output.
    pub gyro: GyroFaults,
}

/// Make a reply unusable while keeping its terminator, as line noise would.
pub fn garble(reply: &[u8]) -> Vec<u8> {
    reply
        .iter()
        .map(|&b| match b {
            b'\r' | b'\n' => b,
            b'0'..=b'9' => b'#',
            _ => b'?',
        })
        .collect()
}

/// Apply the stream faults to a chunk of gyro bytes; `position` counts
/// bytes sent so far and is advanced.
pub fn mangle_stream(f: &GyroFaults, chunk: &[u8], position: &mut u64) -> Vec<u8> {
    let corrupt = u64::from(f.corrupt_every.load(Ordering::Relaxed));
    let drop = u64::from(f.drop_every.load(Ordering::Relaxed));
    if corrupt == 0 && drop == 0 {
        *position += chunk.len() as u64;
        return chunk.to_vec();
    }
    let mut out = Vec::with_capacity(chunk.len());
    for &b in chunk {
        *position += 1;
        if drop > 0 && (*position).is_multiple_of(drop) {
            continue;
        }
        out.push(if corrupt > 0 && (*position).is_multiple_of(corrupt) {
            b ^ 0x20
        } else {
            b
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_shot_faults_are_consumed_in_order() {
        let f = DeviceFaults::default();
        f.no_reply.store(1, Ordering::Relaxed);
        f.garble.store(1, Ordering::Relaxed);
        assert_eq!(f.next_action(), Action::NoReply);
        assert_eq!(f.next_action(), Action::Garble);
        assert_eq!(f.next_action(), Action::Normal);
        f.silent.store(true, Ordering::Relaxed);
        assert_eq!(f.next_action(), Action::NoReply);
        assert_eq!(f.next_action(), Action::NoReply);
    }

    #[test]
    fn garbled_replies_keep_their_terminator() {
        assert_eq!(garble(b"23.5,OK\r\n"), b"##?#???\r\n");
    }

    #[test]
    fn stream_faults_drop_and_flip_the_right_bytes() {
        let f = GyroFaults::default();
        f.drop_every.store(4, Ordering::Relaxed);
        let mut pos = 0;
        assert_eq!(
            mangle_stream(&f, &[1, 2, 3, 4, 5, 6, 7, 8, 9], &mut pos),
            vec![1, 2, 3, 5, 6, 7, 9]
        );
        assert_eq!(pos, 9);
    }
}
