-- Schema version 3: the tolerances a tracking run judged its frames against.
--
-- tracking_frames.status says 'in_tolerance' or 'out_of_tolerance'; without
-- the limits used, that verdict cannot be checked afterwards. Runs recorded
-- before this migration get 3 mm and 2 degrees as defaults; their `options`
-- text holds the limits actually used, if the run recorded them.

ALTER TABLE tracking_runs ADD COLUMN tolerance_translation_mm REAL NOT NULL DEFAULT 3.0
  CHECK (tolerance_translation_mm > 0);
ALTER TABLE tracking_runs ADD COLUMN tolerance_rotation_deg REAL NOT NULL DEFAULT 2.0
  CHECK (tolerance_rotation_deg > 0);
