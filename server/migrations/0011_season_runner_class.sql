-- The runner class a season's times come from (fbksd-ci's machine
-- `class`: CPU model, ISA level, cores, memory). Equal time compares only
-- runs measured on it, and benchmark jobs of the season go only to runners
-- of it. NULL until the season's first result set that names a class is
-- stored (or an administrator names one when starting the season).
ALTER TABLE seasons ADD COLUMN runner_class TEXT;
