#include "room_map/bundle_adjustment.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <sstream>

#include <ceres/ceres.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <ceres/rotation.h>

#include "features/marker_pose.h"
#include "util/check.h"

namespace arpos {

std::string BaOptions::Validate() const {
  std::ostringstream out;
  if (!(huber > 0)) out << "huber must be positive";
  else if (!(depth_sigma_const_m >= 0 && depth_sigma_quad_per_m >= 0 &&
             depth_sigma_const_m + depth_sigma_quad_per_m > 0))
    out << "depth sigmas must be non-negative and not both zero";
  else if (marker_depth_max_effective < 1) out << "marker_depth_max_effective must be at least 1";
  else if (max_iterations < 1) out << "max_iterations must be at least 1";
  else if (threads < 1) out << "threads must be at least 1";
  return out.str();
}

bool BaOptions::Check(std::string* reason) const {
  const std::string r = Validate();
  if (reason) *reason = r;
  return r.empty();
}

namespace {

// Pose blocks: quaternion (x, y, z, w: Eigen's memory order) and translation.
struct PoseBlock {
  double q[4];
  double t[3];
  void Set(const Rigid3d& pose) {
    const Eigen::Quaterniond n = pose.rotation.normalized();
    q[0] = n.x();
    q[1] = n.y();
    q[2] = n.z();
    q[3] = n.w();
    for (int k = 0; k < 3; ++k) t[k] = pose.translation[k];
  }
  Rigid3d Get() const {
    return Rigid3d(Eigen::Quaterniond(q[3], q[0], q[1], q[2]), Eigen::Vector3d(t[0], t[1], t[2]));
  }
};

template <typename T>
Eigen::Matrix<T, 3, 1> Transform(const T* q, const T* t, const Eigen::Matrix<T, 3, 1>& p) {
  const Eigen::Map<const Eigen::Quaternion<T>> quat(q);
  return quat * p + Eigen::Map<const Eigen::Matrix<T, 3, 1>>(t);
}

struct MarkerCornerCost {
  MarkerCornerCost(const CameraIntrinsics& k, const Eigen::Vector3d& corner_in_marker,
                   const Eigen::Vector2d& observed, double sigma)
      : fx(k.fx), fy(k.fy), cx(k.cx), cy(k.cy), corner(corner_in_marker), obs(observed),
        inv_sigma(1.0 / sigma) {}
  template <typename T>
  bool operator()(const T* cq, const T* ct, const T* mq, const T* mt, T* residual) const {
    const Eigen::Matrix<T, 3, 1> in_room = Transform(mq, mt, corner.cast<T>().eval());
    const Eigen::Matrix<T, 3, 1> p = Transform(cq, ct, in_room);
    residual[0] = (T(fx) * p.x() / p.z() + T(cx) - T(obs.x())) * T(inv_sigma);
    residual[1] = (T(fy) * p.y() / p.z() + T(cy) - T(obs.y())) * T(inv_sigma);
    return true;
  }
  double fx, fy, cx, cy;
  Eigen::Vector3d corner;
  Eigen::Vector2d obs;
  double inv_sigma;
};

struct MarkerDepthCost {
  MarkerDepthCost(const CameraIntrinsics& k, const DepthSample& s, double weight_over_sigma)
      : ray((s.pixel.x() - k.cx) / k.fx, (s.pixel.y() - k.cy) / k.fy, 1.0), z(s.depth_m),
        w(weight_over_sigma) {}
  template <typename T>
  bool operator()(const T* cq, const T* ct, const T* mq, const T* mt, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> camera_q(cq), marker_q(mq);
    const Eigen::Matrix<T, 3, 1> normal = camera_q * (marker_q * Eigen::Matrix<T, 3, 1>(T(0), T(0), T(1)));
    const Eigen::Matrix<T, 3, 1> centre = Transform(cq, ct, Eigen::Map<const Eigen::Matrix<T, 3, 1>>(mt).eval());
    const T denom = normal.dot(ray.cast<T>());
    residual[0] = (normal.dot(centre) / denom - T(z)) * T(w);
    return true;
  }
  Eigen::Vector3d ray;
  double z, w;
};

// A depth pixel on a room plane: the plane (unit normal n, offset o, room
// frame) in the camera is n_c = R n, n_c . x = o + n_c . t; the ray (x, y, 1)
// meets it at z = (o + n_c . t) / (n_c . ray).
struct PlaneDepthCost {
  PlaneDepthCost(const CameraIntrinsics& k, const DepthSample& s, double weight_over_sigma)
      : ray((s.pixel.x() - k.cx) / k.fx, (s.pixel.y() - k.cy) / k.fy, 1.0), z(s.depth_m),
        w(weight_over_sigma) {}
  template <typename T>
  bool operator()(const T* cq, const T* ct, const T* normal, const T* offset, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> camera_q(cq);
    const Eigen::Matrix<T, 3, 1> n = camera_q * Eigen::Map<const Eigen::Matrix<T, 3, 1>>(normal);
    const T d = offset[0] + n.dot(Eigen::Map<const Eigen::Matrix<T, 3, 1>>(ct));
    residual[0] = (d / n.dot(ray.cast<T>()) - T(z)) * T(w);
    return true;
  }
  Eigen::Vector3d ray;
  double z, w;
};

// A marker on a room plane: its centre's distance from the plane (one
// residual, / flatness sigma) and, when tilt_sigma > 0, its normal's
// difference from the plane's (three, / tilt sigma).
struct MarkerOnPlaneCost {
  MarkerOnPlaneCost(double flatness_sigma, double tilt_sigma)
      : inv_flatness(1.0 / flatness_sigma), inv_tilt(tilt_sigma > 0 ? 1.0 / tilt_sigma : 0.0) {}
  template <typename T>
  bool operator()(const T* mq, const T* mt, const T* normal, const T* offset, T* residual) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> n(normal), centre(mt);
    residual[0] = (n.dot(centre) - offset[0]) * T(inv_flatness);
    const Eigen::Matrix<T, 3, 1> marker_normal =
        Eigen::Map<const Eigen::Quaternion<T>>(mq) * Eigen::Matrix<T, 3, 1>(T(0), T(0), T(1));
    for (int k = 0; k < 3; ++k) residual[1 + k] = (marker_normal[k] - n[k]) * T(inv_tilt);
    return true;
  }
  double inv_flatness, inv_tilt;
};

struct KeypointCost {
  KeypointCost(const CameraIntrinsics& k, const Eigen::Vector2d& observed, double sigma)
      : fx(k.fx), fy(k.fy), cx(k.cx), cy(k.cy), obs(observed), inv_sigma(1.0 / sigma) {}
  template <typename T>
  bool operator()(const T* cq, const T* ct, const T* point, T* residual) const {
    const Eigen::Matrix<T, 3, 1> p = Transform(cq, ct, Eigen::Map<const Eigen::Matrix<T, 3, 1>>(point).eval());
    residual[0] = (T(fx) * p.x() / p.z() + T(cx) - T(obs.x())) * T(inv_sigma);
    residual[1] = (T(fy) * p.y() / p.z() + T(cy) - T(obs.y())) * T(inv_sigma);
    return true;
  }
  double fx, fy, cx, cy;
  Eigen::Vector2d obs;
  double inv_sigma;
};

struct KeypointDepthCost {
  KeypointDepthCost(double depth_m, double sigma_m) : z(depth_m), inv_sigma(1.0 / sigma_m) {}
  template <typename T>
  bool operator()(const T* cq, const T* ct, const T* point, T* residual) const {
    const Eigen::Matrix<T, 3, 1> p = Transform(cq, ct, Eigen::Map<const Eigen::Matrix<T, 3, 1>>(point).eval());
    residual[0] = (p.z() - T(z)) * T(inv_sigma);
    return true;
  }
  double z, inv_sigma;
};

// A weak prior holding a parameter block near its value, for the
// covariance only: a direction nothing observes (a landmark on one ray, a
// plane's offset with no depth) makes the Jacobian rank deficient, and
// Ceres's sparse QR then computes no covariance at all. 10 units (m, or a
// quaternion's components) is nothing next to what the observations say of
// every direction they do determine.
class WeakPriorCost : public ceres::CostFunction {
 public:
  WeakPriorCost(const double* x0, int n) : x0_(x0, x0 + n) {
    set_num_residuals(n);
    mutable_parameter_block_sizes()->push_back(n);
  }
  bool Evaluate(double const* const* x, double* residuals, double** jacobians) const override {
    const int n = static_cast<int>(x0_.size());
    for (int i = 0; i < n; ++i) residuals[i] = (x[0][i] - x0_[i]) * kWeight;
    if (jacobians && jacobians[0]) {
      for (int i = 0; i < n * n; ++i) jacobians[0][i] = 0;
      for (int i = 0; i < n; ++i) jacobians[0][i * n + i] = kWeight;
    }
    return true;
  }

