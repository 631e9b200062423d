#pragma once
/// Image keypoints for the room map and for localisation: FAST corners spread
/// over an image grid, oriented BRIEF (ORB) descriptors, depth at each corner.
///
/// One pyramid level only: localisation must run at video rate on one core
/// (cv::ORB with 8 levels costs ~10x more), and the room map is built and used
/// at similar distances (0.6-3 m). Descriptors are OpenCV's ORB (32 bytes,
/// patch 31) so they can be matched with cv::NORM_HAMMING anywhere.
///
/// Pixel convention: OpenCV (centre of the top-left pixel at (0, 0)); FAST
/// corners are at integer pixels.

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace arpos {

struct KeypointOptions {
  int max_keypoints = 1000;
  /// The image is cut into cells of about this size; each cell keeps its
  /// strongest corners first, so keypoints spread over the whole image.
  int grid_cell_px = 40;
  int fast_threshold = 20;
  /// Cells with no corner at fast_threshold are searched again at this one.
  int min_fast_threshold = 8;
  /// Keypoints closer than this to the border get no descriptor (ORB needs 19).
  int border_px = 20;
  /// Depth at a keypoint is valid only if its 3x3 neighbourhood is complete and
  /// spans less than this fraction of the depth (rejects depth edges).
  double max_depth_relative_span = 0.03;
  /// Refine corners to sub-pixel positions (cv::cornerSubPix, small window):
  /// FAST corners sit on integer pixels (0.3 px RMS quantisation). Off by
  /// default: on simulated cases it cost 1.5 ms per frame and did not help.
  bool subpixel = false;
  int subpixel_half_window_px = 2;
  double min_depth_m = 0.2;
  double max_depth_m = 8.0;
  /// FAST thresholds are grey-level differences: an underexposed image (a
  /// camera with a linear response, auto exposure set by a window) puts the
  /// room in a few dozen grey levels, where they find few corners. The grey
  /// levels between the image's `contrast_percentile` and
  /// 100 - `contrast_percentile` percentiles are stretched to 0-255 first,
  /// by at most `max_contrast_gain` (noise is stretched too). ORB
  /// descriptors compare intensities and are unchanged by the stretch up to
  /// rounding, so maps built without it still match. 1: off.
  double max_contrast_gain = 4.0;
  double contrast_percentile = 1.0;

  std::string Validate() const;
  bool Check(std::string* reason = nullptr) const;
};

/// Keypoints of one image. `keypoints[i]`, descriptor row i and `depth_m[i]`
/// belong together; depth 0 = no valid reading.
struct KeypointSet {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;  ///< CV_8UC1, N x 32
  std::vector<float> depth_m;
  int image_width = 0, image_height = 0;

  size_t size() const { return keypoints.size(); }
  void clear();
};

/// Indices of keypoints by grid cell, for searches around a predicted pixel.
class KeypointGrid {
 public:
  void Build(const KeypointSet& set, int cell_px = 16);
  /// Calls f(i) for every keypoint within `radius_px` of (u, v).
  template <typename F>
  void ForEachInRadius(double u, double v, double radius_px, F&& f) const;

 private:
  const KeypointSet* set_ = nullptr;
  int cell_px_ = 16, cols_ = 0, rows_ = 0;
  std::vector<int> cell_start_;  ///< CSR: cell c holds order_[cell_start_[c] .. cell_start_[c+1])
  std::vector<int> order_;
};

/// Extracts keypoints frame after frame, reusing buffers. Not thread-safe.
class KeypointExtractor {
 public:
  explicit KeypointExtractor(const KeypointOptions& options = {});
  /// `gray` CV_8UC1; `depth` CV_16UC1 registered to it (`depth_scale` units
  /// per metre) or empty. Throws arpos::Error for wrong types or sizes.
  void Extract(const cv::Mat& gray, const cv::Mat& depth, double depth_scale, KeypointSet* out);
  /// The depth of each keypoint of `set` (as Extract reads it) from `depth`
  /// (CV_16UC1 of the image's size, or empty: no depth); for keypoints found
  /// before in the same colour image, with other depth.
  void ReadDepth(const cv::Mat& depth, double depth_scale, KeypointSet* set) const;
  const KeypointOptions& options() const { return options_; }

 private:
  KeypointOptions options_;
  cv::Ptr<cv::ORB> orb_;
  std::vector<cv::KeyPoint> candidates_;
  std::vector<std::vector<int>> cells_;
  std::vector<int> umax_;
  std::vector<cv::Point2f> points_;
  cv::Mat stretched_;
};

/// The nearest and second-nearest of descriptors offered one by one (for the
/// ratio test): `best` is the index offered with the smallest distance `d1`,
/// `d2` the next smallest distance; 257 (beyond any 256-bit distance) until
/// offered.
struct NearestTwo {
  int best = -1;
  int d1 = 257, d2 = 257;
  void Offer(int index, int distance) {
    if (distance < d1) {
      d2 = d1;
      d1 = distance;
      best = index;
    } else if (distance < d2) {
      d2 = distance;
    }
  }
};

/// The nearest two of rows offered as `earlier` and then as `later`, from
/// the nearest two of each: what offering them all one by one gives (the
/// first of equally near rows is `best`).
inline NearestTwo MergeNearestTwo(const NearestTwo& earlier, const NearestTwo& later) {
  NearestTwo out;
  if (later.d1 < earlier.d1) {
    out.best = later.best;
    out.d1 = later.d1;
    out.d2 = std::min(earlier.d1, later.d2);
  } else {
    out.best = earlier.best;
    out.d1 = earlier.d1;
    out.d2 = std::min(earlier.d2, later.d1);
  }
  return out;
}

/// Hamming distance of two 32-byte descriptors. On x86-64 with SSE2 only
/// (Debian's baseline has no POPCNT instruction, so __builtin_popcountll
/// becomes a bit-twiddling call per word): a byte-wise bit count in two
/// 128-bit registers summed by PSADBW, about 5x faster than the scalar
/// fallback (1000 x 4000 descriptors: 87 -> 17 ms). The brute-force search
/// against the whole map has a faster path of its own (NearestTwoOfRows).
inline int HammingDistance32(const std::uint8_t* a, const std::uint8_t* b) {
#if defined(__SSE2__)
  const __m128i m1 = _mm_set1_epi8(0x55), m2 = _mm_set1_epi8(0x33), m4 = _mm_set1_epi8(0x0f);
  __m128i x0 = _mm_xor_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(a)),
                             _mm_loadu_si128(reinterpret_cast<const __m128i*>(b)));
  __m128i x1 = _mm_xor_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(a + 16)),
                             _mm_loadu_si128(reinterpret_cast<const __m128i*>(b + 16)));
  x0 = _mm_sub_epi8(x0, _mm_and_si128(_mm_srli_epi64(x0, 1), m1));
  x1 = _mm_sub_epi8(x1, _mm_and_si128(_mm_srli_epi64(x1, 1), m1));
  x0 = _mm_add_epi8(_mm_and_si128(x0, m2), _mm_and_si128(_mm_srli_epi64(x0, 2), m2));
  x1 = _mm_add_epi8(_mm_and_si128(x1, m2), _mm_and_si128(_mm_srli_epi64(x1, 2), m2));
  // Bits per byte (<= 8 each), then both halves added (<= 16, no overflow).
  x0 = _mm_and_si128(_mm_add_epi8(x0, _mm_srli_epi64(x0, 4)), m4);
  x1 = _mm_and_si128(_mm_add_epi8(x1, _mm_srli_epi64(x1, 4)), m4);
  const __m128i s = _mm_sad_epu8(_mm_add_epi8(x0, x1), _mm_setzero_si128());
  return _mm_cvtsi128_si32(s) + _mm_cvtsi128_si32(_mm_srli_si128(s, 8));
