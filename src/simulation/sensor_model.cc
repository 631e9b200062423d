#include "simulation/sensor_model.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "geometry/so3.h"
#include "simulation/random.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos::sim {
namespace {

// Per-pixel standard normal, independent of evaluation order.
inline double PixelNormal(uint64_t key, int x, int y) {
  return FastNormalFromBits(Hash3(key, static_cast<uint64_t>(x), static_cast<uint64_t>(y)));
}
inline double PixelUniform(uint64_t key, int x, int y) {
  return UniformFromBits(Hash3(key, static_cast<uint64_t>(x), static_cast<uint64_t>(y)));
}

cv::Vec3f BilinearAt(const cv::Mat& img, double x, double y) {
  x = std::clamp(x, 0.0, img.cols - 1.0);
  y = std::clamp(y, 0.0, img.rows - 1.0);
  const int x0 = std::min(static_cast<int>(x), img.cols - 2 < 0 ? 0 : img.cols - 2);
  const int y0 = std::min(static_cast<int>(y), img.rows - 2 < 0 ? 0 : img.rows - 2);
  const int x1 = std::min(x0 + 1, img.cols - 1), y1 = std::min(y0 + 1, img.rows - 1);
  const float ax = static_cast<float>(x - x0), ay = static_cast<float>(y - y0);
  const cv::Vec3f& a = img.at<cv::Vec3f>(y0, x0);
  const cv::Vec3f& b = img.at<cv::Vec3f>(y0, x1);
  const cv::Vec3f& c = img.at<cv::Vec3f>(y1, x0);
  const cv::Vec3f& d = img.at<cv::Vec3f>(y1, x1);
  return (a * (1 - ax) + b * ax) * (1 - ay) + (c * (1 - ax) + d * ax) * ay;
}

}  // namespace

std::string SensorProfile::Describe() const {
  std::string out = StringPrintf(
      "%s %dx%d f=%.1f depth_scale=%g sigma_z=%.4g+%.4g*z^2 m range=[%.2f, %.2f] m",
      name.c_str(), intrinsics.width, intrinsics.height, intrinsics.fx, intrinsics.depth_scale,
      depth_sigma_const_m, depth_sigma_quad_per_m, min_range_m, max_range_m);
  if (disparity_subpixel > 0 && projector_baseline_m > 0) {
    out += StringPrintf(" disparity_step=1/%d px (baseline %.3f m)", disparity_subpixel, projector_baseline_m);
  }
  return out;
}

