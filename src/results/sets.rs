//! Coefficient sets against the store: what the store knows of a set a run
//! is about to use (`run --coeffs`), and how a run's stored coefficients
//! read back. A set's text names its unit and version, but anyone can edit
//! a text; the store holds what `calibrate` recorded (each set's text and
//! its SHA-256) and the runs it was fitted on, so it can say whether a text
//! is a stored set, an edited copy of one, or none it knows.

use serde::Serialize;

use super::sql::Row;
use super::{Store, StoreError};
use crate::coeffs::identity::{FittedRun, claim_text};
use crate::coeffs::{CoefficientSet, SetIdentity, SetStatus, StoredSet, UnitSection};

/// A stored set with the text the store holds.
struct StoredText {
    set: StoredSet,
    text: String,
}

fn stored_text(r: &Row) -> StoredText {
    StoredText {
        set: StoredSet {
            serial: r.text("serial"),
            dut_type: r.text("dut_type"),
            version: r.int("version").unwrap_or(0),
            sha256: r.opt_text("sha256"),
        },
        text: r.text("coeffs_toml"),
    }
}

const SET_COLUMNS: &str = "c.version, c.sha256, c.coeffs_toml, u.dut_type, u.serial \
                           FROM coefficient_sets c JOIN units u ON u.id = c.unit_id";

/// The provenance two sets share when one is a copy of the other: when and
/// by what they were fitted, and on which runs (their logs' SHA-256).
fn same_provenance(a: &CoefficientSet, b: &CoefficientSet) -> bool {
    let (Some(a), Some(b)) = (&a.set, &b.set) else {
        return false;
    };
    let runs = |s: &crate::coeffs::SetSection| {
        let mut r: Vec<(String, String)> = s
            .fitted_on
            .iter()
            .map(|f| (f.run_id.clone(), f.log_sha256.clone()))
            .collect();
        r.sort();
        r
    };
    !a.fitted_on.is_empty()
        && a.created_utc == b.created_utc
        && a.software == b.software
        && runs(a) == runs(b)
}

impl Store {
    /// What the store knows of the set `set` whose text hashes to `sha256`:
    /// the stored set it is, or an edited copy of, or none; and the units
    /// of the runs it names as fitted on. Fails only when the store cannot
    /// be read.
    pub fn identify_set(
        &mut self,
        set: &CoefficientSet,
        sha256: &str,
    ) -> Result<SetIdentity, StoreError> {
        let claimed_version = set.set.as_ref().and_then(|s| s.version);
        let claim = claim_text(set.unit.as_ref(), claimed_version);
        let fitted_on_runs = self.fitted_on_runs(set)?;
        let store = self.name.clone();
        let short = |h: &str| h.get(..12).unwrap_or(h).to_owned();
        let (status, stored, mut note) = if let Some(s) = self.set_with_text(sha256)? {
            let note = format!(
                "the results store {store} holds this text, byte for byte, as {}",
                s.describe()
            );
            (SetStatus::Registered, Some(s), note)
        } else if let Some(s) = self.set_of_same_provenance(set)? {
            let note = format!(
                "not a text the results store {store} holds: {} was fitted at the same time on the same runs, and this text (sha256 {}) is an edited copy of it (sha256 {})",
                s.describe(),
                short(sha256),
                s.sha256.as_deref().map_or("-".into(), short)
            );
            (SetStatus::Edited, Some(s), note)
        } else if let Some(s) = self.set_claimed(set)? {
            let note = format!(
                "not a text the results store {store} holds: its {} has sha256 {}, this text {}: it was edited",
                s.describe(),
                s.sha256.as_deref().map_or("-".into(), short),
                short(sha256)
            );
            (SetStatus::Edited, Some(s), note)
        } else {
            let note = match claimed_version {
                Some(_) => format!("the results store {store} holds no {claim}"),
                None => format!(
                    "the results store {store} holds no such set: its text names no version (calibrate records a set in the store it can reach)"
                ),
            };
            (SetStatus::Unregistered, None, note)
        };
        let named = set.set.as_ref().map_or(0, |s| s.fitted_on.len());
        if named > 0 {
            note.push_str(&format!(
                "; {} of the {named} run(s) it was fitted on {} in the store",
                fitted_on_runs.len(),
                if fitted_on_runs.len() == 1 {
                    "is"
                } else {
                    "are"
                }
            ));
        }
        Ok(SetIdentity {
            status,
            claimed_unit: set.unit.clone(),
            claimed_version,
            stored,
            fitted_on_runs,
            store: Some(store),
            note,
        })
    }