 private:
  static constexpr double kWeight = 0.1;
  std::vector<double> x0_;
};

// The covariance of `wanted` (variable, non-landmark parameter blocks; in
// their tangent spaces, in that order) marginal over every other variable
// block of `problem`, at its current state with the loss applied. Each
// landmark (a 3-vector seen only with poses) is eliminated by its Schur
// complement; the rest (cameras, markers, planes: a few thousand columns)
// is solved densely. Ceres's own covariance (sparse QR over everything)
// took 36 s on a 300-frame room with 4000 landmarks. False when the
// reduced system is not positive definite.
bool MarginalCovariance(ceres::Problem* problem, const std::set<const double*>& landmarks,
                        const std::vector<const double*>& wanted, int threads, Eigen::MatrixXd* covariance) {
  std::vector<double*> all, order;
  problem->GetParameterBlocks(&all);
  std::map<const double*, int> column;  // first tangent column of each non-landmark block
  int P = 0;
  for (double* x : all) {
    if (problem->IsParameterBlockConstant(x) || landmarks.count(x)) continue;
    column[x] = P;
    P += problem->ParameterBlockTangentSize(x);
    order.push_back(x);
  }
  const int L = static_cast<int>(order.size());
  for (double* x : all) {
    if (!problem->IsParameterBlockConstant(x) && landmarks.count(x)) order.push_back(x);
  }
  const int num_landmarks = static_cast<int>(order.size()) - L;
  ceres::Problem::EvaluateOptions eo;
  eo.parameter_blocks = order;
  eo.apply_loss_function = true;
  eo.num_threads = threads;
  ceres::CRSMatrix J;
  if (!problem->Evaluate(eo, nullptr, nullptr, nullptr, &J)) return false;
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(P, P);
  std::vector<Eigen::Matrix3d> hll(num_landmarks, Eigen::Matrix3d::Zero());
  std::vector<std::vector<std::pair<int, Eigen::Vector3d>>> hpl(num_landmarks);
  std::vector<std::pair<int, double>> pose;
  for (int r = 0; r < J.num_rows; ++r) {
    pose.clear();
    int landmark = -1;
    Eigen::Vector3d jl = Eigen::Vector3d::Zero();
    for (int k = J.rows[r]; k < J.rows[r + 1]; ++k) {
      const int c = J.cols[k];
      if (c < P) {
        pose.emplace_back(c, J.values[k]);
      } else {
        landmark = (c - P) / 3;
        jl((c - P) % 3) = J.values[k];
      }
    }
    for (const auto& [ci, vi] : pose) {
      for (const auto& [cj, vj] : pose) S(ci, cj) += vi * vj;
    }
    if (landmark >= 0) {
      hll[landmark] += jl * jl.transpose();
      for (const auto& [c, v] : pose) hpl[landmark].emplace_back(c, v * jl);
    }
  }
  for (int l = 0; l < num_landmarks; ++l) {
    auto& b = hpl[l];
    if (b.empty()) continue;
    std::sort(b.begin(), b.end(), [](const auto& a, const auto& c) { return a.first < c.first; });
    std::vector<std::pair<int, Eigen::Vector3d>> merged;
    for (const auto& e : b) {
      if (!merged.empty() && merged.back().first == e.first) {
        merged.back().second += e.second;
      } else {
        merged.push_back(e);
      }
    }
    const Eigen::Matrix3d inv = hll[l].inverse();
    if (!inv.allFinite()) return false;
    for (const auto& [ci, bi] : merged) {
      const Eigen::RowVector3d bi_inv = bi.transpose() * inv;
      for (const auto& [cj, bj] : merged) S(ci, cj) -= bi_inv.dot(bj);
    }
  }
  int n = 0;
  for (const double* x : wanted) {
    if (!column.count(x)) return false;
    n += problem->ParameterBlockTangentSize(x);
  }
  Eigen::MatrixXd select = Eigen::MatrixXd::Zero(P, n);
  int k = 0;
  for (const double* x : wanted) {
    for (int i = 0; i < problem->ParameterBlockTangentSize(x); ++i) select(column.at(x) + i, k++) = 1;
  }
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(S);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return false;
  const Eigen::MatrixXd columns = ldlt.solve(select);
  *covariance = select.transpose() * columns;
  return covariance->allFinite();
}

// Depth readings at image pixels as samples at their ideal (undistorted)
// pixels, at most `max_samples`.
std::vector<DepthSample> IdealDepthSamples(std::vector<cv::Point2d> px, const std::vector<float>& z,
                                           const CameraIntrinsics& k, int max_samples) {
  if (k.HasDistortion() && !px.empty()) {
    std::vector<cv::Point2d> ideal;
    cv::undistortPoints(px, ideal, k.CvK(), k.CvDistortion(), cv::noArray(), k.CvK());
    px = ideal;
  }
  std::vector<DepthSample> samples;
  samples.reserve(std::min<size_t>(px.size(), static_cast<size_t>(std::max(0, max_samples))));
  for (size_t i = 0; i < px.size() && static_cast<int>(samples.size()) < max_samples; ++i) {
    samples.push_back({Eigen::Vector2f(static_cast<float>(px[i].x), static_cast<float>(px[i].y)), z[i]});
  }
  return samples;
}

}  // namespace

