-- ARPos session store, schema version 1: the initial tables.
--
-- Applied by src/store/migrator.cc inside one transaction together with
-- `PRAGMA user_version = 1`. Never edit a migration that has shipped: add a
-- new numbered file instead.
--
-- Conventions
--   *_id INTEGER PRIMARY KEY     row ids (typed ids in src/store/records.h)
--   *_unix_ms INTEGER            UTC time, milliseconds since 1970-01-01
--   *_m / *_mm / *_deg / *_px    units as in the name
--   BLOB columns                 the codecs of src/store/blob_codec.h; poses are
--                                4x4 float64 matrices named b_from_a
--
-- ON DELETE policy: clinical history is never removed by accident. A patient
-- with plans, and a plan with sessions, cannot be deleted (RESTRICT). The data
-- products of a plan or session (recordings, maps, reconstructions, alignments,
-- tracking runs and frames) go with it (CASCADE) when it may be deleted;
-- optional links to a source row become NULL (SET NULL). The audit log is
-- never deleted or changed (triggers below).

PRAGMA application_id = 1095913551;  -- 0x4152504F, 'ARPO': marks an ARPos store

CREATE TABLE patients (
  patient_id      INTEGER PRIMARY KEY,
  external_id     TEXT NOT NULL UNIQUE CHECK (length(external_id) > 0),  -- hospital id
  display_name    TEXT NOT NULL DEFAULT '',
  created_unix_ms INTEGER NOT NULL CHECK (created_unix_ms >= 0)
);

-- A treatment plan: the reference body surface and where it must be in the room.
CREATE TABLE plans (
  plan_id                 INTEGER PRIMARY KEY,
  patient_id              INTEGER NOT NULL
                            REFERENCES patients(patient_id) ON DELETE RESTRICT,
  name                    TEXT NOT NULL CHECK (length(name) > 0),
  reference_model_name    TEXT NOT NULL DEFAULT '',  -- source file, for people
  reference_model_mesh    BLOB NOT NULL,             -- triangle mesh, model frame, metres
  room_from_model_target  BLOB NOT NULL,             -- 4x4: model frame -> room frame (desired)
  created_unix_ms         INTEGER NOT NULL CHECK (created_unix_ms >= 0)
);

-- One treatment session (fraction) of a plan.
CREATE TABLE sessions (
  session_id      INTEGER PRIMARY KEY,
  plan_id         INTEGER NOT NULL REFERENCES plans(plan_id) ON DELETE RESTRICT,
  fraction        INTEGER NOT NULL CHECK (fraction >= 1),
  operator_name   TEXT NOT NULL DEFAULT '',
  started_unix_ms INTEGER NOT NULL CHECK (started_unix_ms >= 0),
  notes           TEXT NOT NULL DEFAULT ''
);

-- RGB-D sequences (DATASET.md layout). A room sequence belongs to a plan;
-- body scans and tracking sequences belong to a session.
CREATE TABLE recordings (
  recording_id    INTEGER PRIMARY KEY,
  plan_id         INTEGER REFERENCES plans(plan_id) ON DELETE CASCADE,
  session_id      INTEGER REFERENCES sessions(session_id) ON DELETE CASCADE,
  kind            TEXT NOT NULL CHECK (kind IN ('room', 'body_scan', 'tracking')),
  name            TEXT NOT NULL DEFAULT '',
  path            TEXT NOT NULL CHECK (length(path) > 0),
  frame_count     INTEGER NOT NULL CHECK (frame_count >= 0),
  width           INTEGER NOT NULL CHECK (width > 0),
  height          INTEGER NOT NULL CHECK (height > 0),
  fx              REAL NOT NULL CHECK (fx > 0),
  fy              REAL NOT NULL CHECK (fy > 0),
  cx              REAL NOT NULL,
  cy              REAL NOT NULL,
  k1              REAL NOT NULL DEFAULT 0,
  k2              REAL NOT NULL DEFAULT 0,
  p1              REAL NOT NULL DEFAULT 0,
  p2              REAL NOT NULL DEFAULT 0,
  k3              REAL NOT NULL DEFAULT 0,
  depth_scale     REAL NOT NULL CHECK (depth_scale > 0),  -- depth units per metre
  created_unix_ms INTEGER NOT NULL CHECK (created_unix_ms >= 0),
  CHECK ((plan_id IS NULL) <> (session_id IS NULL)),
  CHECK ((kind = 'room') = (plan_id IS NOT NULL))
);

