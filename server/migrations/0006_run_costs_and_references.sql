-- What each run cost, shown by the results viewer: wall time, CPU time and
-- peak memory of the technique process (0 for runs stored before they were).
ALTER TABLE result_runs ADD COLUMN wall_ms DOUBLE PRECISION NOT NULL DEFAULT 0;
ALTER TABLE result_runs ADD COLUMN cpu_ms DOUBLE PRECISION NOT NULL DEFAULT 0;
ALTER TABLE result_runs ADD COLUMN peak_memory_bytes BIGINT NOT NULL DEFAULT 0;
-- The run's record (`<spp>_0_log.json`) in the set's files; the viewer
-- finds the technique's log and error maps beside it.
ALTER TABLE result_runs ADD COLUMN log TEXT;
