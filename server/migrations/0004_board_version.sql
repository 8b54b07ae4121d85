-- A counter bumped by every change to what leaderboards show (publish,
-- unpublish, hide, discard, new season), so every server instance can keep
-- boards in memory and know when to reload them.
CREATE TABLE board_version (
    id BIGINT PRIMARY KEY,
    version BIGINT NOT NULL
);
INSERT INTO board_version (id, version) VALUES (1, 0);