std::vector<DepthSample> SampleMarkerDepth(const cv::Mat& depth, const std::array<Eigen::Vector2d, 4>& corners_image_px,
                                           const CameraIntrinsics& k, int max_samples) {
  if (depth.empty() || max_samples <= 0) return {};
  ARPOS_CHECK(depth.type() == CV_16UC1, "depth must be CV_16UC1");
  const std::vector<cv::Point2f> square = {{-0.5f, 0.5f}, {0.5f, 0.5f}, {0.5f, -0.5f}, {-0.5f, -0.5f}};
  std::vector<cv::Point2f> quad;
  for (const auto& c : corners_image_px) quad.emplace_back(static_cast<float>(c.x()), static_cast<float>(c.y()));
  const cv::Matx33d h = cv::getPerspectiveTransform(square, quad);
  const int n = std::max(2, static_cast<int>(std::ceil(std::sqrt(double(max_samples)))));
  std::vector<cv::Point2d> px;
  std::vector<float> z;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const double x = -0.35 + 0.7 * (i + 0.5) / n, y = -0.35 + 0.7 * (j + 0.5) / n;
      const cv::Vec3d q = h * cv::Vec3d(x, y, 1);
      const int u = cvRound(q[0] / q[2]), v = cvRound(q[1] / q[2]);
      if (u < 0 || v < 0 || u >= depth.cols || v >= depth.rows) continue;
      const uint16_t d = depth.at<uint16_t>(v, u);
      if (d == 0) continue;
      px.emplace_back(u, v);
      z.push_back(static_cast<float>(d / k.depth_scale));
    }
  }
  return IdealDepthSamples(std::move(px), z, k, max_samples);
}

