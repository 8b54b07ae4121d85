-- References built once for the whole service: one row per reference key
-- (what makes the image: renderer version, samples per pixel, scene
-- files). `job_id` is the reference job that makes it (the latest, when a
-- failed one was retried); `reference_hash` is set once its files are
-- stored under the data directory's scene-references/<key hex>/.
CREATE TABLE scene_references (
    key TEXT PRIMARY KEY,
    scene TEXT NOT NULL,
    job_id TEXT NOT NULL,
    reference_hash TEXT,
    created_at BIGINT NOT NULL,
    finished_at BIGINT
);
-- Which reference job makes which key (a claim looks jobs up by key).
ALTER TABLE jobs ADD COLUMN reference_key TEXT;