SensorProfile MakeSensorProfile(const std::string& name) {
  SensorProfile p;
  p.name = name;
  if (name == "xtion") {
    // Asus Xtion / Kinect v1 class: structured light, 7.5 cm baseline.
    p.intrinsics.width = 640;
    p.intrinsics.height = 480;
    p.intrinsics.fx = p.intrinsics.fy = 540.0;
    p.intrinsics.cx = 319.5;
    p.intrinsics.cy = 239.5;
    p.intrinsics.depth_scale = 1000;  // OpenNI millimetres (finer than the noise)
    p.blur_sigma_px = 0.7;
    p.vignetting = 0.25;
    p.read_noise = 1.0;
    p.shot_noise_gain = 0.08;
    p.exposure_time_s = 0.02;
    p.depth_sigma_const_m = 0.0;
    p.depth_sigma_quad_per_m = 1.4e-3;  // Khoshelham & Elberink 2012
    p.depth_correlated_fraction = 0.3;
    p.depth_correlation_px = 8;
    p.min_range_m = 0.45;
    p.max_range_m = 4.0;
    p.grazing_start_deg = 68;
    p.grazing_end_deg = 82;
    p.edge_relative_jump = 0.03;
    p.edge_dropout = 0.7;
    p.random_dropout = 0.004;
    p.projector_baseline_m = 0.075;
    p.disparity_subpixel = 8;  // Kinect v1 / PrimeSense: 1/8 px disparity steps
  } else if (name == "l515") {
    // Intel RealSense L515 class: LiDAR depth registered to 1280x720 colour.
    p.intrinsics.width = 1280;
    p.intrinsics.height = 720;
    p.intrinsics.fx = p.intrinsics.fy = 905.0;
    p.intrinsics.cx = 639.5;
    p.intrinsics.cy = 359.5;
    p.intrinsics.depth_scale = 4000;
    p.blur_sigma_px = 0.6;
    p.vignetting = 0.15;
    p.read_noise = 0.8;
    p.shot_noise_gain = 0.05;
    p.exposure_time_s = 0.012;
    p.depth_sigma_const_m = 0.0018;
    p.depth_sigma_quad_per_m = 0.0002;
    p.depth_correlated_fraction = 0.2;
    p.depth_correlation_px = 12;
    p.min_range_m = 0.25;
    p.max_range_m = 9.0;
    p.grazing_start_deg = 72;
    p.grazing_end_deg = 86;
    p.edge_relative_jump = 0.02;
    p.edge_dropout = 0.5;
    p.random_dropout = 0.002;
    p.projector_baseline_m = 0;
  } else if (name == "d435") {
    // Intel RealSense D435 class: active stereo depth (5 cm baseline)
    // registered to 848x480 colour, with a calibration as a real unit has it:
    // the principal point off the image centre and fx != fy (the other two
    // profiles are centred and square, so this one checks that nothing
    // assumes they are).
    p.intrinsics.width = 848;
    p.intrinsics.height = 480;
    p.intrinsics.fx = 611.8;
    p.intrinsics.fy = 610.9;
    p.intrinsics.cx = 428.3;
    p.intrinsics.cy = 246.6;
    p.intrinsics.depth_scale = 1000;
    p.blur_sigma_px = 0.8;
    p.vignetting = 0.3;
    p.read_noise = 1.2;
    p.shot_noise_gain = 0.09;
    p.exposure_time_s = 0.016;
    // Stereo: sigma_z = z^2 * subpixel / (f b), 0.08 px / (612 px * 0.05 m).
    p.depth_sigma_const_m = 0.0005;
    p.depth_sigma_quad_per_m = 2.6e-3;
    p.depth_correlated_fraction = 0.4;
    p.depth_correlation_px = 10;
    p.min_range_m = 0.3;
    p.max_range_m = 6.0;
    p.grazing_start_deg = 70;
    p.grazing_end_deg = 84;
    p.edge_relative_jump = 0.03;
    p.edge_dropout = 0.6;
    p.random_dropout = 0.006;
    p.projector_baseline_m = 0.05;  // the left-right stereo pair's occlusion band
    p.disparity_subpixel = 16;
  } else {
    ARPOS_INPUT_ERROR("unknown camera profile '" << name << "' (known: xtion, l515, d435)");
  }
  return p;
}