    /// The stored set whose text hashes to `sha256` (a set stored before
    /// the store kept its SHA-256 is hashed here).
    fn set_with_text(&mut self, sha256: &str) -> Result<Option<StoredSet>, StoreError> {
        let rows = self.sql().query(
            &format!(
                "SELECT {SET_COLUMNS} WHERE c.sha256 = $1 OR c.sha256 IS NULL ORDER BY c.version"
            ),
            &[sha256.into()],
        )?;
        // The text itself must be this one: a row whose text no longer
        // hashes to its SHA-256 is not what calibrate stored.
        Ok(rows
            .iter()
            .map(stored_text)
            .find(|s| super::record::sha256_text(&s.text) == sha256)
            .map(|s| StoredSet {
                sha256: Some(sha256.to_owned()),
                ..s.set
            }))
    }

    /// The stored set `set` is a copy of: fitted at the same time, by the
    /// same gyrobench, on the same runs.
    fn set_of_same_provenance(
        &mut self,
        set: &CoefficientSet,
    ) -> Result<Option<StoredSet>, StoreError> {
        let Some(first) = set.set.as_ref().and_then(|s| s.fitted_on.first()) else {
            return Ok(None);
        };
        // Candidates by their first run's log SHA-256 in the JSON the store
        // keeps (hex, so nothing in it is a LIKE pattern); each one's text
        // then compared whole.
        if first.log_sha256.is_empty() || !first.log_sha256.chars().all(|c| c.is_ascii_hexdigit()) {
            return Ok(None);
        }
        let rows = self.sql().query(
            &format!("SELECT {SET_COLUMNS} WHERE c.fitted_on LIKE $1 ORDER BY c.version"),
            &[format!("%{}%", first.log_sha256).into()],
        )?;
        Ok(rows.iter().map(stored_text).find_map(|s| {
            let src = crate::config::Source::from_text("stored set", &s.text);
            let theirs = CoefficientSet::from_source(&src).ok()?;
            same_provenance(set, &theirs).then_some(s.set)
        }))
    }

    /// The stored set `set` claims to be: its unit's set of its version.
    fn set_claimed(&mut self, set: &CoefficientSet) -> Result<Option<StoredSet>, StoreError> {
        let (Some(u), Some(v)) = (&set.unit, set.set.as_ref().and_then(|s| s.version)) else {
            return Ok(None);
        };
        Ok(self
            .sql()
            .query(
                &format!(
                    "SELECT {SET_COLUMNS} WHERE u.dut_type = $1 AND u.serial = $2 AND c.version = $3"
                ),
                &[u.dut_type.clone().into(), u.serial.clone().into(), v.into()],
            )?
            .first()
            .map(|r| stored_text(r).set))
    }

    /// The runs `set` names as fitted on that the store holds, each with
    /// the units the store has for it.
    fn fitted_on_runs(&mut self, set: &CoefficientSet) -> Result<Vec<FittedRun>, StoreError> {
        let mut ids: Vec<String> = set
            .set
            .iter()
            .flat_map(|s| &s.fitted_on)
            .map(|f| f.run_id.clone())
            .filter(|id| !id.is_empty())
            .collect();
        ids.sort();
        ids.dedup();
        if ids.is_empty() {
            return Ok(Vec::new());
        }
        let marks: Vec<String> = (1..=ids.len()).map(|i| format!("${i}")).collect();
        let rows = self.sql().query(
            &format!(
                "SELECT DISTINCT r.run_id, u.dut_type, u.serial FROM runs r \
                 JOIN run_units ru ON ru.run = r.id JOIN units u ON u.id = ru.unit_id \
                 WHERE r.run_id IN ({}) ORDER BY r.run_id, u.dut_type, u.serial",
                marks.join(", ")
            ),
            &ids.iter().map(|i| i.clone().into()).collect::<Vec<_>>(),
        )?;
        let mut runs: Vec<FittedRun> = Vec::new();
        for r in &rows {
            let unit = UnitSection {
                serial: r.text("serial"),
                dut_type: r.text("dut_type"),
            };
            let id = r.text("run_id");
            match runs.last_mut() {
                Some(last) if last.run_id == id => last.units.push(unit),
                _ => runs.push(FittedRun {
                    run_id: id,
                    units: vec![unit],
                }),
            }
        }
        Ok(runs)
    }
}

