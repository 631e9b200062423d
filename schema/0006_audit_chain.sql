-- Schema version 6: a tamper-evident audit log.
--
-- audit_log gains
--   prev_hash   the entry_hash of the entry before it ('' for the first)
--   entry_hash  SHA-256 (hex) over the entry's id, time, actor, action,
--               entity, details and prev_hash (store/audit_chain.h), computed
--               by the program when it appends the entry
-- so that a changed, inserted or removed entry breaks the chain from there on
-- (`arpos audit verify`). Entries written before this migration keep empty
-- hashes: the chain starts after them, and verify counts them apart.
-- (ADD COLUMN changes no row, so the append-only triggers stay as they are.)

ALTER TABLE audit_log ADD COLUMN prev_hash TEXT NOT NULL DEFAULT '';
ALTER TABLE audit_log ADD COLUMN entry_hash TEXT NOT NULL DEFAULT '';
