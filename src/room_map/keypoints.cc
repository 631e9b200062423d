#include "room_map/keypoints.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <opencv2/imgproc.hpp>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define ARPOS_HAVE_AVX2_PATH 1
#endif

#include "util/check.h"

namespace arpos {
namespace {

constexpr int kHalfPatch = 15;  // ORB patch 31

// Orientation by intensity centroid over ORB's circular patch (Rublee et al.).
float IntensityCentroidAngleDeg(const cv::Mat& gray, int u, int v, const std::vector<int>& umax) {
  int m01 = 0, m10 = 0;
  const uchar* center = gray.ptr<uchar>(v) + u;
  for (int du = -kHalfPatch; du <= kHalfPatch; ++du) m10 += du * center[du];
  const int step = static_cast<int>(gray.step1());
  for (int dv = 1; dv <= kHalfPatch; ++dv) {
    int v_sum = 0;
    const int d = umax[dv];
    for (int du = -d; du <= d; ++du) {
      const int val_plus = center[du + dv * step], val_minus = center[du - dv * step];
      v_sum += val_plus - val_minus;
      m10 += du * (val_plus + val_minus);
    }
    m01 += dv * v_sum;
  }
  return cv::fastAtan2(static_cast<float>(m01), static_cast<float>(m10));
}

}  // namespace

std::string KeypointOptions::Validate() const {
  std::ostringstream out;
  if (max_keypoints <= 0) out << "max_keypoints must be positive, got " << max_keypoints;
  else if (grid_cell_px < 8) out << "grid_cell_px must be at least 8, got " << grid_cell_px;
  else if (fast_threshold < 1 || min_fast_threshold < 1 || min_fast_threshold > fast_threshold)
    out << "FAST thresholds must satisfy 1 <= min_fast_threshold <= fast_threshold";
  else if (border_px < 19) out << "border_px must be at least 19 (ORB patch), got " << border_px;
  else if (!(max_depth_relative_span > 0)) out << "max_depth_relative_span must be positive";
  else if (!(min_depth_m >= 0 && max_depth_m > min_depth_m)) out << "depth range is empty";
  else if (!(max_contrast_gain >= 1))
    out << "max_contrast_gain must be at least 1, got " << max_contrast_gain;
  else if (!(contrast_percentile >= 0 && contrast_percentile < 50))
    out << "contrast_percentile must be in [0, 50), got " << contrast_percentile;
  return out.str();
}

bool KeypointOptions::Check(std::string* reason) const {
  const std::string r = Validate();
  if (reason) *reason = r;
  return r.empty();
}

void KeypointSet::clear() {
  keypoints.clear();
  descriptors.release();
  depth_m.clear();
}

void KeypointGrid::Build(const KeypointSet& set, int cell_px) {
  set_ = &set;
  cell_px_ = cell_px;
  cols_ = std::max(1, (set.image_width + cell_px - 1) / cell_px);
  rows_ = std::max(1, (set.image_height + cell_px - 1) / cell_px);
  const int n_cells = cols_ * rows_;
  cell_start_.assign(n_cells + 1, 0);
  std::vector<int> cell_of(set.size());
  for (size_t i = 0; i < set.size(); ++i) {
    const int c = std::clamp(static_cast<int>(set.keypoints[i].pt.x) / cell_px, 0, cols_ - 1);
    const int r = std::clamp(static_cast<int>(set.keypoints[i].pt.y) / cell_px, 0, rows_ - 1);
    cell_of[i] = r * cols_ + c;
    ++cell_start_[cell_of[i] + 1];
  }
  for (int c = 0; c < n_cells; ++c) cell_start_[c + 1] += cell_start_[c];
  order_.assign(set.size(), 0);
  std::vector<int> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (size_t i = 0; i < set.size(); ++i) order_[fill[cell_of[i]]++] = static_cast<int>(i);
}

float SmoothDepthAt(const cv::Mat& depth, int u, int v, double depth_scale,
                    const KeypointOptions& options) {
  if (depth.empty() || u < 1 || v < 1 || u >= depth.cols - 1 || v >= depth.rows - 1) return 0;
  int lo = 65535, hi = 0;
  for (int dv = -1; dv <= 1; ++dv) {
    const uint16_t* row = depth.ptr<uint16_t>(v + dv);
    for (int du = -1; du <= 1; ++du) {
      const int d = row[u + du];
      if (d == 0) return 0;
      lo = std::min(lo, d);
      hi = std::max(hi, d);
    }
  }
  const double z = depth.ptr<uint16_t>(v)[u] / depth_scale;
  if (z < options.min_depth_m || z > options.max_depth_m) return 0;
  if ((hi - lo) / depth_scale > options.max_depth_relative_span * z) return 0;
  return static_cast<float>(z);
}

KeypointExtractor::KeypointExtractor(const KeypointOptions& options) : options_(options) {
  std::string reason;
  ARPOS_CHECK(options_.Check(&reason), "invalid keypoint options: " << reason);
  // One level, no own detection (we give it our corners): only its descriptor.
  orb_ = cv::ORB::create(options_.max_keypoints, 1.2f, 1, 19, 0, 2, cv::ORB::FAST_SCORE, 31,
                         options_.fast_threshold);
  umax_.assign(kHalfPatch + 2, 0);
  const int vmax = cvFloor(kHalfPatch * std::sqrt(2.0) / 2 + 1);
  const int vmin = cvCeil(kHalfPatch * std::sqrt(2.0) / 2);
  for (int v = 0; v <= vmax; ++v) umax_[v] = cvRound(std::sqrt(double(kHalfPatch * kHalfPatch - v * v)));
  for (int v = kHalfPatch, v0 = 0; v >= vmin; --v) {
    while (umax_[v0] == umax_[v0 + 1]) ++v0;
    umax_[v] = v0;
    ++v0;
  }
}

namespace {

// `gray` with the grey levels between its `percentile` and 100 - `percentile`
// percentiles stretched to 0-255, by at most `max_gain`; `gray` itself when
// that would change little.
const cv::Mat& StretchContrast(const cv::Mat& gray, double percentile, double max_gain,
                               cv::Mat* buffer) {
  if (!(max_gain > 1) || gray.empty()) return gray;
  // Every 4th pixel of every 4th row of a 640x480 or larger image (0.05 ms
  // where the whole image took 0.6 ms at 1280x720).
  const int step = gray.cols >= 640 && gray.rows >= 480 ? 4 : 1;
  int histogram[256] = {0};
  double total = 0;
  for (int r = 0; r < gray.rows; r += step) {
    const std::uint8_t* row = gray.ptr<std::uint8_t>(r);
    for (int c = 0; c < gray.cols; c += step) ++histogram[row[c]], ++total;
  }
  const double cut = total * percentile / 100.0;
  int lo = 0, hi = 255;
  for (double below = 0; lo < 255 && below + histogram[lo] <= cut; ++lo) below += histogram[lo];
  for (double above = 0; hi > 0 && above + histogram[hi] <= cut; --hi) above += histogram[hi];
  if (hi <= lo) return gray;
  const double gain = std::min(max_gain, 255.0 / (hi - lo));
  if (gain < 1.1) return gray;
  // Centred on the range kept, so a capped gain does not clip one end.
  const double offset = 127.5 - gain * 0.5 * (lo + hi);
  gray.convertTo(*buffer, CV_8U, gain, offset);
  return *buffer;
}

}  // namespace

void KeypointExtractor::Extract(const cv::Mat& input_gray, const cv::Mat& depth, double depth_scale,
                                KeypointSet* out) {
  ARPOS_CHECK(out != nullptr, "Extract needs an output set");
  ARPOS_CHECK(input_gray.type() == CV_8UC1,
              "keypoints need an 8-bit grey image, got type " << input_gray.type());
  const cv::Mat& gray = StretchContrast(input_gray, options_.contrast_percentile,
                                        options_.max_contrast_gain, &stretched_);
  ARPOS_CHECK(depth.empty() || (depth.type() == CV_16UC1 && depth.size() == gray.size()),
              "depth must be CV_16UC1 of the image's size");
  out->clear();
  out->image_width = gray.cols;
  out->image_height = gray.rows;
  const int border = options_.border_px;
  if (gray.cols <= 2 * border || gray.rows <= 2 * border) return;

  cv::FAST(gray, candidates_, options_.fast_threshold, true);
  const int cell = options_.grid_cell_px;
  const int cols = (gray.cols + cell - 1) / cell, rows = (gray.rows + cell - 1) / cell;
  cells_.assign(cols * rows, {});
  auto cell_index = [&](const cv::KeyPoint& k) {
    return std::min(rows - 1, static_cast<int>(k.pt.y) / cell) * cols +
           std::min(cols - 1, static_cast<int>(k.pt.x) / cell);
  };
  auto inside = [&](const cv::KeyPoint& k) {
    return k.pt.x >= border && k.pt.y >= border && k.pt.x < gray.cols - border &&
           k.pt.y < gray.rows - border;
  };
  std::vector<cv::KeyPoint> all;
  all.reserve(candidates_.size());
  for (const auto& k : candidates_) {
    if (!inside(k)) continue;
    cells_[cell_index(k)].push_back(static_cast<int>(all.size()));
    all.push_back(k);
  }
  // Low-contrast cells (walls, floor) get a second, more sensitive pass.
  if (options_.min_fast_threshold < options_.fast_threshold) {
    bool any_empty = false;
    for (const auto& c : cells_) any_empty |= c.empty();
    if (any_empty) {
      for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < cols; ++c) {
          if (!cells_[r * cols + c].empty()) continue;
          const int x0 = std::max(border - 3, c * cell - 3), y0 = std::max(border - 3, r * cell - 3);
          const int x1 = std::min(gray.cols - border + 3, (c + 1) * cell + 3);
          const int y1 = std::min(gray.rows - border + 3, (r + 1) * cell + 3);
          if (x1 - x0 < 8 || y1 - y0 < 8) continue;
          std::vector<cv::KeyPoint> local;
          cv::FAST(gray(cv::Rect(x0, y0, x1 - x0, y1 - y0)), local, options_.min_fast_threshold, true);
          for (auto k : local) {
            k.pt.x += x0;
            k.pt.y += y0;
            if (!inside(k) || cell_index(k) != r * cols + c) continue;
            cells_[r * cols + c].push_back(static_cast<int>(all.size()));
            all.push_back(k);
          }
        }
      }
    }
  }
  // Round-robin over cells by strength: every cell's best first, then second...
  for (auto& c : cells_) {
    std::sort(c.begin(), c.end(), [&](int a, int b) { return all[a].response > all[b].response; });
  }
  std::vector<cv::KeyPoint>& chosen = out->keypoints;
  chosen.reserve(options_.max_keypoints);
  for (size_t rank = 0; static_cast<int>(chosen.size()) < options_.max_keypoints; ++rank) {
    // Within a rank, strongest cells first so a cut-off keeps the best.
    std::vector<int> layer;
    for (const auto& c : cells_) {
      if (rank < c.size()) layer.push_back(c[rank]);
    }
    if (layer.empty()) break;
    std::sort(layer.begin(), layer.end(), [&](int a, int b) { return all[a].response > all[b].response; });
    for (int i : layer) {
      if (static_cast<int>(chosen.size()) >= options_.max_keypoints) break;
      cv::KeyPoint k = all[i];
      k.size = 31;
      k.octave = 0;
      k.angle = IntensityCentroidAngleDeg(gray, cvRound(k.pt.x), cvRound(k.pt.y), umax_);
      chosen.push_back(k);
    }
  }
  if (chosen.empty()) return;
  orb_->compute(gray, chosen, out->descriptors);
  if (options_.subpixel && !chosen.empty()) {
    // After the descriptors (computed about the integer corner, as in the map).
    points_.resize(chosen.size());
    for (size_t i = 0; i < chosen.size(); ++i) points_[i] = chosen[i].pt;
    const int w = options_.subpixel_half_window_px;
    cv::cornerSubPix(gray, points_, cv::Size(w, w), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 10, 0.01));
    for (size_t i = 0; i < chosen.size(); ++i) {
      // A corner that wanders off is not a corner cornerSubPix can place: keep FAST's.
      if (std::abs(points_[i].x - chosen[i].pt.x) < 1.0f && std::abs(points_[i].y - chosen[i].pt.y) < 1.0f) {
        chosen[i].pt = points_[i];
      }
    }
  }
  ReadDepth(depth, depth_scale, out);
}

