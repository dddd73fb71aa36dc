-- Schema 5: a verdict a lab can sign. Each run part keeps the decision
-- rule its figures were judged by (`simple`, `guarded` with its guard
-- band as a multiple of U, or `non_binary`), and each measurement its
-- uncertainty (`u`, the expanded `expanded_u` and its coverage factor
-- `k`) and the guard band the rule moved its limits by, in its unit.
-- Runs stored before have none of these (null); their logs, replayed,
-- were judged by simple acceptance.

ALTER TABLE runs ADD COLUMN decision_rule TEXT;
ALTER TABLE runs ADD COLUMN guard_band_u DOUBLE PRECISION;

ALTER TABLE measurements ADD COLUMN u DOUBLE PRECISION;
ALTER TABLE measurements ADD COLUMN expanded_u DOUBLE PRECISION;
ALTER TABLE measurements ADD COLUMN k DOUBLE PRECISION;
ALTER TABLE measurements ADD COLUMN guard_band DOUBLE PRECISION;
