-- Schema 1 of the results store (SQLite): units, runs (one row per part of
-- a run), their measurements, and the coefficient sets calibrate wrote.
-- The PostgreSQL twin of this file has the same tables and columns.

CREATE TABLE units (
    id INTEGER PRIMARY KEY,
    dut_type TEXT NOT NULL,
    serial TEXT NOT NULL,
    UNIQUE (dut_type, serial)
);

CREATE TABLE runs (
    id TEXT PRIMARY KEY,
    run_id TEXT NOT NULL,
    part INTEGER NOT NULL,
    parent_id TEXT REFERENCES runs (id),
    latest INTEGER NOT NULL,
    unit_id INTEGER NOT NULL REFERENCES units (id),
    procedure_name TEXT NOT NULL,
    procedure_sha256 TEXT NOT NULL,
    procedure_path TEXT NOT NULL,
    bench TEXT NOT NULL,
    station TEXT NOT NULL,
    operator TEXT NOT NULL,
    seed INTEGER,
    software_version TEXT NOT NULL,
    run_started_utc TEXT NOT NULL,
    started_utc TEXT NOT NULL,
    ended_utc TEXT,
    device_time_s REAL,
    frames INTEGER,
    outcome TEXT NOT NULL,
    error_step TEXT,
    error_device TEXT,
    error_message TEXT,
    cleanup_completed INTEGER,
    bench_left TEXT,
    bench_left_verified INTEGER,
    link_frames INTEGER,
    link_lost_frames INTEGER,
    link_crc_errors INTEGER,
    link_reconnects INTEGER,
    link_longest_gap_ms INTEGER,
    log_path TEXT NOT NULL,
    log_sha256 TEXT,
    imported_from TEXT,
    recorded_utc TEXT NOT NULL
);
CREATE INDEX runs_unit ON runs (unit_id, started_utc);
CREATE INDEX runs_started ON runs (started_utc);
CREATE INDEX runs_procedure ON runs (procedure_name, started_utc);
CREATE INDEX runs_outcome ON runs (outcome, started_utc);
CREATE INDEX runs_run ON runs (run_id, part);

CREATE TABLE measurements (
    run TEXT NOT NULL REFERENCES runs (id),
    seq INTEGER NOT NULL,
    name TEXT NOT NULL,
    value REAL,
    unit TEXT NOT NULL,
    low REAL,
    high REAL,
    outcome TEXT NOT NULL,
    step TEXT NOT NULL,
    note TEXT NOT NULL,
    PRIMARY KEY (run, seq)
);
CREATE INDEX measurements_name ON measurements (name, run);

CREATE TABLE coefficient_sets (
    id INTEGER PRIMARY KEY,
    unit_id INTEGER NOT NULL REFERENCES units (id),
    version INTEGER NOT NULL,
    created_utc TEXT NOT NULL,
    coeffs_toml TEXT NOT NULL,
    validation TEXT NOT NULL,
    held_out_drift_pp_dph REAL,
    source_runs TEXT NOT NULL,
    UNIQUE (unit_id, version)
);
