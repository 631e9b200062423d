-- Schema version 10: the room's still surface near the couch, as the room
-- recording's depth showed it (room_map/room_surface.h), for the camera
-- localiser to register tracking depth to.
--
-- room_map_surface: at most one row per room map: the voxel size the
-- surface was gathered on (metres) and its points with their normals in the
-- room frame (a point cloud blob with normals, store/blob_codec.h). Maps
-- stored before this migration have no row and localise without it.
CREATE TABLE room_map_surface (
  room_map_id INTEGER PRIMARY KEY
                REFERENCES room_maps(room_map_id) ON DELETE CASCADE,
  voxel_m     REAL NOT NULL CHECK (voxel_m > 0 AND voxel_m < 1),
  points      BLOB NOT NULL  -- point cloud with normals
);
-- Part of a room map's audited row hash (store/audit_chain.cc); a map
-- without a row hashes as before.