cv::Mat SimulateColor(const cv::Mat& radiance, const SensorProfile& profile, bool noise,
                      uint64_t frame_key, const ColorEncoding& encoding) {
  ARPOS_CHECK(radiance.type() == CV_32FC3, "radiance must be CV_32FC3");
  cv::Mat lin = radiance;
  if (noise && profile.blur_sigma_px > 0) {
    cv::GaussianBlur(radiance, lin, cv::Size(0, 0), profile.blur_sigma_px, profile.blur_sigma_px,
                     cv::BORDER_REPLICATE);
  }
  const int W = radiance.cols, H = radiance.rows;
  const double cx = (W - 1) / 2.0, cy = (H - 1) / 2.0;
  const double r2max = cx * cx + cy * cy;
  cv::Mat out(H, W, CV_8UC3);
  const uint64_t key = HashCombine(frame_key, 0xC0102ULL);
  // The default (sRGB, no exposure change) keeps its original arithmetic.
  const bool srgb = encoding.response == CameraResponse::kSrgb;
  const double exposure_gain = encoding.exposure_stops != 0 ? std::exp2(encoding.exposure_stops) : 1.0;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y) {
    const cv::Vec3f* in = lin.ptr<cv::Vec3f>(y);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < W; ++x) {
      double gain = profile.exposure;
      if (encoding.exposure_stops != 0) gain *= exposure_gain;
      if (noise) {
        const double r2 = ((x - cx) * (x - cx) + (y - cy) * (y - cy)) / r2max;
        gain *= 1.0 - profile.vignetting * r2;
      }
      for (int c = 0; c < 3; ++c) {
        double v = in[x][c] * gain * 255.0;  // linear 8-bit units
        if (noise) {
          const double sigma =
              std::sqrt(profile.shot_noise_gain * std::max(v, 0.0) + profile.read_noise * profile.read_noise);
          v += sigma * FastNormalFromBits(Hash4(key, static_cast<uint64_t>(x), static_cast<uint64_t>(y),
                                            static_cast<uint64_t>(c)));
        }
        // RGB -> BGR.
        o[x][2 - c] = srgb ? Srgb8FromLinearFast(static_cast<float>(v / 255.0))
                           : Encode8Fast(encoding.response, static_cast<float>(v / 255.0));
      }
    }
  }
  if (noise && encoding.sharpen_amount > 0) {
    cv::Mat codes, blurred;
    out.convertTo(codes, CV_32FC3);
    cv::GaussianBlur(codes, blurred, cv::Size(0, 0), encoding.sharpen_sigma_px, encoding.sharpen_sigma_px,
                     cv::BORDER_REPLICATE);
    cv::Mat sharpened = codes + encoding.sharpen_amount * (codes - blurred);
    sharpened.convertTo(out, CV_8UC3);  // rounds and saturates
  }
  return out;
}

cv::Mat MakeDepthErrorField(int width, int height, uint64_t seed) {
  Rng rng(seed);
  // Weights of the radial term and three plane waves, |w| summing to 1.
  double w[4];
  double total = 0;
  for (double& v : w) {
    v = rng.Uniform(0.3, 1.0) * (rng.Uniform() < 0.5 ? -1 : 1);
    total += std::abs(v);
  }
  for (double& v : w) v /= total;
  double kx[3], ky[3], phase[3];
  for (int i = 0; i < 3; ++i) {
    kx[i] = rng.Uniform(-1.5, 1.5);
    ky[i] = rng.Uniform(-1.5, 1.5);
    phase[i] = rng.Uniform(0, 2 * M_PI);
  }
  const double cx = 0.5 * (width - 1), cy = 0.5 * (height - 1);
  const double r2max = cx * cx + cy * cy;
  cv::Mat field(height, width, CV_32F);
  for (int y = 0; y < height; ++y) {
    float* row = field.ptr<float>(y);
    for (int x = 0; x < width; ++x) {
      const double u = static_cast<double>(x) / width, v = static_cast<double>(y) / height;
      const double r2 = ((x - cx) * (x - cx) + (y - cy) * (y - cy)) / r2max;
      double f = w[0] * (2 * r2 - 1);
      for (int i = 0; i < 3; ++i) f += w[i + 1] * std::cos(2 * M_PI * (kx[i] * u + ky[i] * v) + phase[i]);
      row[x] = static_cast<float>(f);
    }
  }
  return field;
}