std::vector<DepthSample> SampleSupportDepth(const cv::Mat& depth, const std::array<Eigen::Vector2d, 4>& corners_image_px,
                                            const CameraIntrinsics& k, double marker_side_m, double half_width_m,
                                            int max_samples) {
  if (depth.empty() || max_samples <= 0 || !(marker_side_m > 0) || !(half_width_m > 0)) return {};
  ARPOS_CHECK(depth.type() == CV_16UC1, "depth must be CV_16UC1");
  const float h = static_cast<float>(marker_side_m / 2);
  const std::vector<cv::Point2f> square = {{-h, h}, {h, h}, {h, -h}, {-h, -h}};
  std::vector<cv::Point2f> quad;
  for (const auto& c : corners_image_px) quad.emplace_back(static_cast<float>(c.x()), static_cast<float>(c.y()));
  const cv::Matx33d H = cv::getPerspectiveTransform(square, quad);
  // Points behind the camera map with the other sign of w than the centre.
  const double w_centre = (H * cv::Vec3d(0, 0, 1))[2];
  const int n = std::max(2, static_cast<int>(std::floor(std::sqrt(double(max_samples)))));
  std::vector<cv::Point2d> px;
  std::vector<float> z;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const double x = half_width_m * (-1 + 2 * (i + 0.5) / n), y = half_width_m * (-1 + 2 * (j + 0.5) / n);
      const cv::Vec3d q = H * cv::Vec3d(x, y, 1);
      if (!(q[2] * w_centre > 0)) continue;
      const double uf = q[0] / q[2], vf = q[1] / q[2];
      if (!(uf >= 0 && vf >= 0 && uf < depth.cols - 0.5 && vf < depth.rows - 0.5)) continue;
      const int u = cvRound(uf), v = cvRound(vf);
      const uint16_t d = depth.at<uint16_t>(v, u);
      if (d == 0) continue;
      px.emplace_back(u, v);
      z.push_back(static_cast<float>(d / k.depth_scale));
    }
  }
  return IdealDepthSamples(std::move(px), z, k, max_samples);
}

