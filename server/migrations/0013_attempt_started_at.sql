-- When the current attempt of a running job was claimed: the server stops
-- an attempt that runs past `max_job_seconds`, however its runner
-- heart-beats. (`started_at` is the first attempt's.)
ALTER TABLE jobs ADD COLUMN attempt_started_at BIGINT;
-- Jobs running at the upgrade: bounded from their first attempt's start.
UPDATE jobs SET attempt_started_at = started_at WHERE state = 'running';
