-- Projects (hosted git repositories), pipelines and their jobs, runners,
-- leaderboard seasons and result sets. Same portable conventions as 0001.

-- A technique's repository: `data_dir/git/<id>.git`, served at /git/<name>.git.
-- Names are unique on the server, as technique names on a leaderboard are.
CREATE TABLE projects (
    id TEXT PRIMARY KEY,
    owner_id TEXT NOT NULL REFERENCES users (id) ON DELETE CASCADE,
    name TEXT NOT NULL UNIQUE,
    visibility TEXT NOT NULL,
    created_at BIGINT NOT NULL
);
CREATE INDEX projects_by_owner ON projects (owner_id);

-- One push, or one request from a form or the API, at one commit.
CREATE TABLE pipelines (
    id TEXT PRIMARY KEY,
    project_id TEXT NOT NULL REFERENCES projects (id) ON DELETE CASCADE,
    user_id TEXT NOT NULL REFERENCES users (id) ON DELETE CASCADE,
    commit_sha TEXT NOT NULL,
    git_ref TEXT NOT NULL,
    -- JSON object of the pipeline's variables (FBKSD_RUN, FBKSD_PUBLISH).
    variables TEXT NOT NULL,
    -- push | api | web | season
    source TEXT NOT NULL,
    created_at BIGINT NOT NULL
);
CREATE INDEX pipelines_by_project ON pipelines (project_id, created_at);

-- Machines that run jobs; only the SHA-256 of their token is stored.
CREATE TABLE runners (
    id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    token_hash TEXT NOT NULL UNIQUE,
    -- JSON: what the runner said about its machine (CPU model, cores, …).
    machine TEXT NOT NULL,
    registered_at BIGINT NOT NULL,
    last_seen_at BIGINT NOT NULL
);

-- Leaderboard seasons: a new one starts when the scene pool changes; old
-- seasons stay readable.
CREATE TABLE seasons (
    number BIGINT PRIMARY KEY,
    note TEXT NOT NULL,
    started_at BIGINT NOT NULL
);
INSERT INTO seasons (number, note, started_at) VALUES (1, 'first season', 0);

-- A unit of work for a runner (build, benchmark) or for the server itself
-- (publish). state: queued | running | succeeded | failed | cancelled.
-- failure_reason: build_failed | timeout | out_of_memory | crashed |
-- invalid_output | infrastructure_error.
CREATE TABLE jobs (
    id TEXT PRIMARY KEY,
    pipeline_id TEXT NOT NULL REFERENCES pipelines (id) ON DELETE CASCADE,
    project_id TEXT NOT NULL REFERENCES projects (id) ON DELETE CASCADE,
    user_id TEXT NOT NULL REFERENCES users (id) ON DELETE CASCADE,
    kind TEXT NOT NULL,
    state TEXT NOT NULL,
    failure_reason TEXT,
    message TEXT NOT NULL,
    -- Runner-side attempts so far; a lost lease queues the job again
    -- until max_attempts.
    attempts BIGINT NOT NULL,
    max_attempts BIGINT NOT NULL,
    runner_id TEXT REFERENCES runners (id) ON DELETE SET NULL,
    -- SHA-256 of the current attempt's job token.
    token_hash TEXT UNIQUE,
    lease_expires_at BIGINT,
    season BIGINT NOT NULL REFERENCES seasons (number),
    -- Season re-runs publish their result as soon as it exists.
    publish_on_success BIGINT NOT NULL,
    -- Whether the job counts against the user's daily runs (infrastructure
    -- failures and cancellations before start do not).
    counts_for_quota BIGINT NOT NULL,
    log_bytes BIGINT NOT NULL,
    upload_bytes BIGINT NOT NULL,
    -- The results the runner uploaded (JSON), stored as a result set when
    -- the job succeeds.
    staged_results TEXT,
    created_at BIGINT NOT NULL,
    started_at BIGINT,
    finished_at BIGINT
);
CREATE INDEX jobs_by_state ON jobs (state, created_at);
CREATE INDEX jobs_by_user ON jobs (user_id, created_at);
CREATE INDEX jobs_by_pipeline ON jobs (pipeline_id);

-- A job's log, in the chunks it arrived in.
CREATE TABLE job_logs (
    job_id TEXT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    seq BIGINT NOT NULL,
    attempt BIGINT NOT NULL,
    content TEXT NOT NULL,
    created_at BIGINT NOT NULL,
    PRIMARY KEY (job_id, seq)
);

-- The immutable outcome of one successful benchmark job. The owner's and
-- the project's deletion keep published sets (ids become NULL) and
-- delete the others.
CREATE TABLE result_sets (
    id TEXT PRIMARY KEY,
    job_id TEXT UNIQUE REFERENCES jobs (id) ON DELETE SET NULL,
    project_id TEXT REFERENCES projects (id) ON DELETE SET NULL,
    user_id TEXT REFERENCES users (id) ON DELETE SET NULL,
    technique TEXT NOT NULL,
    -- The technique's info.json at the commit (JSON).
    info TEXT NOT NULL,
    commit_sha TEXT NOT NULL,
    season BIGINT NOT NULL REFERENCES seasons (number),
    -- JSON: image digest, runner, machine, renderer versions, …
    provenance TEXT NOT NULL,
    -- JSON list of the metrics' descriptions (acronym, name, lower_is_better).
    metrics TEXT NOT NULL,
    created_at BIGINT NOT NULL,
    published_at BIGINT,
    hidden_reason TEXT
);
CREATE INDEX result_sets_by_season ON result_sets (season, published_at);
CREATE INDEX result_sets_by_project ON result_sets (project_id);

-- One (scene, spp) run of a result set.
CREATE TABLE result_runs (
    result_id TEXT NOT NULL REFERENCES result_sets (id) ON DELETE CASCADE,
    scene TEXT NOT NULL,
    spp BIGINT NOT NULL,
    status TEXT NOT NULL,
    message TEXT NOT NULL,
    technique_ms DOUBLE PRECISION NOT NULL,
    render_ms DOUBLE PRECISION NOT NULL,
    used_samples BIGINT NOT NULL,
    -- JSON object: metric acronym → finite value.
    metric_values TEXT NOT NULL,
    -- A file of the result set (PNG), if uploaded.
    image TEXT,
    PRIMARY KEY (result_id, scene, spp)
);

-- The scenes a result set was measured on, with the hashes that pin them.
CREATE TABLE result_scenes (
    result_id TEXT NOT NULL REFERENCES result_sets (id) ON DELETE CASCADE,
    scene TEXT NOT NULL,
    -- JSON list of tags.
    tags TEXT NOT NULL,
    scene_hash TEXT NOT NULL,
    reference_hash TEXT NOT NULL,
    PRIMARY KEY (result_id, scene)
);

-- Server-wide settings (the runner registration token's digest, …).
CREATE TABLE settings (
    key TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
