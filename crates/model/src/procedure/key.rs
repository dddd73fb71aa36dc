//! A step's key as the log, the report and the diagnosis name it:
//! `GROUP.INDEX` (`main.3`), a repeat's inner step (`main.4.2`), and the
//! two steps a `rate` step becomes: its turn up to the rate
//! (`main.5.turn`) and the record taken while the table turns
//! (`main.5.record`). The suffixes are known here alone; every other
//! module asks a key what it names.

/// The part of a procedure's step a key names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
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
        assert!(!StepKey::parse("main.5.recording").is_rate_record());
        assert!(!StepKey::parse("main.5.turn").is_rate_record());
    }
}
