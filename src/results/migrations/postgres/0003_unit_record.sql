-- Schema 3: the record of a unit. A run holds one or more units (the
-- run-unit relation, one row per unit slot of each part, with the unit's
-- own outcome and the coefficient set it was compensated with); who ran it
-- where with what (bench id, host, source revision, the instruments'
-- identities and calibration due dates); coefficient sets with their
-- SHA-256, the software that fitted them and the runs they were fitted on;
-- imported runs stored as references (never judged); and the logs sync has
-- indexed, so an unchanged log is not read again.

ALTER TABLE runs ADD COLUMN bench_id TEXT;
ALTER TABLE runs ADD COLUMN host TEXT;
ALTER TABLE runs ADD COLUMN software_revision TEXT;
ALTER TABLE runs ADD COLUMN instruments TEXT;
ALTER TABLE runs ADD COLUMN calibration_overdue TEXT;

CREATE TABLE run_units (
    run TEXT NOT NULL REFERENCES runs (id),
    slot TEXT NOT NULL,
    unit_id BIGINT NOT NULL REFERENCES units (id),
    outcome TEXT NOT NULL,
    coeffs_source TEXT,
    coeffs_serial TEXT,
    coeffs_version BIGINT,
    coeffs_sha256 TEXT,
    coeffs_override_reason TEXT,
    PRIMARY KEY (run, slot)
);
CREATE INDEX run_units_unit ON run_units (unit_id, run);
INSERT INTO run_units (run, slot, unit_id, outcome) SELECT id, '', unit_id, outcome FROM runs;

ALTER TABLE measurements ADD COLUMN slot TEXT NOT NULL DEFAULT '';

ALTER TABLE coefficient_sets ADD COLUMN sha256 TEXT;
ALTER TABLE coefficient_sets ADD COLUMN software TEXT;
ALTER TABLE coefficient_sets ADD COLUMN fitted_on TEXT;

UPDATE runs SET outcome = 'reference' WHERE imported_from IS NOT NULL AND outcome <> 'running';
UPDATE run_units SET outcome = 'reference'
    WHERE run IN (SELECT id FROM runs WHERE outcome = 'reference');

CREATE TABLE log_files (
    path TEXT PRIMARY KEY,
    size BIGINT NOT NULL,
    mtime_ns BIGINT NOT NULL,
    summary_sha256 TEXT NOT NULL,
    part_key TEXT NOT NULL,
    indexed_utc TEXT NOT NULL
);