-- Planning: the marker (and keypoint) map of the treatment room, room frame.
CREATE TABLE room_maps (
  room_map_id          INTEGER PRIMARY KEY,
  plan_id              INTEGER NOT NULL REFERENCES plans(plan_id) ON DELETE CASCADE,
  recording_id         INTEGER REFERENCES recordings(recording_id) ON DELETE SET NULL,
  origin_marker_id     INTEGER NOT NULL CHECK (origin_marker_id >= 0),
  marker_size_m        REAL NOT NULL CHECK (marker_size_m > 0),
  mean_residual_px     REAL NOT NULL CHECK (mean_residual_px >= 0),
  max_residual_px      REAL NOT NULL CHECK (max_residual_px >= mean_residual_px),
  landmarks_in_room    BLOB,  -- point cloud of keypoint landmarks, room frame, metres
  landmark_descriptors BLOB,  -- uint8 matrix, one row per landmark
  created_unix_ms      INTEGER NOT NULL CHECK (created_unix_ms >= 0)
);

CREATE TABLE room_map_markers (
  room_map_id      INTEGER NOT NULL REFERENCES room_maps(room_map_id) ON DELETE CASCADE,
  marker_id        INTEGER NOT NULL CHECK (marker_id >= 0),
  corners_in_room  BLOB NOT NULL,  -- 4x3 float64, ArUco corner order, room frame, metres
  residual_px      REAL NOT NULL CHECK (residual_px >= 0),
  num_observations INTEGER NOT NULL CHECK (num_observations >= 0),
  PRIMARY KEY (room_map_id, marker_id)
) WITHOUT ROWID;

-- Session: body markers measured in the body scan, body frame.
CREATE TABLE body_marker_maps (
  body_marker_map_id INTEGER PRIMARY KEY,
  session_id         INTEGER NOT NULL REFERENCES sessions(session_id) ON DELETE CASCADE,
  recording_id       INTEGER REFERENCES recordings(recording_id) ON DELETE SET NULL,
  marker_size_m      REAL NOT NULL CHECK (marker_size_m > 0),
  mean_residual_px   REAL NOT NULL CHECK (mean_residual_px >= 0),
  max_residual_px    REAL NOT NULL CHECK (max_residual_px >= mean_residual_px),
  created_unix_ms    INTEGER NOT NULL CHECK (created_unix_ms >= 0)
);

CREATE TABLE body_marker_poses (
  body_marker_map_id INTEGER NOT NULL
                       REFERENCES body_marker_maps(body_marker_map_id) ON DELETE CASCADE,
  marker_id          INTEGER NOT NULL CHECK (marker_id >= 0),
  body_from_marker   BLOB NOT NULL,  -- 4x4 float64
  residual_px        REAL NOT NULL CHECK (residual_px >= 0),
  num_observations   INTEGER NOT NULL CHECK (num_observations >= 0),
  PRIMARY KEY (body_marker_map_id, marker_id)
) WITHOUT ROWID;

-- Session: the surface reconstructed from the body scan, body frame.
CREATE TABLE reconstructions (
  reconstruction_id INTEGER PRIMARY KEY,
  session_id        INTEGER NOT NULL REFERENCES sessions(session_id) ON DELETE CASCADE,
  recording_id      INTEGER REFERENCES recordings(recording_id) ON DELETE SET NULL,
  cloud             BLOB NOT NULL,   -- point cloud
  mesh              BLOB,            -- triangle mesh, optional
  num_points        INTEGER NOT NULL CHECK (num_points >= 0),
  num_triangles     INTEGER NOT NULL CHECK (num_triangles >= 0),
  num_frames_used   INTEGER NOT NULL CHECK (num_frames_used >= 0),
  voxel_size_m      REAL NOT NULL CHECK (voxel_size_m >= 0),  -- 0: not voxelised
  created_unix_ms   INTEGER NOT NULL CHECK (created_unix_ms >= 0)
);

