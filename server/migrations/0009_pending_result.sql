-- The result set id a succeeding job's files are moved under, chosen once
-- before the move: a retry after a crash between moving the files and
-- committing the set finds them there (see pipelines::store_results).
ALTER TABLE jobs ADD COLUMN result_pending TEXT;
