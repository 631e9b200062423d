#include "sensor/depth_timing.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace arpos {

DelayedDepthSigma DelayedDepthSigmaOf(double delay_s, const Rigid3d* step, double step_s) {
  DelayedDepthSigma s;
  const double delay = std::abs(delay_s);
  if (!(delay > 0)) return s;
  double speed = kAssumedHandheldSpeedMS, turn = kAssumedHandheldTurnRadS;
  if (step != nullptr && step_s > 0) {
    speed = step->translation.norm() / step_s;
    turn = step->RotationVector().norm() / step_s;
  }
  s.const_m = delay * speed;
  s.per_m = delay * turn;
  return s;
}

Eigen::Matrix<double, 6, 6> DelayedDepthSigma::Covariance() const {
  Eigen::Matrix<double, 6, 6> c = Eigen::Matrix<double, 6, 6>::Zero();
  c.topLeftCorner<3, 3>().diagonal().setConstant(per_m * per_m);
  c.bottomRightCorner<3, 3>().diagonal().setConstant(const_m * const_m);
  return c;
}

void MarginaliseSharedMotion(const Eigen::Matrix<double, 6, 6>& covariance,
                             Eigen::Matrix<double, 6, 6>* H, Eigen::Matrix<double, 6, 1>* g,
                             const Eigen::Matrix<double, 6, 1>& mean) {
  if (covariance.isZero(0)) return;
  // With the depth camera at exp(d) * camera, d ~ N(0, C), the readings'
  // quadratic in (camera perturbation + d) integrated over d: the depth's
  // own estimate's covariance H^-1 plus C, written without inverting H
  // (which has null directions: a plane alone says nothing along itself).
  const Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Identity() + *H * covariance;
  const Eigen::PartialPivLU<Eigen::Matrix<double, 6, 6>> lu(A);
  Eigen::Matrix<double, 6, 6> h = lu.solve(*H);
  h = 0.5 * (h + h.transpose()).eval();
  *g = lu.solve(*g) + h * mean;
  *H = h;
}

DepthCameraMotion MeasuredSharedMotion(const Eigen::Matrix<double, 6, 6>& covariance,
                                       const Eigen::Matrix<double, 6, 6>& H,
                                       const Eigen::Matrix<double, 6, 1>& g,
                                       const Eigen::Matrix<double, 6, 1>& mean) {
  const Eigen::PartialPivLU<Eigen::Matrix<double, 6, 6>> lu(
      Eigen::Matrix<double, 6, 6>::Identity() + covariance * H);
  DepthCameraMotion out;
  out.mean = lu.solve(mean - covariance * g);
  out.covariance = lu.solve(covariance);
  out.covariance = 0.5 * (out.covariance + out.covariance.transpose()).eval();
  return out;
}

cv::Mat DepthAtColourInstant(const cv::Mat& depth, double depth_scale, double fx, double fy,
                             double cx, double cy, const Rigid3d& colour_from_depth) {
  cv::Mat out = cv::Mat::zeros(depth.size(), CV_16UC1);
  if (depth.empty() || depth.type() != CV_16UC1 || !(depth_scale > 0)) return out;
  const Rigid3d depth_from_colour = colour_from_depth.Inverse();
  const Eigen::Matrix3d Rd = depth_from_colour.RotationMatrix(),
                        Rc = colour_from_depth.RotationMatrix();
  const Eigen::Vector3d td = depth_from_colour.translation, tc = colour_from_depth.translation;
  const int w = depth.cols, h = depth.rows;
  for (int v = 0; v < h; ++v) {
    const uint16_t* row = depth.ptr<uint16_t>(v);
    uint16_t* out_row = out.ptr<uint16_t>(v);
    const double y = (v - cy) / fy;
    for (int u = 0; u < w; ++u) {
      if (row[u] == 0) continue;
      const double x = (u - cx) / fx;
      double z = row[u] / depth_scale;
      bool ok = true;
      for (int step = 0; step < 2 && ok; ++step) {
        // The colour pixel's point at z, seen by the depth camera ...
        const Eigen::Vector3d in_depth = Rd * Eigen::Vector3d(x * z, y * z, z) + td;
        if (in_depth.z() <= 1e-6) {
          ok = false;
          break;
        }
        const int ud = static_cast<int>(std::lround(fx * in_depth.x() / in_depth.z() + cx));
        const int vd = static_cast<int>(std::lround(fy * in_depth.y() / in_depth.z() + cy));
        if (ud < 0 || vd < 0 || ud >= w || vd >= h || depth.at<uint16_t>(vd, ud) == 0) {
          ok = false;
          break;
        }
        // ... whose reading there, back in the colour camera.
        const double zd = depth.at<uint16_t>(vd, ud) / depth_scale;
        const Eigen::Vector3d read(zd * (ud - cx) / fx, zd * (vd - cy) / fy, zd);
        z = (Rc * read + tc).z();
      }
      if (!ok || !(z > 0)) continue;
      out_row[u] = static_cast<uint16_t>(std::clamp(std::lround(z * depth_scale), 1L, 65535L));
    }
  }
  return out;
}

std::optional<Rigid3d> ColourFromDepthCamera(const std::vector<double>& times_s,
                                             const std::vector<Rigid3d>& room_from_camera, size_t k,
                                             double delay_s, double max_gap_s) {
  const size_t n = std::min(times_s.size(), room_from_camera.size());
  if (delay_s == 0 || k >= n || n < 2) return std::nullopt;
  // The pair around the depth instant: k and the next frame for a later
  // depth, the previous and k for an earlier one; at the ends, the nearest.
  size_t a = delay_s > 0 ? k : (k > 0 ? k - 1 : 0);
  if (a + 1 >= n) a = n - 2;
  const size_t b = a + 1;
  const double gap = times_s[b] - times_s[a];
  if (!(gap > 0 && gap <= max_gap_s)) return std::nullopt;
  // Constant velocity: the motion a -> b scaled to the depth instant.
  const double f = (times_s[k] + delay_s - times_s[a]) / gap;
  const Rigid3d a_from_b = room_from_camera[a].Inverse() * room_from_camera[b];
  const Rigid3d room_from_depth_camera =
      room_from_camera[a] *
      Rigid3d::FromRotationVector(f * a_from_b.RotationVector(), f * a_from_b.translation);
  return room_from_camera[k].Inverse() * room_from_depth_camera;
}

}  // namespace arpos
