-- Service accounts (the `baselines` account that publishes the state of
-- the art on first start): verified without mail, exempt from quotas, and
-- their jobs wait while any user's job is queued.
ALTER TABLE users ADD COLUMN is_service INTEGER NOT NULL DEFAULT 0;
