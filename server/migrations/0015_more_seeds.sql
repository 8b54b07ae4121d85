-- Seeds jobs: runs of a published result set (more_seeds_of) made again
-- with more sample seeds (more_seeds, JSON: scene, spp, first, end per
-- run), because a tie on the board rests on them that more seeds could
-- settle. Their repeats are added to the set when the job succeeds.
ALTER TABLE jobs ADD COLUMN more_seeds_of TEXT;
ALTER TABLE jobs ADD COLUMN more_seeds TEXT;
