-- Schema 6: review and sign-off. A signature names the run part it
-- signs, the role (`reviewed`, then `approved` by another person), who
-- and when, and binds what was signed: the log's SHA-256 as the store
-- held it and a digest of the part's stored verdict and figures
-- (`results::sign`). `results verify` names a signed part whose log or
-- figures changed since.

CREATE TABLE signatures (
    run TEXT NOT NULL REFERENCES runs (id),
    role TEXT NOT NULL,
    by_name TEXT NOT NULL,
    signed_utc TEXT NOT NULL,
    log_sha256 TEXT NOT NULL,
    figures_sha256 TEXT NOT NULL,
    note TEXT NOT NULL,
    PRIMARY KEY (run, role, by_name)
);
