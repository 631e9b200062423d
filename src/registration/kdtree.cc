#include "registration/kdtree.h"

#include <algorithm>
#include <cmath>

#include "util/check.h"

namespace arpos {
namespace {

// Sorted fixed-capacity buffer of the k best candidates.
class KnnSet {
 public:
  KnnSet(int k, size_t* indices, double* dists, double bound)
      : k_(k), indices_(indices), dists_(dists), bound_(bound) {}
  double worst() const { return count_ < k_ ? bound_ : dists_[k_ - 1]; }
  void Add(double d, size_t index) {
    int i = count_ < k_ ? count_++ : k_ - 1;
    while (i > 0 && dists_[i - 1] > d) {
      dists_[i] = dists_[i - 1];
      indices_[i] = indices_[i - 1];
      --i;
    }
    dists_[i] = d;
    indices_[i] = index;
  }
  int count() const { return count_; }

 private:
  int k_;
  int count_ = 0;
  size_t* indices_;
  double* dists_;
  double bound_;
};

class NearestSet {
 public:
  explicit NearestSet(double bound) : best_(bound) {}
  double worst() const { return best_; }
  void Add(double d, size_t index) {
    best_ = d;
    index_ = index;
    found_ = true;
  }
  bool found_ = false;
  double best_;
  size_t index_ = 0;
};

class RadiusSet {
 public:
  // Candidates are added when d < worst(); nextafter makes the radius inclusive.
  RadiusSet(double r2, std::vector<size_t>* out)
      : bound_(std::nextafter(r2, std::numeric_limits<double>::infinity())), out_(out) {}
  double worst() const { return bound_; }
  void Add(double, size_t position) { out_->push_back(position); }

 private:
  double bound_;
  std::vector<size_t>* out_;
};

}  // namespace

std::string KdTreeOptions::Validate() const {
  if (max_leaf_size < 1) return "max_leaf_size must be >= 1";
  return "";
}

KdTree::KdTree(const PointCloud& cloud, const KdTreeOptions& options) {
  points_ = cloud.points;
  for (auto& p : points_) p.w() = 1.0;
  Build(options);
}

KdTree::KdTree(const std::vector<Eigen::Vector3d>& points_m, const KdTreeOptions& options) {
  points_.reserve(points_m.size());
  for (const auto& p : points_m) points_.emplace_back(p.x(), p.y(), p.z(), 1.0);
  Build(options);
}

void KdTree::Build(const KdTreeOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "KdTreeOptions: " << problem);
  ARPOS_CHECK(points_.size() < std::numeric_limits<uint32_t>::max(),
              "kd-tree of " << points_.size() << " points is too large");
  for (size_t i = 0; i < points_.size(); ++i) {
    ARPOS_CHECK(points_[i].allFinite(), "kd-tree point " << i << " is not finite");
  }
  indices_.resize(points_.size());
  for (size_t i = 0; i < indices_.size(); ++i) indices_[i] = static_cast<uint32_t>(i);
  nodes_.clear();
  if (points_.empty()) return;
  nodes_.reserve(2 * points_.size() / options.max_leaf_size + 2);
  BuildNode(0, static_cast<uint32_t>(points_.size()), options.max_leaf_size);
  // Reorder the copy so that every leaf reads contiguous memory.
  std::vector<Eigen::Vector4d> reordered(points_.size());
  for (size_t i = 0; i < indices_.size(); ++i) reordered[i] = points_[indices_[i]];
  points_.swap(reordered);
  Eigen::AlignedBox3d box;
  for (const auto& p : points_) box.extend(p.head<3>());
  root_min_ = box.min();
  root_max_ = box.max();
}