#else
  int d = 0;
  for (int k = 0; k < 4; ++k) {
    std::uint64_t x, y;
    __builtin_memcpy(&x, a + 8 * k, 8);
    __builtin_memcpy(&y, b + 8 * k, 8);
    d += __builtin_popcountll(x ^ y);
  }
  return d;
#endif
}

/// The two rows of `descriptors` (CV_8U, 32 columns: ORB) in [first, last)
/// nearest to the 32-byte `query`, as offering each row's HammingDistance32
/// in row order would give them (the same result to the bit; rows outside
/// the matrix are not read). Brute-force relocalisation matches every
/// keypoint of a frame against the whole map here. With AVX2 (checked once
/// at run time; Debian's baseline build has only SSE2) a descriptor fits one
/// register: 1000 x 4000 descriptors 9.0 -> 4.3 ms
/// (`localize_bench --benchmark_filter=NearestTwo`).
NearestTwo NearestTwoOfRows(const std::uint8_t* query, const cv::Mat& descriptors, int first,
                            int last);
/// Whether NearestTwoOfRows uses AVX2 on this processor.
bool NearestTwoOfRowsUsesAvx2();
/// NearestTwoOfRows without AVX2 (HammingDistance32 row by row): the
/// reference it is tested and benchmarked against.
NearestTwo NearestTwoOfRowsPortable(const std::uint8_t* query, const cv::Mat& descriptors,
                                    int first, int last);

/// Depth (m) at integer pixel (u, v) if its 3x3 neighbourhood is valid and
/// smooth (see KeypointOptions), else 0.
float SmoothDepthAt(const cv::Mat& depth, int u, int v, double depth_scale,
                    const KeypointOptions& options);

// ---------------------------------------------------------------- inline

template <typename F>
void KeypointGrid::ForEachInRadius(double u, double v, double radius_px, F&& f) const {
  if (set_ == nullptr || cols_ == 0) return;
  const int c0 = std::max(0, static_cast<int>((u - radius_px) / cell_px_));
  const int c1 = std::min(cols_ - 1, static_cast<int>((u + radius_px) / cell_px_));
  const int r0 = std::max(0, static_cast<int>((v - radius_px) / cell_px_));
  const int r1 = std::min(rows_ - 1, static_cast<int>((v + radius_px) / cell_px_));
  const double r2 = radius_px * radius_px;
  for (int r = r0; r <= r1; ++r) {
    for (int c = c0; c <= c1; ++c) {
      const int cell = r * cols_ + c;
      for (int k = cell_start_[cell]; k < cell_start_[cell + 1]; ++k) {
        const int i = order_[k];
        const double du = set_->keypoints[i].pt.x - u, dv = set_->keypoints[i].pt.y - v;
        if (du * du + dv * dv <= r2) f(i);
      }
    }
  }
}

}  // namespace arpos
