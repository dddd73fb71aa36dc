//! Review and sign-off of a stored run (ISO/IEC 17025 7.8.1: results
//! reviewed and authorised before release). A signature names the run
//! part, the role (`reviewed`, then `approved` by another person), who
//! signed and when, and binds what was signed: the SHA-256 of the run's
//! log as the store holds it and a digest of its stored verdict and
//! figures. `results verify` names a signed run whose log or figures are
//! no longer what was signed (`docs/results.md`, "Signing").

use super::query::measurement_of;
use super::sql::Value;
use super::{RunState, Store, StoreError};

/// What a signature says of the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Reviewed: the record checked against the procedure and the data.
    Reviewed,
    /// Approved: released, by someone other than the reviewer.
    Approved,
}

impl Role {
    /// `reviewed` or `approved`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Reviewed => "reviewed",
            Self::Approved => "approved",
        }
    }
}

/// One signature as the store keeps it (the report's type: a replay
/// shows them).
pub use crate::report::Signature;

/// The longest name or note a signature keeps.
const MAX_TEXT: usize = 200;

impl Store {
    /// The digest of part `key`'s stored outcome and every figure (each
    /// value to the bit, its limits, statement, uncertainty and note), in
    /// order: what a signature binds.
    pub fn figures_digest(&mut self, key: &str) -> Result<String, StoreError> {
        let mut text = String::new();
        for r in self.sql().query(
            "SELECT r.outcome AS run_outcome, r.log_sha256 FROM runs r WHERE r.id = $1",
            &[key.into()],
        )? {
            text.push_str(&format!("outcome {}\n", r.text("run_outcome")));
        }
        let rows = self.sql().query(
            "SELECT m.slot, m.name, m.value, m.unit, m.low, m.high, m.outcome, m.step, m.note, \
             m.u, m.expanded_u, m.k, m.guard_band FROM measurements m WHERE m.run = $1 ORDER BY m.seq",
            &[key.into()],
        )?;
        let bits = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{:016x}", v.to_bits()));
        for r in &rows {
            let m = measurement_of(r);
            let u = m.uncertainty;
            text.push_str(&format!(
                "{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}\n",
                r.text("slot"),
                m.name,
                bits(m.value),
                m.unit,
                bits(m.low),
                bits(m.high),
                m.outcome.as_str(),
                m.step,
                m.note,
                bits(u.map(|u| u.u)),
                bits(u.map(|u| u.expanded)),
                bits(u.map(|u| u.k)),
                bits(m.guard_band),
            ));
        }
        Ok(crate::fsutil::sha256_text(&text))
    }

