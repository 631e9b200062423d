#pragma once
/// Procedural, deterministic textures for the simulated treatment room and
/// printed ArUco markers.

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>

#include "simulation/render_scene.h"

namespace arpos::sim {

/// Converts an 8-bit BGR image (row 0 = top = v 0) to a texture.
Texture TextureFromBgr(const cv::Mat& bgr, bool nearest, bool wrap);

/// A printed ArUco marker on white paper, sampled nearest so that every black
/// cell edge lies exactly on a texel boundary.
///
/// Layout in cells (one cell = marker side / 6 for a 4x4 dictionary): the
/// 6x6-cell marker (with its one-cell black border) is surrounded by
/// `quiet_cells` of white paper on every side; `label_cells` more cells of
/// paper below it carry a printed caption (e.g. "ROOM 7"), or none if 0.
/// `texels_per_cell` sets the resolution. The texture is
/// (6 + 2 q) x (6 + 2 q + label) cells. Throws arpos::Error for an unknown
/// dictionary or an id out of range.
struct MarkerArtwork {
  Texture texture;
  int marker_cells = 6;       ///< cells across the black square, border included
  int quiet_cells = 1;
  int label_cells = 0;
  /// Texture uv of the black square's corners, OpenCV ArUco order: top-left,
  /// top-right, bottom-right, bottom-left of the printed marker.
  cv::Point2f uv_corners[4];
};
MarkerArtwork MakeMarkerArtwork(int dictionary_id, int marker_id, int quiet_cells, int label_cells,
                                int texels_per_cell, const std::string& caption);

enum class SurfaceStyle { kFloor, kWall, kCeiling, kCouchTop, kCouchBase, kGantry };

/// How much a room's surfaces show. kRich: posters, signs, scattered shapes
/// and strong mottling on every surface (a cluttered room, many keypoints).
/// kPlain: a painted bunker: low-contrast mottling, the floor's and ceiling's
/// tile seams, the gantry's panels and one label, nothing scattered, no
/// posters (few keypoints: the markers and the room's shape must carry).
enum class TextureDetail { kRich, kPlain };

/// A surface of `width_m` x `height_m` at `texel_m` per texel. Rich:
/// multi-scale noise plus random shapes, posters and signs (walls), tiles
/// and scuffs (floor), an indexed carbon-fibre look (couch top); plain: see
/// TextureDetail (the couch top, which moves with the patient, stays as it
/// is). Same seed and detail, same texture.
Texture MakeSurfaceTexture(SurfaceStyle style, double width_m, double height_m, double texel_m,
                           uint64_t seed, TextureDetail detail = TextureDetail::kRich);

}  // namespace arpos::sim
