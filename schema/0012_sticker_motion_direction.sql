-- Schema version 12: which way each breathing sticker moved during the body
-- scan (body_model/sticker_motion.h), measured from its corners, for
-- tracking to let it move that way.
--
-- body_marker_motion_direction: per sticker of a body marker map whose
-- direction the scan determined, the unit direction in the sticker's own
-- frame (x, y, z; (0, 0, 1) is its normal). The sticker has a
-- body_marker_motion row (how far, along this direction). A moving sticker
-- without a row moves along its normal; maps stored before this migration
-- have no rows.
CREATE TABLE body_marker_motion_direction (
  body_marker_map_id INTEGER NOT NULL,
  marker_id          INTEGER NOT NULL,
  x                  REAL NOT NULL,
  y                  REAL NOT NULL,
  z                  REAL NOT NULL,
  CHECK (abs(x * x + y * y + z * z - 1) < 1e-6),
  PRIMARY KEY (body_marker_map_id, marker_id),
  FOREIGN KEY (body_marker_map_id, marker_id)
    REFERENCES body_marker_motion(body_marker_map_id, marker_id) ON DELETE CASCADE
) WITHOUT ROWID;
-- Part of a body marker map's audited row hash (store/audit_chain.cc); a map
-- without rows hashes as before.