-- Session: reference model registered to a reconstruction. A refinement
-- (e.g. ICP started from a manual pairing) names its parent.
CREATE TABLE alignments (
  alignment_id              INTEGER PRIMARY KEY,
  reconstruction_id         INTEGER NOT NULL
                              REFERENCES reconstructions(reconstruction_id) ON DELETE CASCADE,
  parent_alignment_id       INTEGER REFERENCES alignments(alignment_id) ON DELETE SET NULL,
  method                    TEXT NOT NULL CHECK (method IN ('manual', 'icp', 'automatic')),
  reconstruction_from_model BLOB NOT NULL,  -- 4x4 float64
  fitness                   REAL NOT NULL CHECK (fitness >= 0 AND fitness <= 1),
  rmse_m                    REAL NOT NULL CHECK (rmse_m >= 0),
  num_inliers               INTEGER NOT NULL CHECK (num_inliers >= 0),
  options                   TEXT NOT NULL DEFAULT '',  -- the stage options, YAML
  created_unix_ms           INTEGER NOT NULL CHECK (created_unix_ms >= 0),
  CHECK (parent_alignment_id IS NULL OR parent_alignment_id <> alignment_id)
);

-- Tracking: one positioning run, and one row per processed frame.
CREATE TABLE tracking_runs (
  tracking_run_id INTEGER PRIMARY KEY,
  session_id      INTEGER NOT NULL REFERENCES sessions(session_id) ON DELETE CASCADE,
  alignment_id    INTEGER REFERENCES alignments(alignment_id) ON DELETE SET NULL,
  recording_id    INTEGER REFERENCES recordings(recording_id) ON DELETE SET NULL,
  options         TEXT NOT NULL DEFAULT '',  -- the stage options, YAML
  started_unix_ms INTEGER NOT NULL CHECK (started_unix_ms >= 0)
);

-- status 'lost' means no estimate: then pose and correction are NULL, and
-- only then. Corrections are what the couch must move, room axes.
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
  PRIMARY KEY (tracking_run_id, frame_index),
  CHECK ((status = 'lost') = (room_from_model IS NULL)),
  CHECK ((room_from_model IS NULL) = (correction_tx_mm IS NULL)),
  CHECK ((correction_tx_mm IS NULL) = (correction_ty_mm IS NULL)
     AND (correction_tx_mm IS NULL) = (correction_tz_mm IS NULL)
     AND (correction_tx_mm IS NULL) = (correction_rx_deg IS NULL)
     AND (correction_tx_mm IS NULL) = (correction_ry_deg IS NULL)
     AND (correction_tx_mm IS NULL) = (correction_rz_deg IS NULL))
) WITHOUT ROWID;

-- Append-only record of who did what. AUTOINCREMENT: ids are never reused.
CREATE TABLE audit_log (
  audit_id     INTEGER PRIMARY KEY AUTOINCREMENT,
  time_unix_ms INTEGER NOT NULL CHECK (time_unix_ms >= 0),
  actor        TEXT NOT NULL CHECK (length(actor) > 0),
  action       TEXT NOT NULL CHECK (length(action) > 0),
  entity       TEXT NOT NULL DEFAULT '',  -- e.g. 'plan:3'
  details      TEXT NOT NULL DEFAULT ''
);

-- INSERT OR REPLACE would delete an existing row without firing the delete
-- trigger (SQLite fires it only with recursive_triggers on): refuse reusing an id.
CREATE TRIGGER audit_log_refuse_replace BEFORE INSERT ON audit_log
WHEN EXISTS (SELECT 1 FROM audit_log WHERE audit_id = NEW.audit_id)
BEGIN
  SELECT RAISE(ABORT, 'audit_log is append-only: an existing entry cannot be replaced');
END;

CREATE TRIGGER audit_log_refuse_update BEFORE UPDATE ON audit_log
BEGIN
  SELECT RAISE(ABORT, 'audit_log is append-only: UPDATE refused');
END;

CREATE TRIGGER audit_log_refuse_delete BEFORE DELETE ON audit_log
BEGIN
  SELECT RAISE(ABORT, 'audit_log is append-only: DELETE refused');
END;
