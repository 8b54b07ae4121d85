-- Seeds jobs: runs of a published result set (more_seeds_of) made again
-- with more sample seeds (more_seeds, JSON: scene, spp, first, end per
-- run), because a tie on the board rests on them that more seeds could
-- settle. Their repeats are added to the set when the job succeeds.
ALTER TABLE jobs ADD COLUMN more_seeds_of TEXT;
ALTER TABLE jobs ADD COLUMN more_seeds TEXT;
-- One seeds job waiting or running per set, whichever server instance
-- planned it.
CREATE UNIQUE INDEX jobs_one_pending_seeds ON jobs (more_seeds_of)
    WHERE more_seeds_of IS NOT NULL AND state IN ('queued', 'running');