uint32_t KdTree::BuildNode(uint32_t begin, uint32_t end, int max_leaf) {
  const uint32_t id = static_cast<uint32_t>(nodes_.size());
  nodes_.emplace_back();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  for (uint32_t i = begin; i < end; ++i) {
    const Eigen::Vector3d p = points_[indices_[i]].head<3>();
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  int axis = 0;
  (hi - lo).maxCoeff(&axis);
  if (static_cast<int>(end - begin) <= max_leaf || hi[axis] <= lo[axis]) {
    nodes_[id].begin = begin;
    nodes_[id].end = end;
    nodes_[id].axis = -1;
    return id;
  }
  const uint32_t mid = begin + (end - begin) / 2;
  std::nth_element(indices_.begin() + begin, indices_.begin() + mid, indices_.begin() + end,
                   [&](uint32_t a, uint32_t b) { return points_[a][axis] < points_[b][axis]; });
  const double split = points_[indices_[mid]][axis];
  const uint32_t left = BuildNode(begin, mid, max_leaf);
  const uint32_t right = BuildNode(mid, end, max_leaf);
  Node& node = nodes_[id];
  node.axis = axis;
  node.split = split;
  node.left = left;
  node.right = right;
  node.begin = begin;
  node.end = end;
  return id;
}

template <class Set>
void KdTree::SearchNode(uint32_t id, const Eigen::Vector4d& query, double mindist,
                        double* dists, Set& set) const {
  const Node& node = nodes_[id];
  if (node.axis < 0) {
    for (uint32_t i = node.begin; i < node.end; ++i) {
      const double d = (points_[i] - query).squaredNorm();
      if (d < set.worst()) set.Add(d, i);  // tree position; mapped by the caller
    }
    return;
  }
  const int axis = node.axis;
  const double diff = query[axis] - node.split;
  const uint32_t near_child = diff < 0 ? node.left : node.right;
  const uint32_t far_child = diff < 0 ? node.right : node.left;
  SearchNode(near_child, query, mindist, dists, set);
  const double cut = diff * diff;
  const double far_mindist = mindist - dists[axis] + cut;
  if (far_mindist < set.worst()) {
    const double saved = dists[axis];
    dists[axis] = cut;
    SearchNode(far_child, query, far_mindist, dists, set);
    dists[axis] = saved;
  }
}

template <class Set>
void KdTree::Search(const Eigen::Vector4d& query, Set& set) const {
  if (nodes_.empty()) return;
  double dists[3];
  double mindist = 0;
  for (int a = 0; a < 3; ++a) {
    const double below = root_min_[a] - query[a];
    const double above = query[a] - root_max_[a];
    dists[a] = below > 0 ? below * below : (above > 0 ? above * above : 0.0);
    mindist += dists[a];
  }
  if (mindist >= set.worst()) return;
  SearchNode(0, query, mindist, dists, set);
}

bool KdTree::Nearest(const Eigen::Vector4d& query, size_t* index, double* sq_dist_m2,
                     double max_sq_dist_m2) const {
  NearestSet set(max_sq_dist_m2);
  Search(Eigen::Vector4d(query.x(), query.y(), query.z(), 1.0), set);
  if (!set.found_) return false;
  *index = indices_[set.index_];
  *sq_dist_m2 = set.best_;
  return true;
}

size_t KdTree::Knn(const Eigen::Vector4d& query, int k, size_t* indices, double* sq_dists_m2,
                   double max_sq_dist_m2) const {
  if (k <= 0) return 0;
  KnnSet set(k, indices, sq_dists_m2, max_sq_dist_m2);
  Search(Eigen::Vector4d(query.x(), query.y(), query.z(), 1.0), set);
  const int n = set.count();
  for (int i = 0; i < n; ++i) indices[i] = indices_[indices[i]];
  return static_cast<size_t>(n);
}

size_t KdTree::KnnWithPoints(const Eigen::Vector4d& query, int k, size_t* indices,
                             double* sq_dists_m2, Eigen::Vector4d* points) const {
  if (k <= 0) return 0;
  KnnSet set(k, indices, sq_dists_m2, std::numeric_limits<double>::infinity());
  Search(Eigen::Vector4d(query.x(), query.y(), query.z(), 1.0), set);
  const int n = set.count();
  for (int i = 0; i < n; ++i) {
    points[i] = points_[indices[i]];
    indices[i] = indices_[indices[i]];
  }
  return static_cast<size_t>(n);
}

void KdTree::RadiusSearch(const Eigen::Vector4d& query, double radius_m,
                          std::vector<size_t>* indices) const {
  indices->clear();
  if (radius_m < 0) return;
  RadiusSet set(radius_m * radius_m, indices);
  Search(Eigen::Vector4d(query.x(), query.y(), query.z(), 1.0), set);
  for (size_t& i : *indices) i = indices_[i];
}

std::vector<size_t> KdTree::Knn(const Eigen::Vector3d& query, int k) const {
  std::vector<size_t> indices(std::max(k, 0));
  std::vector<double> dists(std::max(k, 0));
  const size_t n = Knn(Eigen::Vector4d(query.x(), query.y(), query.z(), 1.0), k,
                       indices.data(), dists.data());
  indices.resize(n);
  return indices;
}

}  // namespace arpos