/// The coefficients a run's unit used, as the store keeps them.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct StoredCoeffs {
    /// `fitted`, `file` or `store` (none for runs stored before schema 3).
    pub source: Option<String>,
    /// The set's unit.
    pub serial: Option<String>,
    /// The set's version (only for a set the store held byte for byte).
    pub version: Option<i64>,
    /// SHA-256 of the set's text.
    pub sha256: Option<String>,
    /// Why another unit's set was used.
    pub override_reason: Option<String>,
    /// How the set's identity checked out when the run chose it:
    /// `registered`, `edited`, `unregistered` or `unchecked` (none: fitted,
    /// or a run stored before schema 4).
    pub identity: Option<String>,
    /// The version the set's text claimed.
    pub claimed_version: Option<i64>,
    /// What was verified, or why it could not be, in words.
    pub identity_note: Option<String>,
}

impl StoredCoeffs {
    /// Read from a row that selects `run_units`' `coeffs_*` columns under
    /// their own names.
    pub fn of_row(r: &Row) -> Self {
        Self {
            source: r.opt_text("coeffs_source"),
            serial: r.opt_text("coeffs_serial"),
            version: r.int("coeffs_version"),
            sha256: r.opt_text("coeffs_sha256"),
            override_reason: r.opt_text("coeffs_override_reason"),
            identity: r.opt_text("coeffs_identity"),
            claimed_version: r.int("coeffs_claimed_version"),
            identity_note: r.opt_text("coeffs_identity_note"),
        }
    }

