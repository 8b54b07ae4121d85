-- Benchmarks that measure a published result set again (measures_again):
-- the set was measured while its runner's calibration lay off its
-- class's, so equal time leaves it out; the new set is published in its
-- place when the benchmark succeeds.
ALTER TABLE jobs ADD COLUMN measures_again TEXT;
-- One such benchmark waiting or running per set, whichever server
-- instance planned it.
CREATE UNIQUE INDEX jobs_one_pending_measure ON jobs (measures_again)
    WHERE measures_again IS NOT NULL AND state IN ('queued', 'running');
