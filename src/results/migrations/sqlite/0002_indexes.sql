-- Schema 2: the questions of docs/results.md, "Benchmark", answered from
-- indexes. Units are looked up by serial alone (`results unit SERIAL`,
-- `--serial`): without an index a unit's history scanned every run. A
-- trend reads a measurement's values from its index, never the table.
CREATE INDEX units_serial ON units (serial);
DROP INDEX measurements_name;
CREATE INDEX measurements_name ON measurements (name, run, value, outcome);
