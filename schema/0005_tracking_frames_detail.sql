-- Schema version 5: what tracking now produces per frame, and per run.
--
-- tracking_runs gains
--   sequence_name     the tracking/<name> folder the run replayed or recorded
--   summary           a person-readable summary written when the run is
--                     stored (frames, tracked/carried/lost, in/out, timing)
-- Both are '' when not recorded, as for runs stored before this migration.
--
-- tracking_frames gains
--   room_from_camera  4x4 float64: camera frame -> room frame, the camera's
--                     localisation against the room map. It may be present on
--                     a lost frame (camera localised, patient not found);
--                     NULL when the camera was not localised.
--   source            how the patient pose was obtained: 'tracked' (measured
--                     in this frame), 'carried' (carried over from earlier
--                     frames) or 'lost' (none); 'lost' exactly when status is
--                     'lost'
--   uncertainty_translation_mm, uncertainty_rotation_deg
--                     the bound on the pose error the in/out verdict was made
--                     with; both or neither, >= 0, NULL on a lost frame
--   total_ms          processing time of the frame, >= 0
--   note              why the frame is lost or carried, free text, may be ''
--
-- Rows from before this migration read back with source 'lost' if their
-- status is 'lost' and 'tracked' otherwise, no camera pose, no uncertainty
-- (so a frame that is not lost may still have none: the program requires it
-- of the frames it writes from now on), total_ms 0 and an empty note.
--
-- The correction columns keep their names and values; their axes are now
-- stated as the couch axes of DATASET.md "Corrections" (0001 said "room
-- axes"; no ARPos before this version wrote tracking frames).
--
-- The source/status rule ties two columns, which ALTER TABLE ADD COLUMN cannot
-- express for existing rows, so tracking_frames is rebuilt: renamed, created
-- anew with every constraint, filled from the old rows, and the old table
-- dropped. Nothing refers to tracking_frames (no foreign key, index, trigger
-- or view), so the rename changes nothing else; the migrator runs this with
-- foreign keys off and checks them afterwards.

ALTER TABLE tracking_runs ADD COLUMN sequence_name TEXT NOT NULL DEFAULT '';
ALTER TABLE tracking_runs ADD COLUMN summary TEXT NOT NULL DEFAULT '';

ALTER TABLE tracking_frames RENAME TO tracking_frames_v4;

-- status 'lost' means no estimate: then pose and correction are NULL, and
-- only then. Corrections are what the couch must move, in the couch axes of
-- DATASET.md "Corrections": tx, ty, tz = lateral, longitudinal, vertical (mm);
-- rx, ry, rz = pitch, roll, yaw (deg).
CREATE TABLE tracking_frames (
  tracking_run_id   INTEGER NOT NULL
                      REFERENCES tracking_runs(tracking_run_id) ON DELETE CASCADE,
  frame_index       INTEGER NOT NULL CHECK (frame_index >= 0),
  timestamp_s       REAL NOT NULL,
  status            TEXT NOT NULL
                      CHECK (status IN ('in_tolerance', 'out_of_tolerance', 'lost')),
  room_from_model   BLOB,  -- 4x4 float64 estimate
  correction_tx_mm  REAL,
  correction_ty_mm  REAL,
  correction_tz_mm  REAL,
  correction_rx_deg REAL,
  correction_ry_deg REAL,
  correction_rz_deg REAL,
  room_from_camera  BLOB,  -- 4x4 float64, NULL: camera not localised
  source            TEXT NOT NULL CHECK (source IN ('tracked', 'carried', 'lost')),
  uncertainty_translation_mm REAL
                      CHECK (uncertainty_translation_mm IS NULL OR uncertainty_translation_mm >= 0),
  uncertainty_rotation_deg   REAL
                      CHECK (uncertainty_rotation_deg IS NULL OR uncertainty_rotation_deg >= 0),
  total_ms          REAL NOT NULL DEFAULT 0 CHECK (total_ms >= 0),
  note              TEXT NOT NULL DEFAULT '',
  PRIMARY KEY (tracking_run_id, frame_index),
  CHECK ((status = 'lost') = (room_from_model IS NULL)),
  CHECK ((room_from_model IS NULL) = (correction_tx_mm IS NULL)),
  CHECK ((correction_tx_mm IS NULL) = (correction_ty_mm IS NULL)
     AND (correction_tx_mm IS NULL) = (correction_tz_mm IS NULL)
     AND (correction_tx_mm IS NULL) = (correction_rx_deg IS NULL)
     AND (correction_tx_mm IS NULL) = (correction_ry_deg IS NULL)
     AND (correction_tx_mm IS NULL) = (correction_rz_deg IS NULL)),
  CHECK ((status = 'lost') = (source = 'lost')),
  CHECK ((uncertainty_translation_mm IS NULL) = (uncertainty_rotation_deg IS NULL)),
  CHECK (status <> 'lost' OR uncertainty_translation_mm IS NULL)
) WITHOUT ROWID;

INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, status, room_from_model,
                             correction_tx_mm, correction_ty_mm, correction_tz_mm,
                             correction_rx_deg, correction_ry_deg, correction_rz_deg, source)
  SELECT tracking_run_id, frame_index, timestamp_s, status, room_from_model,
         correction_tx_mm, correction_ty_mm, correction_tz_mm,
         correction_rx_deg, correction_ry_deg, correction_rz_deg,
         CASE WHEN status = 'lost' THEN 'lost' ELSE 'tracked' END
  FROM tracking_frames_v4;

DROP TABLE tracking_frames_v4;
