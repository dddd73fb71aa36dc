//! A coefficient set's identity as checked when a run chose it: whether the
//! results store holds its text (registered), holds the set it is an edited
//! copy of (edited), holds nothing it claims to be (unregistered), or could
//! not be asked (unchecked). A set's `[unit]` and `[set] version` are plain
//! text anyone can edit; what the store holds is what `calibrate` recorded.
//! The check itself is the store's (`results::sets`); this is what the
//! run's log, report and store record of it.

use serde::{Deserialize, Serialize};

use super::{CoefficientSet, UnitSection};

/// What the check found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SetStatus {
    /// The store holds this text, byte for byte (by its SHA-256), as a
    /// set `calibrate` recorded.
    Registered,
    /// Not a text the store holds, but a changed copy of a stored set: it
    /// has that set's provenance (fitted at the same time on the same
    /// runs), or it claims that set's unit and version.
    Edited,
    /// The store holds no set this text claims to be (it names no version,
    /// or one its unit does not have).
    Unregistered,
    /// No store could be asked (`--db none`, or one that cannot be reached).
    Unchecked,
}

impl SetStatus {
    /// Every status.
    pub const ALL: [Self; 4] = [
        Self::Registered,
        Self::Edited,
        Self::Unregistered,
        Self::Unchecked,
    ];

    /// The word the log, the report and the store hold.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Registered => "registered",
            Self::Edited => "edited",
            Self::Unregistered => "unregistered",
            Self::Unchecked => "unchecked",
        }
    }

    /// The status a word names.
    pub fn parse(word: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.as_str() == word)
    }
}

/// A set as the store holds it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StoredSet {
    /// Its unit's serial.
    pub serial: String,
    /// Its unit's type.
    #[serde(rename = "type")]
    pub dut_type: String,
    /// Its number among the unit's sets.
    pub version: i64,
    /// SHA-256 of the text the store holds (none for sets stored before
    /// the store kept it).
    pub sha256: Option<String>,
}

impl StoredSet {
    /// `set 2 of RL-16 RL16-0042`.
    pub fn describe(&self) -> String {
        format!("set {} of {} {}", self.version, self.dut_type, self.serial)
    }

    fn unit(&self) -> UnitSection {
        UnitSection {
            serial: self.serial.clone(),
            dut_type: self.dut_type.clone(),
        }
    }
}

/// A run a set names in `[[set.fitted_on]]` that the store holds, with
/// the units the store has for it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FittedRun {
    /// The run's id.
    pub run_id: String,
    /// Its units (a batch's: several).
    pub units: Vec<UnitSection>,
}

/// A set's identity, as checked when a run chose it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetIdentity {
    /// What the check found.
    pub status: SetStatus,
    /// The unit its text names (`[unit]`; none: it names none).
    #[serde(default)]
    pub claimed_unit: Option<UnitSection>,
    /// The version its text claims (`[set] version`; none: none).
    #[serde(default)]
    pub claimed_version: Option<i64>,
    /// The stored set it is (registered) or is an edited copy of (edited).
    #[serde(default)]
    pub stored: Option<StoredSet>,
    /// The runs it names as fitted on that the store holds, each with its
    /// units there.
    #[serde(default)]
    pub fitted_on_runs: Vec<FittedRun>,
    /// The store it was checked against (none: none could be asked).
    #[serde(default)]
    pub store: Option<String>,
    /// What was verified, or why it could not be, in words.
    pub note: String,
}

/// A set's claim in words: `set 2 of RL-16 RL16-0042`, `a set of RL-16
/// RL16-0042` (no version), `a set naming no unit`.
pub fn claim_text(unit: Option<&UnitSection>, version: Option<i64>) -> String {
    let set = version.map_or_else(|| "a set".to_owned(), |v| format!("set {v}"));
    match unit {
        Some(u) => format!("{set} of {} {}", u.dut_type, u.serial),
        None => format!("{set} naming no unit"),
    }
}

fn unit_text(u: &UnitSection) -> String {
    format!("{} {}", u.dut_type, u.serial)
}

impl SetIdentity {
    /// A set no store could be asked about: `store` (none: no store given)
    /// and why, in words.
    pub fn unchecked(set: &CoefficientSet, store: Option<&str>, why: &str) -> Self {
        Self {
            status: SetStatus::Unchecked,
            claimed_unit: set.unit.clone(),
            claimed_version: set.set.as_ref().and_then(|s| s.version),
            stored: None,
            fitted_on_runs: Vec::new(),
            store: store.map(str::to_owned),
            note: format!("its identity (unit, version, provenance) could not be checked: {why}"),
        }
    }

    /// What the text claims, in words.
    pub fn claim(&self) -> String {
        claim_text(self.claimed_unit.as_ref(), self.claimed_version)
    }

