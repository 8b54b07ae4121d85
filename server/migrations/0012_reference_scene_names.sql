-- The names result sets give the scenes a reference was made for (the
-- runners' path-safe scene.json names, sent with each ask): a result set
-- may name a reference only for a scene of one of these names. A key may
-- have several (two scenes can render the same files), up to a bound.
CREATE TABLE scene_reference_names (
    key TEXT NOT NULL,
    name TEXT NOT NULL,
    PRIMARY KEY (key, name)
);
