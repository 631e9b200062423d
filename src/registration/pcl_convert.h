#pragma once
/// PointCloud -> PCL clouds, for the registration layer's PCL translation
/// units only (pcl_gicp.cc, features.cc, poisson.cc): no other file may
/// include this header, so PCL stays out of the rest of the build.

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "registration/point_cloud.h"

namespace arpos {

/// Points and normals as float; the cloud must have normals.
inline pcl::PointCloud<pcl::PointNormal>::Ptr ToPclPointNormals(const PointCloud& cloud) {
  pcl::PointCloud<pcl::PointNormal>::Ptr out(new pcl::PointCloud<pcl::PointNormal>);
  out->resize(cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) {
    pcl::PointNormal& p = (*out)[i];
    p.x = static_cast<float>(cloud.points[i].x());
    p.y = static_cast<float>(cloud.points[i].y());
    p.z = static_cast<float>(cloud.points[i].z());
    p.normal_x = static_cast<float>(cloud.normals[i].x());
    p.normal_y = static_cast<float>(cloud.normals[i].y());
    p.normal_z = static_cast<float>(cloud.normals[i].z());
  }
  return out;
}

/// Points as float.
inline pcl::PointCloud<pcl::PointXYZ>::Ptr ToPclPoints(const PointCloud& cloud) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr out(new pcl::PointCloud<pcl::PointXYZ>);
  out->resize(cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector4d& p = cloud.points[i];
    (*out)[i] = pcl::PointXYZ(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
  }
  return out;
}

}  // namespace arpos
