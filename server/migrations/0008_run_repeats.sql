-- A run's repeats (one per sample seed), as JSON: the list of
-- fbksd_exchange::results::Repeat. NULL for runs stored before repeats,
-- which were made once with seed 0.
ALTER TABLE result_runs ADD COLUMN repeats TEXT;
