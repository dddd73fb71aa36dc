//! A step's key as the log, the report and the diagnosis name it:
//! `GROUP.INDEX` (`main.3`), a repeat's inner step (`main.4.2`), and the
//! two steps a `rate` step becomes: its turn up to the rate
//! (`main.5.turn`) and the record taken while the table turns
//! (`main.5.record`). The suffixes are known here alone; every other
//! module asks a key what it names.

/// The part of a procedure's step a key names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum KeyPart {
    /// The step itself.
    Step,
    /// A `rate` step's turn up to its rate.
    Turn,
    /// The record a `rate` step takes while the table turns.
    RateRecord,
}

impl KeyPart {
    /// What the part adds to its step's key.
    const fn suffix(self) -> &'static str {
        match self {
            Self::Step => "",
            Self::Turn => ".turn",
            Self::RateRecord => ".record",
        }
    }
}

/// A step key, read: the step's own key and the part of it named.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepKey<'a> {
    step: &'a str,
    part: KeyPart,
}

impl<'a> StepKey<'a> {
    /// Read `key` (any text: a key of no known part names a step).
    pub fn parse(key: &'a str) -> Self {
        [KeyPart::Turn, KeyPart::RateRecord]
            .into_iter()
            .find_map(|part| {
                key.strip_suffix(part.suffix())
                    .map(|step| Self { step, part })
            })
            .unwrap_or(Self {
                step: key,
                part: KeyPart::Step,
            })
    }

    /// The key of `part` of the step keyed `step`.
    pub fn of(step: &'a str, part: KeyPart) -> Self {
        Self { step, part }
    }

    /// The step's own key (`main.5` of `main.5.record`).
    pub fn step(self) -> &'a str {
        self.step
    }

    /// The part of the step it names.
    pub fn part(self) -> KeyPart {
        self.part
    }

    /// Whether it keys the record of a `rate` step, taken while the table
    /// turns.
    pub fn is_rate_record(self) -> bool {
        self.part == KeyPart::RateRecord
    }
}

impl std::fmt::Display for StepKey<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}{}", self.step, self.part.suffix())
    }
}

/// A step key held (what a recorded sample carries), read once: the
/// owned form of [`StepKey`], as `PathBuf` is of `Path`.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct StepKeyBuf {
    step: String,
    part: KeyPart,
}

impl StepKeyBuf {
    /// Read `key` as [`StepKey::parse`] does.
    pub fn parse(key: &str) -> Self {
        StepKey::parse(key).into()
    }

    /// The key, borrowed.
    pub fn as_key(&self) -> StepKey<'_> {
        StepKey::of(&self.step, self.part)
    }
}

impl From<StepKey<'_>> for StepKeyBuf {
    fn from(k: StepKey<'_>) -> Self {
        Self {
            step: k.step.to_owned(),
            part: k.part,
        }
    }
}

impl From<&str> for StepKeyBuf {
    fn from(key: &str) -> Self {
        Self::parse(key)
    }
}

impl From<String> for StepKeyBuf {
    fn from(key: String) -> Self {
        Self::parse(&key)
    }
}

impl std::fmt::Display for StepKeyBuf {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.as_key().fmt(f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_key_says_which_part_of_which_step_it_names_and_writes_back_as_read() {
        for (key, step, part) in [
            ("main.3", "main.3", KeyPart::Step),
            ("main.4.2", "main.4.2", KeyPart::Step),
            ("main.5.turn", "main.5", KeyPart::Turn),
            ("main.5.record", "main.5", KeyPart::RateRecord),
            ("setup.0.record", "setup.0", KeyPart::RateRecord),
            ("", "", KeyPart::Step),
        ] {
            let k = StepKey::parse(key);
            assert_eq!((k.step(), k.part()), (step, part), "{key}");
            assert_eq!(k.to_string(), key);
            assert_eq!(StepKey::of(step, part), k);
        }
        assert!(StepKey::parse("main.5.record").is_rate_record());
        let held = StepKeyBuf::parse("main.5.record");
        assert_eq!(held.as_key(), StepKey::of("main.5", KeyPart::RateRecord));
        assert_eq!(held.to_string(), "main.5.record");
        assert_eq!(StepKeyBuf::from("main.4.2").as_key().part(), KeyPart::Step);
        assert!(!StepKey::parse("main.5.recording").is_rate_record());
        assert!(!StepKey::parse("main.5.turn").is_rate_record());
    }
}
