-- The name result sets give the scene a reference was made for (the
-- runner's path-safe scene.json name): a result set may name a reference
-- only for a scene of that name. NULL for references asked for before the
-- runners sent it.
ALTER TABLE scene_references ADD COLUMN scene_name TEXT;
