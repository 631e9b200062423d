-- Schema version 2: session lifecycle and foreign-key indices.
--
-- Sessions gain a status and an end time, so a session left open by a crash
-- can be told from one that was completed or aborted. Rows that existed
-- before this migration become 'open' with no end time.
--
-- SQLite does not index the child side of a foreign key by itself; without
-- these, every parent delete or lookup of "the sessions of a plan" scans the
-- child table.

ALTER TABLE sessions ADD COLUMN status TEXT NOT NULL DEFAULT 'open'
  CHECK (status IN ('open', 'completed', 'aborted'));
ALTER TABLE sessions ADD COLUMN ended_unix_ms INTEGER
  CHECK (ended_unix_ms IS NULL OR ended_unix_ms >= started_unix_ms);

CREATE INDEX plans_by_patient ON plans(patient_id);
CREATE INDEX sessions_by_plan ON sessions(plan_id);
CREATE INDEX recordings_by_plan ON recordings(plan_id) WHERE plan_id IS NOT NULL;
CREATE INDEX recordings_by_session ON recordings(session_id) WHERE session_id IS NOT NULL;
CREATE INDEX room_maps_by_plan ON room_maps(plan_id);
CREATE INDEX room_maps_by_recording ON room_maps(recording_id);
CREATE INDEX body_marker_maps_by_session ON body_marker_maps(session_id);
CREATE INDEX body_marker_maps_by_recording ON body_marker_maps(recording_id);
CREATE INDEX reconstructions_by_session ON reconstructions(session_id);
CREATE INDEX reconstructions_by_recording ON reconstructions(recording_id);
CREATE INDEX alignments_by_reconstruction ON alignments(reconstruction_id);
CREATE INDEX alignments_by_parent ON alignments(parent_alignment_id);
CREATE INDEX tracking_runs_by_session ON tracking_runs(session_id);
CREATE INDEX tracking_runs_by_alignment ON tracking_runs(alignment_id);
CREATE INDEX tracking_runs_by_recording ON tracking_runs(recording_id);
CREATE INDEX audit_log_by_entity ON audit_log(entity);
