// session_eval: accuracy of the session stage on a simulated case (not a
// test; prints a report). Runs run-case (plan + session) into a temporary
// store, then the session stage again to get its in-memory result, and
// compares with simulation.yaml and body_scan/body_groundtruth.txt:
//   - body-marker (sticker) positions: estimated room_from_marker at scan
//     time against the truth (mm), and their orientation (deg);
//   - reconstruction surface error: distance of every reconstruction point
//     to the true body surface (the reference model at the true pose,
//     sampled every 0.5 mm; the model carries 0.3 mm of simulated noise);
//   - model pose at scan time against body_groundtruth.txt, split into the
//     scan's placement in the room and the model's alignment within the
//     scan, and the error of the room map's own poses of the scan frames;
//   - the stage's step times.
//
//   session_eval CASE_DIR
#include <algorithm>
#include <cstdio>
#include <iostream>

#include "controllers/run_case_controller.h"
#include "controllers/session_controller.h"
#include "geometry/mesh_io.h"
#include "geometry/pose_error.h"
#include "geometry/so3.h"
#include "registration/kdtree.h"
#include "registration/mesh_cloud.h"
#include "sensor/tum_io.h"
#include "simulation/simulation_truth.h"
#include "store/sqlite_database.h"
#include "util/check.h"
#include "util/file.h"

using namespace arpos;

namespace {

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * (v.size() - 1) + 0.5))];
}

double Mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0 : s / v.size();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2 || std::string(argv[1]) == "--help") {
    std::cerr << "usage: session_eval CASE_DIR\n";
    return 2;
  }
  try {
    const std::filesystem::path case_dir = argv[1];
    TempDir dir;
    auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
    RunCaseOptions run_options;
    run_options.case_dir = case_dir;
    run_options.read_all_images = false;
    RunCaseController run(run_options, db.get());
    run.Run();
    if (!run.result().ok()) {
      std::cerr << run.result().Summary();
      return 1;
    }
    SessionStageOptions options;
    options.case_dir = case_dir;
    options.plan_id = run.result().plan_id;
    SessionController session(options, db.get());
    session.Run();
    const SessionStageResult& r = session.result();
    std::cout << r.Summary();

    const sim::SimulationTruth truth = sim::LoadSimulationTruth(case_dir / "simulation.yaml");
    const auto gt = ReadTrajectory(case_dir / "body_scan" / "body_groundtruth.txt");
    ARPOS_CHECK(!gt.empty(), "no body ground truth");
    const Rigid3d room_from_model = gt.front().room_from_x;

    // Stickers.
    std::vector<double> sticker_mm, sticker_deg, model_sticker_mm, model_sticker_deg;
    for (const auto& e : r.marker_map.markers) {
      for (const auto& m : truth.body_markers) {
        if (m.id != e.marker_id) continue;
        const PoseError err = ComputePoseError(room_from_model * m.parent_from_marker, e.room_from_marker);
        sticker_mm.push_back(err.translation_mm);
        sticker_deg.push_back(err.rotation_deg);
        // What tracking uses: the sticker in the model frame.
        const PoseError rel = ComputePoseError(m.parent_from_marker, r.model_from_markers.at(e.marker_id));
        model_sticker_mm.push_back(rel.translation_mm);
        model_sticker_deg.push_back(rel.rotation_deg);
      }
    }
    std::printf("stickers: %zu mapped of %zu on the body; position error mean %.2f mm, median %.2f, max %.2f; "
                "orientation mean %.2f deg, max %.2f\n",
                sticker_mm.size(), truth.body_markers.size(), Mean(sticker_mm), Percentile(sticker_mm, 0.5),
                Percentile(sticker_mm, 1.0), Mean(sticker_deg), Percentile(sticker_deg, 1.0));

    std::printf("stickers in the model frame (model_from_marker, what tracking uses): position error mean "
                "%.2f mm, max %.2f; orientation mean %.2f deg, max %.2f\n",
                Mean(model_sticker_mm), Percentile(model_sticker_mm, 1.0), Mean(model_sticker_deg),
                Percentile(model_sticker_deg, 1.0));

    // Final scan cameras against the camera ground truth, by where their
    // pose came from; error in camera axes (z: along the optical axis).
    {
      const auto cam_gt = ReadTrajectory(case_dir / "body_scan" / "groundtruth.txt");
      for (int kind = 0; kind < 4; ++kind) {
        std::vector<double> err_mm, lateral_mm, axial_mm, deg;
        for (const ScanCameraPose& c : r.scan_cameras) {
          const int k = c.registered_to_surface ? 3 : c.from_stickers ? (c.room_localized ? 1 : 2) : 0;
          if (k != kind) continue;
          for (const auto& g : cam_gt) {
            if (std::abs(g.timestamp_s - c.timestamp_s) > 1e-3) continue;
            const PoseError e = ComputePoseError(g.room_from_x, c.room_from_camera);
            // Camera-centre error in the true camera's axes.
            const Eigen::Vector3d d = g.room_from_x.rotation.inverse() *
                                      (c.room_from_camera.translation - g.room_from_x.translation);
            err_mm.push_back(e.translation_mm);
            lateral_mm.push_back(1000 * d.head<2>().norm());
            axial_mm.push_back(1000 * d.z());
            deg.push_back(e.rotation_deg);
          }
        }
        static const char* kNames[] = {"room map only", "stickers, room-localised too", "stickers only",
                                       "registered to the reconstruction"};
        if (err_mm.empty()) continue;
        std::printf("scan cameras (%s): %zu, centre error mean %.2f mm, median %.2f, max %.2f (lateral mean %.2f, "
                    "along the axis mean %+.2f); rotation mean %.3f deg\n",
                    kNames[kind], err_mm.size(), Mean(err_mm), Percentile(err_mm, 0.5), Percentile(err_mm, 1.0),
                    Mean(lateral_mm), Mean(axial_mm), Mean(deg));
      }
    }

    // The model pose's error split in two: the scan's placement in the room
    // (the mean error, as a rigid offset at the estimated isocentre, of the
    // cameras registered to the reconstruction: what moves the whole scan)
    // and the model's alignment within the scan (the model pose with that
    // offset taken off). And the room map's own poses of the room-localised
    // frames, the placement's input: their mean error at the isocentre (what
    // averaging cannot remove) and their spread.
    {
      const auto cam_gt = ReadTrajectory(case_dir / "body_scan" / "groundtruth.txt");
      const Eigen::Vector3d iso = r.room_from_model.translation;
      auto offset_at_iso = [&](const Rigid3d& true_from_estimated) {
        Eigen::Matrix<double, 6, 1> v;
        v << true_from_estimated.RotationVector(), true_from_estimated * iso - iso;
        return v;
      };
      auto mean_of = [](const std::vector<Eigen::Matrix<double, 6, 1>>& v) {
        Eigen::Matrix<double, 6, 1> m = Eigen::Matrix<double, 6, 1>::Zero();
        for (const auto& x : v) m += x;
        return v.empty() ? m : Eigen::Matrix<double, 6, 1>(m / static_cast<double>(v.size()));
      };
      std::vector<Eigen::Matrix<double, 6, 1>> registered, localized;
      std::vector<double> localized_mm;
      for (const ScanCameraPose& c : r.scan_cameras) {
        for (const auto& g : cam_gt) {
          if (std::abs(g.timestamp_s - c.timestamp_s) > 1e-3) continue;
          if (c.registered_to_surface) {
            registered.push_back(offset_at_iso(g.room_from_x * c.room_from_camera.Inverse()));
          }
          if (c.room_localized) {
            localized.push_back(offset_at_iso(g.room_from_x * c.localized_room_from_camera.Inverse()));
            localized_mm.push_back(1000 * localized.back().tail<3>().norm());
          }
        }
      }
      if (!registered.empty()) {
        const Eigen::Matrix<double, 6, 1> m = mean_of(registered);
        const Rigid3d placement = Rigid3d::FromRotationVector(m.head<3>(), Eigen::Vector3d::Zero());
        const Rigid3d true_from_estimated(placement.rotation, iso + m.tail<3>() - placement * iso);
        const PoseError aligned = ComputePoseError(room_from_model, true_from_estimated * r.room_from_model);
        std::printf("scan placement at the isocentre (mean of %zu registered cameras): %.2f mm (%+.2f %+.2f %+.2f), "
                    "%.3f deg; model within the scan: %.2f mm, %.3f deg\n",
                    registered.size(), 1000 * m.tail<3>().norm(), 1000 * m(3), 1000 * m(4), 1000 * m(5),
                    DegFromRad(m.head<3>().norm()), aligned.translation_mm, aligned.rotation_deg);
      }
      // The offsets the session averages (room-localised frames registered
      // to the surface, at the isocentre): their spread over sqrt(frames)
      // and over sqrt(runs of consecutive frames), against the placement's
      // error above (consecutive frames share their error).
      {
        std::vector<std::pair<double, Eigen::Vector3d>> o;
        for (const ScanCameraPose& c : r.scan_cameras) {
          if (!c.room_localized || !c.registered_to_surface) continue;
          const Rigid3d off = c.localized_room_from_camera * c.room_from_camera.Inverse();
          o.push_back({c.timestamp_s, off * iso - iso});
        }
        std::sort(o.begin(), o.end(),
                  [](const auto& a, const auto& b) { return a.first < b.first; });
        std::vector<double> gaps;
        for (size_t i = 1; i < o.size(); ++i) gaps.push_back(o[i].first - o[i - 1].first);
        const double step = gaps.empty() ? 0 : *std::min_element(gaps.begin(), gaps.end());
        int runs = o.empty() ? 0 : 1;
        for (double g : gaps) runs += g > 1.5 * step ? 1 : 0;
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        for (const auto& p : o) mean += p.second;
        if (!o.empty()) mean /= static_cast<double>(o.size());
        double ss = 0;
        for (const auto& p : o) ss += (p.second - mean).squaredNorm();
        const double s = o.size() > 1 ? std::sqrt(ss / (o.size() - 1)) : 0;
        std::printf(
            "offsets averaged: %zu frames in %d runs, spread %.2f mm; over sqrt(frames) %.2f, over "
            "sqrt(runs) %.2f\n",
            o.size(), runs, 1000 * s,
            o.empty() ? 0.0 : 1000 * s / std::sqrt(static_cast<double>(o.size())),
            runs ? 1000 * s / std::sqrt(static_cast<double>(runs)) : 0.0);
      }
      if (!localized.empty()) {
        const Eigen::Matrix<double, 6, 1> m = mean_of(localized);
        std::printf("room-localised frames at the isocentre: %zu, mean error %.2f mm (%+.2f %+.2f %+.2f); "
                    "per frame mean %.2f mm, median %.2f, max %.2f\n",
                    localized.size(), 1000 * m.tail<3>().norm(), 1000 * m(3), 1000 * m(4), 1000 * m(5),
                    Mean(localized_mm), Percentile(localized_mm, 0.5), Percentile(localized_mm, 1.0));
      }
    }

    // Reconstruction surface error against the true surface.
    const TriangleMesh model = LoadTriangleMesh(case_dir / "reference_model.ply");
    PointCloud surface = SampleMeshSurface(model, 0.0005);
    surface.Transform(room_from_model);
    const KdTree tree(surface);
    std::vector<double> dist_mm;
    for (size_t i = 0; i < r.reconstruction.size(); ++i) {
      size_t index;
      double sq;
      if (tree.Nearest(r.reconstruction.points[i], &index, &sq)) dist_mm.push_back(1000 * std::sqrt(sq));
    }
    std::printf("reconstruction: %zu points; distance to the true surface mean %.2f mm, median %.2f, p95 %.2f, "
                "max %.2f\n",
                dist_mm.size(), Mean(dist_mm), Percentile(dist_mm, 0.5), Percentile(dist_mm, 0.95),
                Percentile(dist_mm, 1.0));
    const PoseError pose = ComputePoseError(room_from_model, r.room_from_model);
    std::printf("model pose at scan time: %.2f mm, %.3f deg\n", pose.translation_mm, pose.rotation_deg);
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "session_eval: " << e.what() << "\n";
    return 1;
  }
}