cv::Mat SimulateDepth(const RenderOutput& render, const SensorProfile& profile, bool noise,
                      uint64_t frame_key, const DepthBias& bias) {
  ARPOS_CHECK(bias.field_mm_at_1m == 0 ||
                  (bias.field.type() == CV_32F && bias.field.size() == render.depth.size()),
              "depth bias: the error field must be CV_32F of the image size");
  const cv::Mat& z = render.depth;
  const int W = z.cols, H = z.rows;
  const CameraIntrinsics& K = profile.intrinsics;
  cv::Mat valid(H, W, CV_8U, cv::Scalar(1));
  cv::Mat out(H, W, CV_16U, cv::Scalar(0));
  const uint64_t key = HashCombine(frame_key, 0xDE9711ULL);

  if (noise) {
    // Projector shadows (structured light): with the projector at +baseline
    // along camera x, a surface point is lit only if no nearer point lies on
    // its projector ray. Along a row the projector column is
    // u - f b / z; scanning right to left, a pixel whose projector column is
    // not left of every column seen so far is in shadow.
    if (profile.projector_baseline_m > 0) {
      const double fb = K.fx * profile.projector_baseline_m;
      for (int y = 0; y < H; ++y) {
        const float* zr = z.ptr<float>(y);
        uint8_t* vr = valid.ptr<uint8_t>(y);
        double min_col = 1e30;
        for (int x = W - 1; x >= 0; --x) {
          if (zr[x] <= 0) continue;
          const double col = x - fb / zr[x];
          if (col > min_col + 0.5) vr[x] = 0;
          min_col = std::min(min_col, col);
        }
      }
    }
  }
  // Smooth noise field: normals on a coarse grid, bilinear in between.
  cv::Mat smooth;
  if (noise && profile.depth_correlated_fraction > 0) {
    const int gw = static_cast<int>(W / profile.depth_correlation_px) + 2;
    const int gh = static_cast<int>(H / profile.depth_correlation_px) + 2;
    cv::Mat grid(gh, gw, CV_32F);
    const uint64_t gkey = HashCombine(key, 0x5300ULL);
    for (int gy = 0; gy < gh; ++gy)
      for (int gx = 0; gx < gw; ++gx)
        grid.at<float>(gy, gx) = static_cast<float>(PixelNormal(gkey, gx, gy) * 1.6);  // ~unit after interpolation
    cv::resize(grid, smooth,
               cv::Size(static_cast<int>(gw * profile.depth_correlation_px),
                        static_cast<int>(gh * profile.depth_correlation_px)),
               0, 0, cv::INTER_LINEAR);
  }
  const double cos_start = std::cos(RadFromDeg(profile.grazing_start_deg));
  const double cos_end = std::cos(RadFromDeg(profile.grazing_end_deg));
  const double a = profile.depth_correlated_fraction;
  const double white = std::sqrt(std::max(0.0, 1 - a * a));
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y) {
    const float* zr = z.ptr<float>(y);
    const cv::Vec3f* nr = render.normal.ptr<cv::Vec3f>(y);
    const uint8_t* vr = valid.ptr<uint8_t>(y);
    uint16_t* o = out.ptr<uint16_t>(y);
    for (int x = 0; x < W; ++x) {
      double d = zr[x];
      if (d <= 0 || d < profile.min_range_m || d > profile.max_range_m) continue;
      if (noise) {
        if (!vr[x]) continue;
        if (PixelUniform(HashCombine(key, 1), x, y) < profile.random_dropout) continue;
        // Grazing angle between the viewing ray and the surface normal.
        const Eigen::Vector3d ray =
            Eigen::Vector3d((x - K.cx) / K.fx, (y - K.cy) / K.fy, 1.0).normalized();
        const double cosine = std::abs(ray.x() * nr[x][0] + ray.y() * nr[x][1] + ray.z() * nr[x][2]);
        if (cosine < cos_start) {
          const double p = std::clamp((cos_start - cosine) / (cos_start - cos_end), 0.0, 1.0);
          if (PixelUniform(HashCombine(key, 2), x, y) < p) continue;
        }
        // Depth discontinuities (mixed pixels are dropped by real sensors).
        bool edge = false;
        const int dx[4] = {1, -1, 0, 0}, dy[4] = {0, 0, 1, -1};
        for (int k = 0; k < 4 && !edge; ++k) {
          const int xx = x + dx[k], yy = y + dy[k];
          if (xx < 0 || yy < 0 || xx >= W || yy >= H) continue;
          const float zn = z.at<float>(yy, xx);
          if (zn <= 0 || std::abs(zn - d) > profile.edge_relative_jump * d) edge = true;
        }
        bool flying = false;
        if (edge && bias.flying_pixels) {
          // ... or some report a depth between the two surfaces.
          double far = 0, jump = 0;
          for (int k = 0; k < 4; ++k) {
            const int xx = x + dx[k], yy = y + dy[k];
            if (xx < 0 || yy < 0 || xx >= W || yy >= H) continue;
            const float zn = z.at<float>(yy, xx);
            if (zn > 0 && std::abs(zn - d) > profile.edge_relative_jump * d && std::abs(zn - d) > jump) {
              far = zn;
              jump = std::abs(zn - d);
            }
          }
          if (far > 0 && PixelUniform(HashCombine(key, 5), x, y) < 0.5) {
            d += (0.15 + 0.7 * PixelUniform(HashCombine(key, 6), x, y)) * (far - d);
            flying = true;
          }
        }
        if (edge && !flying && PixelUniform(HashCombine(key, 3), x, y) < profile.edge_dropout) continue;
        const double sigma = profile.depth_sigma_const_m + profile.depth_sigma_quad_per_m * d * d;
        double n = white * PixelNormal(HashCombine(key, 4), x, y);
        if (!smooth.empty()) n += a * smooth.at<float>(y, x);
        d += sigma * n;
        if (profile.disparity_subpixel > 0 && profile.projector_baseline_m > 0 && d > 0) {
          const double fbq = K.fx * profile.projector_baseline_m * profile.disparity_subpixel;
          d = fbq / std::max(1.0, std::round(fbq / d));
        }
      }
      if (bias.scale_error != 0 || bias.field_mm_at_1m != 0) {
        // The sensor's own calibration turns its measurement into depth.
        double biased = d * (1.0 + bias.scale_error);
        if (bias.field_mm_at_1m != 0) biased += 0.001 * bias.field_mm_at_1m * d * d * bias.field.at<float>(y, x);
        d = biased;
      }
      const double units = std::round(d * K.depth_scale);
      if (units <= 0 || units > 65535) continue;
      o[x] = static_cast<uint16_t>(units);
    }
  }
  return out;
}

