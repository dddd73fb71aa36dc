//! The faults a run can meet, by the names `run --inject` and `sim serve
//! --inject` take (`chamber-silent@600`): one model for the embedded bench
//! and the served simulators, which play them (the controller's `sim`), and
//! for the sweep and the reports that name them.

/// A fault, by the name `--inject` takes: the one fault model. The embedded
/// bench plays every one at a device time (`run --inject`); the served
/// simulators play the devices' ones ([`Fault::device`]) on their wire
/// protocols (`sim serve --inject`, `SharedBench::play`), so a
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
    /// The gyro link corrupts every `CORRUPT_EVERY_FRAMES`th frame
    /// (dropped, counted as a CRC error; served: one bit flipped in every
    /// 50 frames' bytes). The constants named here and below are the
    /// simulators' (the controller's `sim::faults`).
    GyroCorrupt,
    /// The gyro's output sticks at one value (`STUCK_COUNTS`).
    GyroStuck,
    /// The gyro's output pins at the largest count (`SATURATED_COUNTS`).
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_fault_is_read_back_from_its_name_and_the_names_are_distinct() {
        for (f, name) in Fault::ALL.into_iter().zip(Fault::NAMES) {
            assert_eq!(f.name(), name);
            assert_eq!(name.parse::<Fault>(), Ok(f));
        }
        let mut names = Fault::NAMES.to_vec();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), Fault::ALL.len());
    }

    #[test]
    fn a_fault_at_a_time_is_read_and_what_is_wrong_is_said() {
        assert_eq!(
            Fault::parse_at("chamber-silent@600"),
            Ok((600.0, Fault::ChamberSilent))
        );
        assert_eq!(
            Fault::parse_at("chamber-silent"),
            Err(FaultSpecError::NoTime("chamber-silent".into()))
        );
        for bad in ["gyro-silent@-1", "gyro-silent@inf", "gyro-silent@soon"] {
            assert_eq!(
                Fault::parse_at(bad),
                Err(FaultSpecError::Time(bad.into())),
                "{bad}"
            );
        }
        let unknown = Fault::parse_at("chamber-fire@5").expect_err("no such fault");
        assert!(
            unknown
                .to_string()
                .contains("unknown fault \"chamber-fire\"")
                && unknown.to_string().contains("gyro-silent"),
            "{unknown}"
        );
    }
}
