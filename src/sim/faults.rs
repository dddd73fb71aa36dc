//! Fault injection: the faults a run can meet ([`Fault`], one model for
//! the embedded bench and the served simulators) and the switches the
//! served simulators play them with (what each device does wrong).

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize, Ordering};
use std::time::Duration;

/// A fault, by the name `--inject` takes: the one fault model. The embedded
/// bench plays every one at a device time (`run --inject`); the served
/// simulators play the devices' ones ([`Fault::device`]) on their wire
/// protocols (`sim serve --inject`, [`super::SharedBench::play`]), so a
/// run on the real drivers meets the same fault by the same name.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The chamber raises alarm 9.
    ChamberAlarm,
    /// The chamber stops answering.
    ChamberSilent,
    /// The table's system interlock trips.
    TableInterlock,
    /// The gyro stops sending.
    GyroSilent,
    /// The gyro link corrupts every [`CORRUPT_EVERY_FRAMES`]th frame
    /// (dropped, counted as a CRC error; served: one bit flipped in every
    /// 50 frames' bytes).
    GyroCorrupt,
    /// The gyro's output sticks at one value ([`STUCK_COUNTS`]).
    GyroStuck,
    /// The gyro's output pins at the largest count ([`SATURATED_COUNTS`]).
    GyroSaturated,
    /// The process dies at once, as under SIGKILL: no cleanup, no footer
    /// (for the fault-and-resume sweep).
    ProcessKill,
    /// A bug: the run panics mid-tick (the bench must still reach its safe
    /// state).
    Panic,
    /// The unit shorts: it draws three times its current, and the supply's
    /// over-current protection trips (a bench with a supply).
    SupplyOvercurrent,
    /// The disk the log is on fills: every write to the log fails from
    /// then on, as with `No space left on device` (the recorder plays it;
    /// the bench carries on).
    DiskFull,
    /// The process gets SIGHUP (its terminal or SSH session closed), once.
    Hangup,
    /// The process gets SIGQUIT (Ctrl-\), once.
    Quit,
    /// A batch's last unit's gyro link is lost for good: it sends nothing
    /// more (the others go on).
    UnitLost,
    /// The supply takes `OUTP OFF` without an error and leaves its output
    /// on (a welded relay, a firmware fault): the unit stays powered
    /// whatever the run asks.
    SupplyIgnoresOff,
}

impl Fault {
    /// Every fault, in the order `--help` lists them.
    pub const ALL: [Self; 15] = [
        Self::ChamberAlarm,
        Self::ChamberSilent,
        Self::TableInterlock,
        Self::GyroSilent,
        Self::GyroCorrupt,
        Self::GyroStuck,
        Self::GyroSaturated,
        Self::ProcessKill,
        Self::Panic,
        Self::SupplyOvercurrent,
        Self::DiskFull,
        Self::Hangup,
        Self::Quit,
        Self::UnitLost,
        Self::SupplyIgnoresOff,
    ];

    /// Every fault by the name `--inject` takes.
    pub const NAMES: [&str; 15] = {
        let mut names = [""; 15];
        let mut i = 0;
        while i < 15 {
            names[i] = Self::ALL[i].name();
            i += 1;
        }
        names
    };
}

impl std::str::FromStr for Fault {
    type Err = FaultSpecError;
    fn from_str(s: &str) -> Result<Self, FaultSpecError> {
        Self::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| FaultSpecError::Unknown(s.to_owned()))
    }
}

/// What is wrong with a fault as `--inject` takes it (`FAULT@SECONDS`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FaultSpecError {
    /// No fault of that name.
    #[error("unknown fault {0:?}; expected {names}", names = Fault::NAMES.join(", "))]
    Unknown(String),
    /// No `@` between the fault and its time.
    #[error("{0:?}: expected FAULT@SECONDS, e.g. chamber-silent@600")]
    NoTime(String),
    /// The fault's name is not one (the spec, and why).
    #[error("{0:?}: {1}")]
    Name(String, Box<FaultSpecError>),
    /// The time is not seconds of device time.
    #[error("{0:?}: the time must be seconds of device time")]
    Time(String),
}

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

impl Fault {
    /// The device the fault acts on (`chamber`, `table`, `gyro`, `supply`),
    /// or `None` for a fault of the controller itself (its process, its
    /// signals, its log's disk), which only `run --inject` plays.
    pub fn device(self) -> Option<&'static str> {
        match self {
            Self::ChamberAlarm | Self::ChamberSilent => Some("chamber"),
            Self::TableInterlock => Some("table"),
            Self::GyroSilent
            | Self::GyroCorrupt
            | Self::GyroStuck
            | Self::GyroSaturated
            | Self::UnitLost => Some("gyro"),
            Self::SupplyOvercurrent | Self::SupplyIgnoresOff => Some("supply"),
            Self::ProcessKill | Self::Panic | Self::DiskFull | Self::Hangup | Self::Quit => None,
        }
    }

    /// Its name, as `--inject` takes it.
    pub const fn name(self) -> &'static str {
        match self {
            Self::ChamberAlarm => "chamber-alarm",
            Self::ChamberSilent => "chamber-silent",
            Self::TableInterlock => "table-interlock",
            Self::GyroSilent => "gyro-silent",
            Self::GyroCorrupt => "gyro-corrupt",
            Self::GyroStuck => "gyro-stuck",
            Self::GyroSaturated => "gyro-saturated",
            Self::ProcessKill => "process-kill",
            Self::Panic => "panic",
            Self::SupplyOvercurrent => "supply-overcurrent",
            Self::DiskFull => "disk-full",
            Self::Hangup => "sighup",
            Self::Quit => "sigquit",
            Self::UnitLost => "unit-lost",
            Self::SupplyIgnoresOff => "supply-ignores-off",
        }
    }

    /// `FAULT@SECONDS` (`chamber-silent@600`): the fault and the device
    /// time it starts at, s. The error says what is wrong with `s`.
    pub fn parse_at(s: &str) -> Result<(f64, Self), FaultSpecError> {
        let (f, t) = s
            .split_once('@')
            .ok_or_else(|| FaultSpecError::NoTime(s.to_owned()))?;
        let fault: Self = f
            .parse()
            .map_err(|e| FaultSpecError::Name(s.to_owned(), Box::new(e)))?;
        let at: f64 = t
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| FaultSpecError::Time(s.to_owned()))?;
        Ok((at, fault))
    }
}

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