    /// Sign run `id` (its key or the start of one; its latest part) as
    /// `role` by `by`. Refused: a run still running or kept only for
    /// reference, an approval without a review, an approval by the
    /// reviewer, the same role signed twice by one person.
    pub fn sign(
        &mut self,
        id: &str,
        role: Role,
        by: &str,
        note: &str,
    ) -> Result<Signature, StoreError> {
        let refuse = |why: String| StoreError::Refused { why };
        let by = by.trim();
        if by.is_empty() || by.chars().count() > MAX_TEXT || by.chars().any(char::is_control) {
            return Err(refuse(format!(
                "--by {by:?}: a name of 1 to {MAX_TEXT} printable characters"
            )));
        }
        if note.chars().count() > MAX_TEXT || note.chars().any(|c| c.is_control() && c != '\n') {
            return Err(refuse(format!(
                "--note: at most {MAX_TEXT} printable characters"
            )));
        }
        let run = self.part_named(id)?;
        match run.outcome {
            RunState::Running => {
                return Err(refuse(format!(
                    "{}: the run has not ended (or was killed: `results sync` completes it from its log)",
                    run.id
                )));
            }
            RunState::Reference => {
                return Err(refuse(format!(
                    "{}: an imported run is kept for reference, never judged: nothing to sign",
                    run.id
                )));
            }
            _ => {}
        }
        let existing = self.signatures(&run.id)?;
        if existing
            .iter()
            .any(|s| s.role == role.as_str() && s.by == by)
        {
            return Err(refuse(format!(
                "{}: already signed as {} by {by}",
                run.id,
                role.as_str()
            )));
        }
        if role == Role::Approved {
            let reviewers: Vec<&str> = existing
                .iter()
                .filter(|s| s.role == Role::Reviewed.as_str())
                .map(|s| s.by.as_str())
                .collect();
            if reviewers.is_empty() {
                return Err(refuse(format!(
                    "{}: not reviewed yet; `results sign {} --role reviewed --by NAME` comes first",
                    run.id, run.id
                )));
            }
            if reviewers.iter().all(|r| *r == by) {
                return Err(refuse(format!(
                    "{}: {by} reviewed it; another person approves it",
                    run.id
                )));
            }
        }
        let log_sha = self
            .sql()
            .query(
                "SELECT log_sha256 FROM runs WHERE id = $1",
                &[run.id.clone().into()],
            )?
            .first()
            .map(|r| r.text("log_sha256"))
            .unwrap_or_default();
        let s = Signature {
            run: run.id.clone(),
            role: role.as_str().to_owned(),
            by: by.to_owned(),
            signed_utc: chrono::Utc::now().to_rfc3339_opts(chrono::SecondsFormat::Secs, true),
            log_sha256: log_sha,
            figures_sha256: self.figures_digest(&run.id)?,
            note: note.to_owned(),
        };
        self.sql().execute(
            "INSERT INTO signatures (run, role, by_name, signed_utc, log_sha256, figures_sha256, note) \
             VALUES ($1, $2, $3, $4, $5, $6, $7)",
            &[
                s.run.clone().into(),
                s.role.clone().into(),
                s.by.clone().into(),
                s.signed_utc.clone().into(),
                s.log_sha256.clone().into(),
                s.figures_sha256.clone().into(),
                s.note.clone().into(),
            ],
        )?;
        Ok(s)
    }

    /// The signatures of part `key`, oldest first.
    pub fn signatures(&mut self, key: &str) -> Result<Vec<Signature>, StoreError> {
        Ok(self
            .sql()
            .query(
                "SELECT run, role, by_name, signed_utc, log_sha256, figures_sha256, note \
                 FROM signatures WHERE run = $1 \
                 ORDER BY signed_utc, CASE role WHEN 'reviewed' THEN 0 ELSE 1 END, by_name",
                &[Value::from(key)],
            )?
            .iter()
            .map(|r| Signature {
                run: r.text("run"),
                role: r.text("role"),
                by: r.text("by_name"),
                signed_utc: r.text("signed_utc"),
                log_sha256: r.text("log_sha256"),
                figures_sha256: r.text("figures_sha256"),
                note: r.text("note"),
            })
            .collect())
    }

    /// What no longer holds of each signature of part `key`: the log's
    /// SHA-256 or the stored figures changed since it was signed.
    pub fn broken_signatures(&mut self, key: &str) -> Result<Vec<String>, StoreError> {
        let signed = self.signatures(key)?;
        if signed.is_empty() {
            return Ok(Vec::new());
        }
        let log_now = self
            .sql()
            .query("SELECT log_sha256 FROM runs WHERE id = $1", &[key.into()])?
            .first()
            .map(|r| r.text("log_sha256"))
            .unwrap_or_default();
        let figures_now = self.figures_digest(key)?;
        let mut out = Vec::new();
        for s in signed {
            let mut what = Vec::new();
            if s.log_sha256 != log_now {
                what.push(format!(
                    "its log (sha256 {} when signed, {} now)",
                    short(&s.log_sha256),
                    short(&log_now)
                ));
            }
            if s.figures_sha256 != figures_now {
                what.push("its stored verdict or figures".to_owned());
            }
            if !what.is_empty() {
                out.push(format!(
                    "signed as {} by {} on {}, {} changed since",
                    s.role,
                    s.by,
                    s.signed_utc,
                    what.join(" and ")
                ));
            }
        }
        Ok(out)
    }
}

fn short(sha: &str) -> &str {
    sha.get(..12).unwrap_or(sha)
}
