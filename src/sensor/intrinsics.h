#pragma once
/// Pinhole camera model of a case (DATASET.md, `case.yaml` key `camera`).
///
/// Pixel coordinates follow OpenCV: the centre of the top-left pixel is (0, 0).
/// A camera point p = (x, y, z) (OpenCV camera frame: x right, y down, z
/// forward, metres) projects to u = fx x/z + cx, v = fy y/z + cy before
/// distortion. Depth images are registered to the colour camera, so one model
/// serves both; a depth pixel value d means z = d / depth_scale metres.

#include <Eigen/Core>
#include <array>
#include <opencv2/core.hpp>
#include <string>

namespace arpos {

struct CameraIntrinsics {
  int width = 0;
  int height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  std::array<double, 5> distortion{{0, 0, 0, 0, 0}};  ///< OpenCV k1 k2 p1 p2 k3
  double depth_scale = 1000.0;                         ///< depth PNG units per metre

  /// Empty string if valid, else a sentence naming the first bad field
  /// (e.g. "fx must be positive, got -5").
  std::string Validate() const;
  bool HasDistortion() const;

  Eigen::Matrix3d K() const;
  cv::Matx33d CvK() const;
  cv::Mat CvDistortion() const;  ///< 1x5 CV_64F

  /// Projection ignoring distortion; z must be > 0.
  Eigen::Vector2d Project(const Eigen::Vector3d& point_in_camera) const {
    return {fx * point_in_camera.x() / point_in_camera.z() + cx,
            fy * point_in_camera.y() / point_in_camera.z() + cy};
  }
  /// Back-projection of pixel (u, v) at depth z (metres), ignoring distortion.
  Eigen::Vector3d Unproject(double u, double v, double z) const {
    return {(u - cx) / fx * z, (v - cy) / fy * z, z};
  }
};

}  // namespace arpos
