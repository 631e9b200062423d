-- Schema version 4: what planning measures about the camera, and how well
-- the room frame itself is known, kept with the room map.
--
-- Later stages (a session, `arpos localize`) read the camera's colour
-- response and depth error from the room map when their own recording cannot
-- tell; without these columns they fell back to the defaults.
--
--   camera_response   the colour camera's response, one line as written by
--                     CameraResponse::Serialize (features/camera_response.h):
--                     "name: v0 v1 ... v255", linear value per 8-bit code
--   depth_correction  the depth camera's systematic error measured against
--                     the room's markers, one line as written by
--                     DepthCorrection::Serialize (sensor/depth_correction.h)
--   room_frame_tilt_sigma_deg, room_frame_yaw_sigma_deg
--                     the origin marker's pose uncertainty (1 sigma): tilt
--                     about its in-plane axes, yaw about its normal
--   room_frame_couch_sigma_mm
--                     the position error this gives at the plan's isocentre
--
-- NULL means not recorded: maps stored before this migration read back with
-- an sRGB response, no depth correction and an unknown room-frame
-- uncertainty.

ALTER TABLE room_maps ADD COLUMN camera_response TEXT
  CHECK (camera_response IS NULL OR length(camera_response) > 0);
ALTER TABLE room_maps ADD COLUMN depth_correction TEXT
  CHECK (depth_correction IS NULL OR length(depth_correction) > 0);
ALTER TABLE room_maps ADD COLUMN room_frame_tilt_sigma_deg REAL
  CHECK (room_frame_tilt_sigma_deg IS NULL OR room_frame_tilt_sigma_deg >= 0);
ALTER TABLE room_maps ADD COLUMN room_frame_yaw_sigma_deg REAL
  CHECK (room_frame_yaw_sigma_deg IS NULL OR room_frame_yaw_sigma_deg >= 0);
ALTER TABLE room_maps ADD COLUMN room_frame_couch_sigma_mm REAL
  CHECK (room_frame_couch_sigma_mm IS NULL OR room_frame_couch_sigma_mm >= 0);
