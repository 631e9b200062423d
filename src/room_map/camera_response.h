#pragma once
/// Camera response: 8-bit sRGB-encoded grey values back to (scaled) linear
/// intensity before marker corners are measured.
///
/// Why: cameras encode intensity with a gamma curve, and an edge blurred by
/// the optics in linear light then gamma-encoded has its 50 % grey point on
/// the dark side of the true edge. For a black-on-white marker with ~0.7 px
/// blur this moves every edge ~0.5-0.7 px into the black square: measured on
/// our simulated cases, edge-fit corners sat ~0.7 px inside the true square
/// (a 2-3 % scale error, 30-50 mm of depth at 1.5 m); after linearisation they
/// were within 0.01-0.03 px. The features layer's edge model assumes a linear
/// response (features/edge_refinement.h: "Not modelled: camera gamma").

#include <opencv2/core.hpp>

namespace arpos {

/// The 256-entry table sRGB-encoded value -> linear value * 255 (rounded).
const cv::Mat& SrgbToLinearLut();

/// `gray` (CV_8UC1) mapped through SrgbToLinearLut into `linear` (may alias).
void LinearizeSrgb(const cv::Mat& gray, cv::Mat* linear);

}  // namespace arpos
