//! Signing a stored run from the station: the page's form posts a
//! signature here and the results store's own rules decide
//! (`results::sign`, the same code as `gyrobench results sign`), with the
//! same words for a refusal.

use serde::Deserialize;

use super::{Refused, Station};
use gyrobench::results::StoreError;
use gyrobench::results::sign::{Role, Signature};

/// A signature the page asks for. A field left out is empty, and refused
/// with the reason the store gives for it.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default)]
pub struct SignRequest {
    /// The run part (a history row's `id`, or the start of one).
    pub run: String,
    /// `reviewed` or `approved`.
    pub role: String,
    /// Who signs.
    pub by: String,
    /// A remark kept with the signature (may be empty).
    pub note: String,
}

impl Station {
    /// Sign a run of the station's results store as `results sign` does.
    /// Refused: no store (`--db none`), a role other than `reviewed` or
    /// `approved`, no such run (`404`), and whatever the store's rules
    /// refuse (an approval before a review or by the reviewer, a name
    /// empty or too long, a run not ended, ...: `400`, in the store's
    /// words). A store that cannot be opened is `503`.
    pub fn sign(&self, req: &SignRequest) -> Result<Signature, Refused> {
        let mut store = gyrobench::results::Store::open(&self.cfg.store)
            .map_err(|e| Refused::Store(e.to_string()))?
            .ok_or(Refused::NoStore)?;
        let role = Role::parse(req.role.trim())
            .ok_or_else(|| Refused::Bad(format!("role {:?}: reviewed or approved", req.role)))?;
        store
            .sign(req.run.trim(), role, &req.by, &req.note)
            .map_err(|e| match e {
                StoreError::Refused { why } => Refused::Bad(why),
                e @ StoreError::NotFound { .. } => Refused::NotFound(e.to_string()),
                e => Refused::Store(e.to_string()),
            })
    }
}
