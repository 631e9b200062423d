-- Schema version 7: plan approval, who ended a session and why, and the
-- commands at work on a session (to tell a crashed run from a finished one).
--
-- plans gain their approval (store/roles.h: only a physicist approves):
--   approved_by       "name (role)" of who approved it; NULL while not approved
--   approved_unix_ms  when; NULL while not approved
--   approval_note     free text of the approver
-- An approved plan cannot be changed or deleted, and no room map can be
-- added to it (triggers below): what was approved is what sessions use.
--
-- sessions gain
--   on_unapproved_plan  1 when the session ran on a plan that was not
--                       approved (--unapproved, or a research run); 0 else
--   ended_by, end_reason  who completed or aborted it and why
--
-- session_activity holds one row per command at work on a session (a
-- tracking run, the GUI's positioning screen), removed when the command
-- ends. A row whose process no longer exists is a run that died: the next
-- command that opens the store marks its session aborted (controllers/
-- session_lifecycle.h). Operational rows, not clinical history: not audited.

ALTER TABLE plans ADD COLUMN approved_by TEXT;
ALTER TABLE plans ADD COLUMN approved_unix_ms INTEGER
  CHECK (approved_unix_ms IS NULL OR approved_unix_ms >= created_unix_ms);
ALTER TABLE plans ADD COLUMN approval_note TEXT NOT NULL DEFAULT '';

CREATE TRIGGER plans_approved_are_locked BEFORE UPDATE ON plans
  WHEN OLD.approved_unix_ms IS NOT NULL
BEGIN
  SELECT RAISE(ABORT, 'the plan is approved and cannot be changed');
END;

CREATE TRIGGER plans_approval_only BEFORE UPDATE ON plans
  WHEN OLD.approved_unix_ms IS NULL AND (
    NEW.approved_unix_ms IS NULL OR NEW.approved_by IS NULL OR length(NEW.approved_by) = 0
    OR NEW.plan_id IS NOT OLD.plan_id OR NEW.patient_id IS NOT OLD.patient_id
    OR NEW.name IS NOT OLD.name OR NEW.reference_model_name IS NOT OLD.reference_model_name
    OR NEW.reference_model_mesh IS NOT OLD.reference_model_mesh
    OR NEW.room_from_model_target IS NOT OLD.room_from_model_target
    OR NEW.created_unix_ms IS NOT OLD.created_unix_ms)
BEGIN
  SELECT RAISE(ABORT, 'a plan changes only by its approval (approved_by and approved_unix_ms)');
END;

CREATE TRIGGER plans_approved_are_kept BEFORE DELETE ON plans
  WHEN OLD.approved_unix_ms IS NOT NULL
BEGIN
  SELECT RAISE(ABORT, 'the plan is approved and cannot be deleted');
END;

CREATE TRIGGER room_maps_not_for_approved_plans BEFORE INSERT ON room_maps
  WHEN (SELECT approved_unix_ms FROM plans WHERE plan_id = NEW.plan_id) IS NOT NULL
BEGIN
  SELECT RAISE(ABORT, 'the plan is approved: no room map can be added to it');
END;

ALTER TABLE sessions ADD COLUMN on_unapproved_plan INTEGER NOT NULL DEFAULT 0
  CHECK (on_unapproved_plan IN (0, 1));
ALTER TABLE sessions ADD COLUMN ended_by TEXT NOT NULL DEFAULT '';
ALTER TABLE sessions ADD COLUMN end_reason TEXT NOT NULL DEFAULT '';

CREATE TABLE session_activity (
  activity_id     INTEGER PRIMARY KEY,
  session_id      INTEGER NOT NULL REFERENCES sessions(session_id) ON DELETE CASCADE,
  pid             INTEGER NOT NULL CHECK (pid > 0),
  host            TEXT NOT NULL,
  command         TEXT NOT NULL,
  started_unix_ms INTEGER NOT NULL CHECK (started_unix_ms >= 0)
);
CREATE INDEX session_activity_by_session ON session_activity(session_id);