cv::Mat ApplyMotionBlur(const cv::Mat& radiance, const RenderOutput& render,
                        const CameraIntrinsics& K, double exposure_s, const LabelMotion& motion,
                        int max_label, int taps) {
  ARPOS_CHECK(taps >= 2, "motion blur needs at least 2 taps");
  std::vector<std::vector<Rigid3d>> table(max_label + 1, std::vector<Rigid3d>(taps));
  for (int label = 0; label <= max_label; ++label) {
    for (int k = 0; k < taps; ++k) {
      const double dt = exposure_s * (static_cast<double>(k) / (taps - 1) - 0.5);
      table[label][k] = motion(label, dt);
    }
  }
  const int W = radiance.cols, H = radiance.rows;
  cv::Mat out = radiance.clone();
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y) {
    const float* zr = render.depth.ptr<float>(y);
    const int* lr = render.label.ptr<int>(y);
    cv::Vec3f* o = out.ptr<cv::Vec3f>(y);
    for (int x = 0; x < W; ++x) {
      if (zr[x] <= 0) continue;
      const int label = std::clamp(lr[x], 0, max_label);
      const Eigen::Vector3d p = K.Unproject(x, y, zr[x]);
      cv::Vec3f sum(0, 0, 0);
      for (int k = 0; k < taps; ++k) {
        const Eigen::Vector3d q = table[label][k] * p;
        if (q.z() <= 1e-3) {
          sum += radiance.at<cv::Vec3f>(y, x);
          continue;
        }
        const Eigen::Vector2d uv = K.Project(q);
        // The image at t + dt shows this point at uv; at (x, y) it shows
        // what was at (x, y) - (uv - (x, y)) (locally uniform motion).
        sum += BilinearAt(radiance, 2.0 * x - uv.x(), 2.0 * y - uv.y());
      }
      o[x] = sum * (1.0f / taps);
    }
  }
  return out;
}

}  // namespace arpos::sim
