-- What a runner is doing when it holds no job: preparing (building
-- references, say) or ready. NULL means ready. status_since is when the
-- server first saw this status (Unix ms), so pages can say for how long.
ALTER TABLE runners ADD COLUMN status TEXT;
ALTER TABLE runners ADD COLUMN status_since BIGINT;
