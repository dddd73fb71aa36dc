-- Schema 4: records that cannot be forged. Each unit of a run keeps how
-- the identity of the coefficient set it used checked out against the
-- store when the run chose it (`registered`: the store held its text byte
-- for byte; `edited`: a changed copy of a stored set; `unregistered`: no
-- set the store held; `unchecked`: no store could be asked), the version
-- its text claimed (`coeffs_version` is only ever the store's), and what
-- was verified, in words. Runs stored before have none of these (null).
-- Sets are looked up by the SHA-256 of their text.

ALTER TABLE run_units ADD COLUMN coeffs_identity TEXT;
ALTER TABLE run_units ADD COLUMN coeffs_claimed_version INTEGER;
ALTER TABLE run_units ADD COLUMN coeffs_identity_note TEXT;

CREATE INDEX coefficient_sets_sha256 ON coefficient_sets (sha256);