void KeypointExtractor::ReadDepth(const cv::Mat& depth, double depth_scale,
                                  KeypointSet* set) const {
  ARPOS_CHECK(set != nullptr, "ReadDepth needs a keypoint set");
  ARPOS_CHECK(depth.empty() || (depth.type() == CV_16UC1 && depth.cols == set->image_width &&
                                depth.rows == set->image_height),
              "depth must be CV_16UC1 of the image's size");
  set->depth_m.resize(set->keypoints.size());
  for (size_t i = 0; i < set->keypoints.size(); ++i) {
    set->depth_m[i] = SmoothDepthAt(depth, cvRound(set->keypoints[i].pt.x),
                                    cvRound(set->keypoints[i].pt.y), depth_scale, options_);
  }
}

NearestTwo NearestTwoOfRowsPortable(const std::uint8_t* query, const cv::Mat& descriptors,
                                    int first, int last) {
  first = std::max(first, 0);
  last = std::min(last, descriptors.rows);
  NearestTwo nearest;
  for (int l = first; l < last; ++l) {
    nearest.Offer(l, HammingDistance32(query, descriptors.ptr<std::uint8_t>(l)));
  }
  return nearest;
}

namespace {

#if defined(ARPOS_HAVE_AVX2_PATH)
// A descriptor in one 256-bit register: the XOR's bits counted per nibble by
// table lookup (PSHUFB), summed by PSADBW.
__attribute__((target("avx2"))) NearestTwo NearestTwoOfRowsAvx2(const std::uint8_t* query,
                                                                const cv::Mat& descriptors,
                                                                int first, int last) {
  const __m256i table = _mm256_setr_epi8(0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4, 0, 1, 1, 2,
                                         1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4);
  const __m256i nibble = _mm256_set1_epi8(0x0f);
  const __m256i q = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(query));
  NearestTwo nearest;
  for (int l = first; l < last; ++l) {
    const __m256i x = _mm256_xor_si256(
        q, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(descriptors.ptr<std::uint8_t>(l))));
    const __m256i bits = _mm256_add_epi8(
        _mm256_shuffle_epi8(table, _mm256_and_si256(x, nibble)),
        _mm256_shuffle_epi8(table, _mm256_and_si256(_mm256_srli_epi16(x, 4), nibble)));
    const __m256i sums = _mm256_sad_epu8(bits, _mm256_setzero_si256());
    const __m128i half =
        _mm_add_epi64(_mm256_castsi256_si128(sums), _mm256_extracti128_si256(sums, 1));
    nearest.Offer(l, _mm_cvtsi128_si32(half) + _mm_cvtsi128_si32(_mm_srli_si128(half, 8)));
  }
  return nearest;
}
#endif

}  // namespace

bool NearestTwoOfRowsUsesAvx2() {
#if defined(ARPOS_HAVE_AVX2_PATH)
  static const bool avx2 = __builtin_cpu_supports("avx2");
  return avx2;
#else
  return false;
#endif
}

NearestTwo NearestTwoOfRows(const std::uint8_t* query, const cv::Mat& descriptors, int first,
                            int last) {
  first = std::max(first, 0);
  last = std::min(last, descriptors.rows);
  if (first >= last) return NearestTwo();  // nothing to read (an empty map)
  ARPOS_CHECK(descriptors.type() == CV_8UC1 && descriptors.cols == 32,
              "NearestTwoOfRows needs 32-byte descriptors (CV_8U), got type "
                  << descriptors.type() << " with " << descriptors.cols << " columns");
#if defined(ARPOS_HAVE_AVX2_PATH)
  if (NearestTwoOfRowsUsesAvx2()) return NearestTwoOfRowsAvx2(query, descriptors, first, last);
#endif
  return NearestTwoOfRowsPortable(query, descriptors, first, last);
}

}  // namespace arpos
