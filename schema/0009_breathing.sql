-- Schema version 9: breathing measured in the body scan (the session stage,
-- body_model/surface_motion.h), for tracking to take into account.
--
-- body_marker_motion: per sticker of a body marker map that moved with the
-- breathing during the scan, how far along its normal (1 sigma over the
-- scan, metres). A sticker without a row did not move (or nothing could be
-- told); maps stored before this migration have no rows.
CREATE TABLE body_marker_motion (
  body_marker_map_id INTEGER NOT NULL
                       REFERENCES body_marker_maps(body_marker_map_id) ON DELETE CASCADE,
  marker_id          INTEGER NOT NULL CHECK (marker_id >= 0),
  motion_m           REAL NOT NULL CHECK (motion_m > 0 AND motion_m < 0.05),
  PRIMARY KEY (body_marker_map_id, marker_id)
) WITHOUT ROWID;

-- body_surface_motion: the patches of the reference model's surface that
-- moved during the scan: cubes of side patch_m (metres) in the model frame,
-- given by their centres (moving_patches: N x 3 float64, x, y, z a row). At
-- most one row per map; none when nothing moved or nothing could be told.
CREATE TABLE body_surface_motion (
  body_marker_map_id INTEGER PRIMARY KEY
                       REFERENCES body_marker_maps(body_marker_map_id) ON DELETE CASCADE,
  patch_m            REAL NOT NULL CHECK (patch_m > 0),
  moving_patches     BLOB NOT NULL  -- N x 3 float64
);
-- Both tables are part of a body marker map's audited row hash
-- (store/audit_chain.cc); a map without rows in them hashes as before.
