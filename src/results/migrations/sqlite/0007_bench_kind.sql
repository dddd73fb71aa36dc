-- Schema 7: the kind of bench each run part ran on, so a trend can keep
-- one: `embedded` (the simulated bench inside gyrobench), `simulated`
-- (a bench of devices that identified themselves as gyrobench's
-- simulators: `sim serve`), `hardware` (any other bench of devices) or
-- `imported` (another lab's file). Parts stored before are classed from
-- what they kept: the bench name, the import and the instruments'
-- identities as they answered.

ALTER TABLE runs ADD COLUMN bench_kind TEXT;

UPDATE runs SET bench_kind = CASE
    WHEN imported_from IS NOT NULL THEN 'imported'
    WHEN bench = 'embedded' THEN 'embedded'
    WHEN instruments LIKE '%GYROBENCH-SIM%' OR instruments LIKE '%SIM-TABLE%'
        OR instruments LIKE '%F4T1L1AA1A1SIMA%' THEN 'simulated'
    ELSE 'hardware'
END;
