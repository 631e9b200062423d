#pragma once
/// Camera models of the simulator: what turns an exact render into the
/// images an RGB-D camera delivers.
///
/// Colour: linear radiance -> (optional motion blur) -> optical blur
/// (Gaussian) -> exposure (x 2^stops with auto exposure) and vignetting ->
/// shot + read noise in linear units -> camera response (sRGB unless another
/// is asked for, camera_response.h), clipped -> 8-bit BGR.
/// Depth (registered to colour): exact centre-sample z -> noise growing with
/// distance (white + spatially correlated) -> dropouts (random, grazing
/// angles, depth discontinuities, projector shadows for structured light,
/// range limits) or, with flying pixels, a mix of the two depths at some
/// discontinuities -> disparity steps -> optional calibration bias (scale
/// error, smooth error field) -> quantisation to the depth scale.
///
/// Randomness is a pure function of (seed, frame key, pixel): see random.h.

#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <string>

#include "sensor/intrinsics.h"
#include "simulation/camera_response.h"
#include "simulation/rasterizer.h"

namespace arpos::sim {

struct SensorProfile {
  std::string name;                ///< "xtion", "l515" or "d435"
  CameraIntrinsics intrinsics;
  int supersampling = 3;           ///< rasteriser samples per pixel axis
  // Colour.
  double blur_sigma_px = 0.7;      ///< optical blur (Gaussian sigma)
  double exposure = 1.0;           ///< linear radiance -> [0, 1] sensor value
  double vignetting = 0.2;         ///< relative fall-off at the image corner
  double read_noise = 0.8;         ///< sigma, linear 8-bit units
  double shot_noise_gain = 0.06;   ///< variance per linear 8-bit unit
  double exposure_time_s = 0.016;  ///< motion blur window (--hard)
  // Depth.
  double depth_sigma_const_m = 0;      ///< sigma(z) = const + quad * z^2
  double depth_sigma_quad_per_m = 0;
  double depth_correlated_fraction = 0.3;  ///< share of sigma that is smooth
  double depth_correlation_px = 8;     ///< size of the smooth component's cells
  double min_range_m = 0.4, max_range_m = 4.0;
  double grazing_start_deg = 70, grazing_end_deg = 85;  ///< dropout ramps to 1
  double edge_relative_jump = 0.03;    ///< neighbour depth jump that counts as an edge
  double edge_dropout = 0.6;           ///< probability at an edge pixel
  double random_dropout = 0.003;
  double projector_baseline_m = 0;     ///< structured light: shadow band, 0 = none
  /// Structured light measures disparity in steps of 1/disparity_subpixel
  /// px, so depth comes in steps of z^2 / (f b disparity_subpixel) (3 mm at
  /// 1 m for f = 540 px, b = 7.5 cm, 1/8 px): 0 = no disparity quantisation.
  int disparity_subpixel = 0;

  std::string Describe() const;  ///< one line for logs and simulation.yaml
};

/// "xtion" (640x480 structured light, depth_scale 1000), "d435" (848x480,
/// active stereo, an off-centre principal point, depth_scale 1000) or "l515"
/// (1280x720 colour, registered LiDAR depth, depth_scale 4000). Throws
/// InputError for another name.
SensorProfile MakeSensorProfile(const std::string& name);

/// How the colour camera encodes one frame (defaults: sRGB, the profile's
/// exposure).
struct ColorEncoding {
  CameraResponse response = CameraResponse::kSrgb;
  double exposure_stops = 0;  ///< this frame's exposure relative to the profile's
  /// Unsharp masking of the encoded codes, as a camera's processing does it
  /// after its tone curve: code + amount * (code - Gaussian(code, sigma)).
  double sharpen_amount = 0;
  double sharpen_sigma_px = 1.0;
};

/// Linear radiance (CV_32FC3 RGB) -> 8-bit BGR as the camera delivers it:
/// code = round(255 response(clip(radiance x exposure x 2^stops x
/// vignetting + noise))). With `noise` false: no blur, no noise, no
/// vignetting (exact render, encoded by the response). `frame_key`
/// identifies the frame for the noise.
cv::Mat SimulateColor(const cv::Mat& radiance, const SensorProfile& profile, bool noise,
                      uint64_t frame_key, const ColorEncoding& encoding = {});

/// Systematic depth errors of a miscalibrated sensor (all off by default).
/// Reported depth z' = z (1 + scale_error) + field_mm_at_1m / 1000 (z / 1 m)^2
/// F(u, v), with z the sensor's own (noisy, quantised) depth and F a smooth
/// field in [-1, 1] over the image, fixed for the case (MakeDepthErrorField).
/// Flying pixels: at a depth discontinuity (the edge test of the dropouts),
/// half the edge pixels that have a surface behind them report a mixed depth
/// z + u (z_neighbour - z), u uniform in [0.15, 0.85], instead of the dropout
/// test (noise only).
struct DepthBias {
  double scale_error = 0;      ///< e.g. 0.003 = +0.3 %
  double field_mm_at_1m = 0;   ///< amplitude of the smooth field at 1 m
  cv::Mat field;               ///< CV_32F, image size, values in [-1, 1]; needed if field_mm_at_1m != 0
  bool flying_pixels = false;
  bool Any() const { return scale_error != 0 || field_mm_at_1m != 0 || flying_pixels; }
};

/// The smooth field F of DepthBias for a width x height image: a weighted
/// sum of a radial term and three plane waves of at most 1.5 cycles across
/// the image, weights summing to 1 in absolute value (so |F| <= 1).
cv::Mat MakeDepthErrorField(int width, int height, uint64_t seed);

/// Exact depth (CV_32F metres, 0 = none) and normals -> 16-bit depth PNG
/// values. With `noise` false: only range limits, the bias (scale and field)
/// and rounding to the depth scale.
cv::Mat SimulateDepth(const RenderOutput& render, const SensorProfile& profile, bool noise,
                      uint64_t frame_key, const DepthBias& bias = {});

/// Motion blur along the actual image motion. For each pixel, the point seen
/// at its centre (depth, label) moves rigidly with its object: `motion(label,
/// dt)` returns camera(t + dt) <- camera(t) for points of that label (the
/// camera's own motion composed with the object's). The radiance is averaged
/// along the resulting image path over [-exposure/2, +exposure/2] (`taps`
/// samples). Pixels without depth keep their value.
using LabelMotion = std::function<Rigid3d(int label, double dt_s)>;
cv::Mat ApplyMotionBlur(const cv::Mat& radiance, const RenderOutput& render,
                        const CameraIntrinsics& intrinsics, double exposure_s,
                        const LabelMotion& motion, int max_label, int taps = 9);

}  // namespace arpos::sim