    /// Why the unit the set names is not its own, when the store knows
    /// otherwise: it holds the set as another unit's, or the runs it was
    /// fitted on are another unit's. None when nothing contradicts it (or
    /// it names no unit: that is refused on its own).
    pub fn disagreement(&self) -> Option<String> {
        let claimed = self.claimed_unit.as_ref()?;
        let store = self.store.as_deref().unwrap_or("the results store");
        if let Some(s) = &self.stored
            && s.unit() != *claimed
        {
            let how = match self.status {
                SetStatus::Edited => ", of which this is an edited copy",
                _ => "",
            };
            return Some(format!(
                "the results store {store} holds it as {}{how}",
                s.describe()
            ));
        }
        let others: Vec<&FittedRun> = self
            .fitted_on_runs
            .iter()
            .filter(|r| !r.units.contains(claimed))
            .collect();
        if others.is_empty() {
            return None;
        }
        let mut units: Vec<String> = others
            .iter()
            .flat_map(|r| r.units.iter().map(unit_text))
            .collect();
        units.sort();
        units.dedup();
        Some(format!(
            "{} of the runs it was fitted on ({}) {} of {} in the results store {store}",
            others.len(),
            others
                .iter()
                .map(|r| r.run_id.get(..12).unwrap_or(&r.run_id))
                .collect::<Vec<_>>()
                .join(", "),
            if others.len() == 1 {
                "is a run"
            } else {
                "are runs"
            },
            units.join(" and ")
        ))
    }

    /// The head of how a run names the set it used: which set it is, as
    /// far as the check could tell.
    pub fn head(&self) -> String {
        match (self.status, &self.stored) {
            (SetStatus::Registered, Some(s)) => s.describe(),
            (SetStatus::Edited, Some(s)) => {
                let claim = self.claim();
                if claim == s.describe() {
                    format!("an edited copy of {}", s.describe())
                } else {
                    format!(
                        "an edited copy of {} (its text claims {claim})",
                        s.describe()
                    )
                }
            }
            (SetStatus::Unregistered, _) => match self.claimed_version {
                Some(_) => format!(
                    "a set the results store does not hold (its text claims {})",
                    self.claim()
                ),
                // The words runs have always used for a set without a
                // version.
                None => claim_text(self.claimed_unit.as_ref(), None).replacen(
                    "a set",
                    "a set not in a store",
                    1,
                ),
            },
            _ => format!("{} as its text claims", self.claim()),
        }
    }

    /// How the run's record qualifies the set: checked or not.
    pub fn tail(&self) -> &'static str {
        match self.status {
            SetStatus::Registered => ", as the results store holds it",
            SetStatus::Edited => ", not the text the results store holds",
            SetStatus::Unregistered => "",
            SetStatus::Unchecked => ", not checked against a results store",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(serial: &str) -> UnitSection {
        UnitSection {
            serial: serial.into(),
            dut_type: "RL-16".into(),
        }
    }

    fn stored(serial: &str, version: i64) -> StoredSet {
        StoredSet {
            serial: serial.into(),
            dut_type: "RL-16".into(),
            version,
            sha256: Some("ab".repeat(32)),
        }
    }

    fn identity(status: SetStatus, claimed: &str, version: Option<i64>) -> SetIdentity {
        SetIdentity {
            status,
            claimed_unit: Some(unit(claimed)),
            claimed_version: version,
            stored: None,
            fitted_on_runs: Vec::new(),
            store: Some("results.sqlite".into()),
            note: String::new(),
        }
    }

    #[test]
    fn a_set_the_store_knows_as_another_units_disagrees_with_its_claim() {
        let mut id = identity(SetStatus::Edited, "RL16-0099", Some(1));
        assert_eq!(
            id.disagreement(),
            None,
            "nothing known: nothing contradicts"
        );
        id.stored = Some(stored("RL16-0042", 1));
        let why = id
            .disagreement()
            .expect("the store knows it as RL16-0042's");
        assert!(
            why.contains("holds it as set 1 of RL-16 RL16-0042, of which this is an edited copy"),
            "{why}"
        );
        assert_eq!(
            id.head(),
            "an edited copy of set 1 of RL-16 RL16-0042 (its text claims set 1 of RL-16 RL16-0099)"
        );
    }

    #[test]
    fn runs_of_another_unit_disagree_and_a_batchs_runs_hold_each_of_its_units() {
        let mut id = identity(SetStatus::Unregistered, "RL16-0099", Some(1));
        id.fitted_on_runs = vec![FittedRun {
            run_id: "f838391d6a51ae6180148834f2f9c761".into(),
            units: vec![unit("RL16-0042")],
        }];
        let why = id.disagreement().expect("the runs are RL16-0042's");
        assert!(
            why.contains(
                "1 of the runs it was fitted on (f838391d6a51) is a run of RL-16 RL16-0042"
            ),
            "{why}"
        );
        id.fitted_on_runs[0].units.push(unit("RL16-0099"));
        assert_eq!(id.disagreement(), None, "a batch's run holds both units");
    }

    #[test]
    fn every_status_is_named_plainly_never_as_the_set_it_claims() {
        let mut id = identity(SetStatus::Unregistered, "RL16-0042", Some(999));
        assert_eq!(
            id.head(),
            "a set the results store does not hold (its text claims set 999 of RL-16 RL16-0042)"
        );
        id.claimed_version = None;
        assert_eq!(id.head(), "a set not in a store of RL-16 RL16-0042");
        let mut id = identity(SetStatus::Edited, "RL16-0042", Some(1));
        id.stored = Some(stored("RL16-0042", 1));
        assert_eq!(id.head(), "an edited copy of set 1 of RL-16 RL16-0042");
        let id = identity(SetStatus::Unchecked, "RL16-0042", Some(2));
        assert_eq!(id.head(), "set 2 of RL-16 RL16-0042 as its text claims");
        for s in SetStatus::ALL {
            assert_eq!(SetStatus::parse(s.as_str()), Some(s));
        }
    }
}
