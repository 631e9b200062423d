-- Schema version 11: the room around the couch as the body scan saw it
-- (room_map/scan_landmarks.h): keypoint landmarks placed from the scan's
-- frames, for tracking to localise the camera where the room recording
-- saw little.
--
-- body_scan_landmarks: at most one row per body marker map: the landmarks'
-- positions in the room frame (a point cloud blob, store/blob_codec.h) and,
-- row for row, their ORB descriptors (a byte matrix blob, N x 32), as the
-- room map keeps its own; how well they sit in the room (1 sigma, metres):
-- placement_sigma_m, all together, as the session placed its scan (at the
-- stickers); position_sigma_m, each on its own (how far its views disagree,
-- the median over the landmarks). Maps stored before this migration, or
-- whose scan placed none, have no row.
CREATE TABLE body_scan_landmarks (
  body_marker_map_id INTEGER PRIMARY KEY
                       REFERENCES body_marker_maps(body_marker_map_id) ON DELETE CASCADE,
  placement_sigma_m  REAL NOT NULL CHECK (placement_sigma_m >= 0 AND placement_sigma_m < 1),
  position_sigma_m   REAL NOT NULL CHECK (position_sigma_m >= 0 AND position_sigma_m < 1),
  points             BLOB NOT NULL,  -- point cloud
  descriptors        BLOB NOT NULL   -- N x 32 bytes
);
-- Part of a body marker map's audited row hash (store/audit_chain.cc); a map
-- without a row hashes as before.