BaSummary RunBundleAdjustment(BaProblem* problem, const BaOptions& options) {
  ARPOS_CHECK(problem != nullptr, "no problem given");
  std::string reason;
  ARPOS_CHECK(options.Check(&reason), "invalid bundle adjustment options: " << reason);
  BaProblem& P = *problem;
  ARPOS_CHECK(P.marker_fixed.size() == P.room_from_marker.size(), "marker_fixed size mismatch");
  const auto start = std::chrono::steady_clock::now();

  std::vector<PoseBlock> cameras(P.camera_from_room.size()), markers(P.room_from_marker.size());
  for (size_t i = 0; i < cameras.size(); ++i) cameras[i].Set(P.camera_from_room[i]);
  for (size_t i = 0; i < markers.size(); ++i) markers[i].Set(P.room_from_marker[i]);

  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem cp(problem_options);
  ceres::EigenQuaternionManifold quaternion_manifold;
  ceres::HuberLoss huber(options.huber);

  const std::array<Eigen::Vector3d, 4> in_marker = MarkerCornersInMarker(P.marker_size_m);
  std::vector<bool> camera_used(cameras.size(), false), marker_used(markers.size(), false);
  for (const auto& o : P.marker_observations) {
    ARPOS_CHECK(o.camera >= 0 && o.camera < static_cast<int>(cameras.size()) && o.marker >= 0 &&
                    o.marker < static_cast<int>(markers.size()),
                "marker observation with a bad index");
    PoseBlock& c = cameras[o.camera];
    PoseBlock& m = markers[o.marker];
    for (int k = 0; k < 4; ++k) {
      auto* cost = new ceres::AutoDiffCostFunction<MarkerCornerCost, 2, 4, 3, 4, 3>(
          new MarkerCornerCost(P.intrinsics, in_marker[k], o.corners_px[k], o.sigma_px[k]));
      cp.AddResidualBlock(cost, &huber, c.q, c.t, m.q, m.t);
    }
    if (options.use_marker_depth && !o.depth_samples.empty()) {
      const double n = static_cast<double>(o.depth_samples.size());
      const double share = std::sqrt(std::min(1.0, options.marker_depth_max_effective / n));
      for (const auto& s : o.depth_samples) {
        const double sigma = options.DepthSigmaM(s.depth_m);
        auto* cost = new ceres::AutoDiffCostFunction<MarkerDepthCost, 1, 4, 3, 4, 3>(
            new MarkerDepthCost(P.intrinsics, s, share / sigma));
        cp.AddResidualBlock(cost, &huber, c.q, c.t, m.q, m.t);
      }
    }
    camera_used[o.camera] = true;
    marker_used[o.marker] = true;
  }
  std::vector<bool> landmark_used(P.landmarks_in_room.size(), false);
  for (const auto& o : P.keypoint_observations) {
    ARPOS_CHECK(o.camera >= 0 && o.camera < static_cast<int>(cameras.size()) && o.landmark >= 0 &&
                    o.landmark < static_cast<int>(P.landmarks_in_room.size()),
                "keypoint observation with a bad index");
    PoseBlock& c = cameras[o.camera];
    double* point = P.landmarks_in_room[o.landmark].data();
    cp.AddResidualBlock(new ceres::AutoDiffCostFunction<KeypointCost, 2, 4, 3, 3>(
                            new KeypointCost(P.intrinsics, o.pixel, o.sigma_px)),
                        &huber, c.q, c.t, point);
    if (options.use_keypoint_depth && o.depth_m > 0) {
      cp.AddResidualBlock(new ceres::AutoDiffCostFunction<KeypointDepthCost, 1, 4, 3, 3>(
                              new KeypointDepthCost(o.depth_m, options.DepthSigmaM(o.depth_m))),
                          &huber, c.q, c.t, point);
    }
    camera_used[o.camera] = true;
    landmark_used[o.landmark] = true;
  }
  std::vector<std::array<double, 4>> planes(P.planes.size());  // normal, offset
  for (size_t i = 0; i < planes.size(); ++i) {
    const Eigen::Vector3d n = P.planes[i].normal.normalized();
    planes[i] = {n.x(), n.y(), n.z(), P.planes[i].offset};
  }
  std::vector<bool> plane_used(planes.size(), false);
  if (options.use_plane_depth) {
    for (const auto& o : P.plane_observations) {
      ARPOS_CHECK(o.camera >= 0 && o.camera < static_cast<int>(cameras.size()) && o.plane >= 0 &&
                      o.plane < static_cast<int>(planes.size()) && o.share >= 1,
                  "plane observation with a bad index or share");
      // A camera seen by nothing else would be held by its plane alone.
      if (!camera_used[o.camera]) continue;
      PoseBlock& c = cameras[o.camera];
      for (const auto& s : o.samples) {
        cp.AddResidualBlock(new ceres::AutoDiffCostFunction<PlaneDepthCost, 1, 4, 3, 3, 1>(
                                new PlaneDepthCost(P.intrinsics, s, 1.0 / (o.share * options.DepthSigmaM(s.depth_m)))),
                            &huber, c.q, c.t, planes[o.plane].data(), planes[o.plane].data() + 3);
      }
      plane_used[o.plane] = true;
    }
    for (size_t i = 0; i < planes.size(); ++i) {
      ARPOS_CHECK(P.planes[i].flatness_sigma_m > 0 && P.planes[i].tilt_sigma_rad >= 0,
                  "plane flatness sigma must be positive, its tilt sigma not negative");
      for (int m : P.planes[i].markers) {
        ARPOS_CHECK(m >= 0 && m < static_cast<int>(markers.size()), "plane marker with a bad index");
        if (!marker_used[m]) continue;
        cp.AddResidualBlock(new ceres::AutoDiffCostFunction<MarkerOnPlaneCost, 4, 4, 3, 3, 1>(
                                new MarkerOnPlaneCost(P.planes[i].flatness_sigma_m, P.planes[i].tilt_sigma_rad)),
                            nullptr, markers[m].q, markers[m].t, planes[i].data(), planes[i].data() + 3);
        plane_used[i] = true;
      }
    }
  }
  ceres::SphereManifold<3> sphere_manifold;
  for (size_t i = 0; i < planes.size(); ++i) {
    if (plane_used[i]) cp.SetManifold(planes[i].data(), &sphere_manifold);
  }
  for (size_t i = 0; i < cameras.size(); ++i) {
    if (camera_used[i]) cp.SetManifold(cameras[i].q, &quaternion_manifold);
  }
  for (size_t i = 0; i < markers.size(); ++i) {
    if (!marker_used[i]) continue;
    if (P.marker_fixed[i]) {
      cp.SetParameterBlockConstant(markers[i].q);
      cp.SetParameterBlockConstant(markers[i].t);
    } else {
      cp.SetManifold(markers[i].q, &quaternion_manifold);
    }
  }

  BaSummary summary;
  if (cp.NumResidualBlocks() == 0) {
    summary.message = "nothing to optimise";
    return summary;
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_SCHUR;
  so.max_num_iterations = options.max_iterations;
  so.num_threads = options.threads;
  so.function_tolerance = options.function_tolerance;
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary cs;
  ceres::Solve(so, &cp, &cs);

  summary.usable = cs.IsSolutionUsable();
  summary.iterations = static_cast<int>(cs.iterations.size());
  summary.initial_cost = cs.initial_cost;
  summary.final_cost = cs.final_cost;
  summary.message = cs.BriefReport();
  if (summary.usable) {
    for (size_t i = 0; i < cameras.size(); ++i) {
      if (camera_used[i]) P.camera_from_room[i] = cameras[i].Get();
    }
    for (size_t i = 0; i < markers.size(); ++i) {
      if (marker_used[i] && !P.marker_fixed[i]) P.room_from_marker[i] = markers[i].Get();
    }
    for (size_t i = 0; i < planes.size(); ++i) {
      if (!plane_used[i]) continue;
      P.planes[i].normal = Eigen::Vector3d(planes[i][0], planes[i][1], planes[i][2]).normalized();
      P.planes[i].offset = planes[i][3];
    }
    if (!options.covariance_markers.empty()) {
      const auto t_cov = std::chrono::steady_clock::now();
      const int ref = options.covariance_reference;
      ARPOS_CHECK(ref >= 0 && ref < static_cast<int>(markers.size()), "covariance reference out of range");
      auto free_marker = [&](int m) {
        return m >= 0 && m < static_cast<int>(markers.size()) && marker_used[m] && !P.marker_fixed[m];
      };
      // Blocks: the reference and each marker, with their cross terms.
      std::vector<const double*> ids;
      if (free_marker(ref)) {
        ids.push_back(markers[ref].q);
        ids.push_back(markers[ref].t);
      }
      const size_t ref_blocks = ids.size();
      std::vector<double*> parameter_blocks;
      cp.GetParameterBlocks(&parameter_blocks);
      for (double* x : parameter_blocks) {
        if (cp.IsParameterBlockConstant(x)) continue;
        cp.AddResidualBlock(new WeakPriorCost(x, cp.ParameterBlockSize(x)), nullptr, x);
      }
      std::set<const double*> landmark_blocks;
      for (size_t i = 0; i < P.landmarks_in_room.size(); ++i) {
        if (landmark_used[i]) landmark_blocks.insert(P.landmarks_in_room[i].data());
      }
      // The reference's blocks and every wanted marker's, jointly.
      std::vector<const double*> wanted(ids.begin(), ids.begin() + ref_blocks);
      for (int m : options.covariance_markers) {
        if (!free_marker(m) || m == ref) continue;
        wanted.push_back(markers[m].q);
        wanted.push_back(markers[m].t);
      }
      Eigen::MatrixXd joint_all;
      const bool ok = wanted.empty() || MarginalCovariance(&cp, landmark_blocks, wanted, options.threads, &joint_all);
      auto block_offset = [&](const double* x) {
        int offset = 0;
        for (const double* w : wanted) {
          if (w == x) return offset;
          offset += 3;  // every wanted block (quaternion, translation) has 3 tangent dimensions
        }
        return -1;
      };
      const Rigid3d reference = P.room_from_marker[ref];
      const Eigen::Matrix3d Rt = reference.rotation.toRotationMatrix().transpose();
      for (int m : options.covariance_markers) {
        Eigen::Matrix3d c = Eigen::Matrix3d::Constant(std::numeric_limits<double>::infinity());
        Eigen::Matrix3d rc = c;
        const bool fixed = m >= 0 && m < static_cast<int>(markers.size()) && P.marker_fixed[m];
        if (m == ref || (fixed && ref_blocks == 0)) {  // nothing between them varies
          c.setZero();
          rc.setZero();
        } else if (ok && m >= 0 && m < static_cast<int>(markers.size()) && marker_used[m] &&
                   (free_marker(m) || ref_blocks)) {
          // A fixed marker (the map's root) varies only through the reference.
          std::vector<const double*> these(ids.begin(), ids.begin() + ref_blocks);
          if (free_marker(m)) {
            these.push_back(markers[m].q);
            these.push_back(markers[m].t);
          }
          const int n = 3 * static_cast<int>(these.size());
          Eigen::MatrixXd joint(n, n);
          for (int i = 0; i < static_cast<int>(these.size()); ++i) {
            for (int j = 0; j < static_cast<int>(these.size()); ++j) {
              joint.block<3, 3>(3 * i, 3 * j) = joint_all.block<3, 3>(block_offset(these[i]), block_offset(these[j]));
            }
          }
          {
            // Centre of m in the reference's frame: R_ref^T (t_m - t_ref).
            // Quaternion increments are half angles on the left (Ceres's
            // EigenQuaternionManifold): the rotation is twice the increment.
            const Eigen::Vector3d d = P.room_from_marker[m].translation - reference.translation;
            Eigen::Matrix3d dx;
            dx << 0, -d.z(), d.y(), d.z(), 0, -d.x(), -d.y(), d.x(), 0;
            Eigen::MatrixXd J = Eigen::MatrixXd::Zero(3, n);
            if (ref_blocks) {
              J.block<3, 3>(0, 0) = 2 * dx;
              J.block<3, 3>(0, 3) = -Eigen::Matrix3d::Identity();
            }
            if (free_marker(m)) J.block<3, 3>(0, n - 3) = Eigen::Matrix3d::Identity();
            c = Rt * (J * joint * J.transpose()) * Rt.transpose();
            // Orientation of m in the reference's frame, R_ref^T R_m: a left
            // increment of either turns it by twice the increment.
            Eigen::MatrixXd Jr = Eigen::MatrixXd::Zero(3, n);
            if (ref_blocks) Jr.block<3, 3>(0, 0) = -2 * Eigen::Matrix3d::Identity();
            if (free_marker(m)) Jr.block<3, 3>(0, n - 6) = 2 * Eigen::Matrix3d::Identity();
            rc = Rt * (Jr * joint * Jr.transpose()) * Rt.transpose();
          }
        }
        summary.relative_centre_covariance.push_back(c);
        summary.relative_rotation_covariance.push_back(rc);
      }
      summary.covariance_seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t_cov).count();
    }
  }
  summary.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

BaResiduals ComputeBaResiduals(const BaProblem& P) {
  BaResiduals out;
  const std::array<Eigen::Vector3d, 4> in_marker = MarkerCornersInMarker(P.marker_size_m);
  const CameraIntrinsics& k = P.intrinsics;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const auto& o : P.marker_observations) {
    const Rigid3d camera_from_marker = P.camera_from_room[o.camera] * P.room_from_marker[o.marker];
    double sum = 0;
    for (int c = 0; c < 4; ++c) {
      sum += (k.Project(camera_from_marker * in_marker[c]) - o.corners_px[c]).squaredNorm();
    }
    out.marker_rms_px.push_back(std::sqrt(sum / 4));
    if (o.depth_samples.empty()) {
      out.marker_depth_ratio.push_back(nan);
      continue;
    }
    const Eigen::Vector3d normal = camera_from_marker.rotation * Eigen::Vector3d::UnitZ();
    const double d = normal.dot(camera_from_marker.translation);
    std::vector<double> ratios;
    for (const auto& s : o.depth_samples) {
      const Eigen::Vector3d ray((s.pixel.x() - k.cx) / k.fx, (s.pixel.y() - k.cy) / k.fy, 1.0);
      const double z = d / normal.dot(ray);
      if (z > 0) ratios.push_back(s.depth_m / z);
    }
    if (ratios.empty()) {
      out.marker_depth_ratio.push_back(nan);
    } else {
      std::nth_element(ratios.begin(), ratios.begin() + ratios.size() / 2, ratios.end());
      out.marker_depth_ratio.push_back(ratios[ratios.size() / 2]);
    }
  }
  for (const auto& o : P.keypoint_observations) {
    const Eigen::Vector3d p = P.camera_from_room[o.camera] * P.landmarks_in_room[o.landmark];
    out.keypoint_px.push_back(p.z() > 0 ? (k.Project(p) - o.pixel).norm() : 1e9);
    out.keypoint_depth_m.push_back(o.depth_m > 0 ? p.z() - o.depth_m : nan);
  }
  return out;
}

}  // namespace arpos
