-- Schema version 8: each audit entry also seals the row it is about.
--
-- audit_log gains
--   row_hash  SHA-256 (hex) of the audited row's content as it is when the
--             entry is appended (every column; for a room map, body marker
--             map or tracking run also its markers, poses or frames), for
--             entries whose entity names a row of an audited table
--             ("plan:3", "session:7", ...); '' otherwise
-- and the entry's hash covers it (store/audit_chain.h). `arpos audit verify`
-- recomputes each audited row's hash and compares it with the newest entry
-- about that row: a row changed outside the program (sqlite3, another tool)
-- is named. Entries written before this migration have no row hash; their
-- rows are checked from their next entry on.

--
-- The row hash covers every column (SELECT *): a later migration that adds a
-- column to an audited table changes the hash of every such row, so it must
-- append re-sealing entries for them (or leave the new column out of the
-- hash) in the same migration.

ALTER TABLE audit_log ADD COLUMN row_hash TEXT NOT NULL DEFAULT '';
