-- When the current attempt of a running job was claimed: the server stops
-- an attempt that runs past `max_job_seconds`, however its runner
-- heart-beats. (`started_at` is the first attempt's.)
ALTER TABLE jobs ADD COLUMN attempt_started_at BIGINT;