    /// In words.
    pub fn describe(&self) -> String {
        let claimed = self
            .claimed_version
            .map_or(String::new(), |v| format!(" (its text claims set {v})"));
        let of = |s: &str| format!(" of {s}");
        let unit = self.serial.as_deref().map_or(" naming no unit".into(), of);
        let set = match (
            self.identity.as_deref().and_then(SetStatus::parse),
            self.version,
        ) {
            (Some(SetStatus::Edited), _) => format!("an EDITED set{unit}{claimed}"),
            (Some(SetStatus::Unregistered), _) => {
                format!("a set{unit} the results store did not hold{claimed}")
            }
            (Some(SetStatus::Unchecked), _) => {
                format!("a set{unit}{claimed}, not checked against a results store")
            }
            (_, Some(v)) => format!("set {v}{unit}"),
            (_, None) if self.serial.is_some() => format!("a set{unit} not in a store"),
            _ => "a set naming no unit".into(),
        };
        let sha = self.sha256.as_deref().map_or(String::new(), |h| {
            format!(" (sha256 {})", h.get(..12).unwrap_or(h))
        });
        let why = self
            .override_reason
            .as_deref()
            .map_or(String::new(), |r| format!(", used for another unit: {r}"));
        match self.source.as_deref() {
            None => "not recorded".into(),
            Some("fitted") => "fitted on the run's records".into(),
            Some(_) => format!("{set}{sha}{why}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::record::SetRecord;
    use super::super::{Location, Store};
    use super::*;
    use crate::coeffs::{FittedOn, SetSection};

    fn unit(serial: &str) -> UnitSection {
        UnitSection {
            serial: serial.into(),
            dut_type: "RL-16".into(),
        }
    }

    /// A set of `serial` fitted on one run, as calibrate makes it.
    fn fitted(serial: &str) -> CoefficientSet {
        CoefficientSet {
            unit: Some(unit(serial)),
            set: Some(SetSection {
                version: None,
                created_utc: "2026-12-03T10:00:00.123456789+00:00".into(),
                software: "gyrobench 0.1.0 (1a2b3c4d5e6f)".into(),
                models: vec!["model4".into()],
                fitted_on: vec![FittedOn {
                    run_id: "f838391d6a51ae6180148834f2f9c761".into(),
                    log_sha256: "43".repeat(32),
                    log: "runs/c1/run.mcap".into(),
                }],
            }),
            model4: Some(crate::compensation::Model4 {
                k1_dph_per_c: -0.12,
                k2_dph_per_c2: -0.01,
                k3_dph_per_c_per_s: 20.0,
                k4_dph_per_c: -0.007,
                k5_dph: 0.36,
                warmup_tau_s: 600.0,
                offset_dph: 0.0,
            }),
            ..CoefficientSet::default()
        }
    }

    fn identify(store: &mut Store, text: &str) -> SetIdentity {
        let set = CoefficientSet::from_source(&crate::config::Source::from_text("t", text))
            .expect("a set");
        store
            .identify_set(&set, &crate::fsutil::sha256_text(text))
            .expect("the store answers")
    }

    #[test]
    fn the_store_tells_its_set_from_an_edited_copy_and_from_one_it_never_held() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut store = Store::open(&Location::Sqlite(dir.path().join("s.sqlite")))
            .expect("opens")
            .expect("a store");
        let mut set = fitted("RL16-0042");
        let rec = SetRecord {
            validation: "test",
            held_out_drift_pp_dph: None,
            sources: Vec::new(),
        };
        let text = store.record_coefficients(&mut set, &rec).expect("recorded");
        let id = identify(&mut store, &text);
        assert_eq!(id.status, SetStatus::Registered, "{}", id.note);
        assert_eq!(id.stored.as_ref().map(|s| s.version), Some(1));

        // A coefficient edited: the same provenance, another text.
        let id = identify(&mut store, &text.replace("k5_dph = 0.36", "k5_dph = 0.5"));
        assert_eq!(id.status, SetStatus::Edited, "{}", id.note);
        assert!(id.note.contains("edited copy of it"), "{}", id.note);
        // The serial edited: an edited copy of RL16-0042's set, which the
        // unit it names is not.
        let id = identify(&mut store, &text.replace("RL16-0042", "RL16-0099"));
        assert_eq!(id.status, SetStatus::Edited);
        assert!(
            id.disagreement()
                .is_some_and(|d| d.contains("holds it as set 1 of RL-16 RL16-0042")),
            "{id:?}"
        );
        // Its provenance edited too, claiming the stored set's number:
        // still not that set.
        let renamed = text.replace("2026-12-03T10:00:00.123", "2026-12-04T10:00:00.123");
        let id = identify(
            &mut store,
            &renamed.replace("k5_dph = 0.36", "k5_dph = 0.5"),
        );
        assert_eq!(id.status, SetStatus::Edited);
        assert!(id.note.contains("it was edited"), "{}", id.note);
        // A set number the unit does not have, of no stored provenance.
        let id = identify(&mut store, &renamed.replace("version = 1", "version = 999"));
        assert_eq!(id.status, SetStatus::Unregistered, "{}", id.note);
        assert!(
            id.note.contains("holds no set 999 of RL-16 RL16-0042"),
            "{}",
            id.note
        );
        // The runs it names are not in the store: nothing contradicts it.
        assert!(id.fitted_on_runs.is_empty() && id.disagreement().is_none());
    }

    #[test]
    fn a_stored_runs_coefficients_say_how_their_set_checked_out() {
        let mut c = StoredCoeffs {
            source: Some("file".into()),
            serial: Some("RL16-0042".into()),
            version: Some(1),
            sha256: Some("c0dff1852246aa".into()),
            identity: Some("registered".into()),
            ..StoredCoeffs::default()
        };
        assert_eq!(c.describe(), "set 1 of RL16-0042 (sha256 c0dff1852246)");
        c.version = None;
        c.identity = Some("edited".into());
        c.claimed_version = Some(1);
        assert_eq!(
            c.describe(),
            "an EDITED set of RL16-0042 (its text claims set 1) (sha256 c0dff1852246)"
        );
        c.identity = Some("unchecked".into());
        assert!(c.describe().contains("not checked against a results store"));
        assert_eq!(StoredCoeffs::default().describe(), "not recorded");
    }
}
