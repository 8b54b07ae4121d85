-- An account that must choose its own password before anything else: the
-- administrator created at the first start, whose one-time password was
-- printed to the log (and may sit in a terminal's scrollback or a log
-- collector). Cleared when the password is changed or reset.
ALTER TABLE users ADD COLUMN must_change_password BIGINT NOT NULL DEFAULT 0;
