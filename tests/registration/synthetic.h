#pragma once
// Synthetic surfaces, depth renders and random poses for the registration
// tests and benchmarks. Everything is deterministic for a given seed.

#include <Eigen/Core>
#include <cstdint>
#include <opencv2/core.hpp>
#include <random>

#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "registration/point_cloud.h"
#include "sensor/intrinsics.h"

namespace arpos::testing {

/// UV ellipsoid centred at the origin, outward counter-clockwise faces.
TriangleMesh MakeEllipsoid(const Eigen::Vector3d& radii_m, int stacks = 48, int slices = 96);
/// Open cylinder along z, centred at the origin.
TriangleMesh MakeCylinder(double radius_m, double length_m, int stacks = 40, int slices = 96);
/// Square plane z = 0, normal +z, side `size_m`.
TriangleMesh MakePlane(double size_m, int cells = 40);

/// The MakeHuman base mesh, group "body", in metres (dm -> m), model frame of
/// the file, loaded once.
const TriangleMesh& BodyMesh();

/// Pinhole 640x480, f = 540 (the simulator's xtion profile).
CameraIntrinsics TestIntrinsics();

/// Exact z-buffer depth (CV_32FC1, metres, 0 = background) of `mesh` seen
/// from a camera at camera_from_mesh; depth at pixel centres.
cv::Mat RenderDepth(const TriangleMesh& mesh, const CameraIntrinsics& intrinsics,
                    const Rigid3d& camera_from_mesh);

/// Camera at `eye` looking at `target` (OpenCV camera axes), `up` roughly
/// opposite to the image y axis. Returns mesh_from_camera.
Rigid3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
               const Eigen::Vector3d& up);

/// Random rigid transform: rotation about a uniform random axis by an angle
/// uniform in [0, max_angle_rad], translation uniform in the ball of radius
/// max_translation_m.
Rigid3d RandomPose(std::mt19937_64& rng, double max_translation_m, double max_angle_rad);

/// Adds Gaussian noise of sigma_m to every point (along a random direction
/// per axis).
void AddNoise(PointCloud* cloud, double sigma_m, uint64_t seed);

/// Translation (m) and rotation (rad) of a_from_b^-1 * c: how far two
/// estimates of the same transform differ.
double TranslationError(const Rigid3d& truth, const Rigid3d& estimate);
double RotationErrorRad(const Rigid3d& truth, const Rigid3d& estimate);

}  // namespace arpos::testing
