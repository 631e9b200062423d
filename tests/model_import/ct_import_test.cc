// The real CT series (TotalSegmentator example, JPEG 2000 compressed, anonymised):
// reading, body surface, and refusal of broken series.
#include <gdcmDataSet.h>
#include <gtest/gtest.h>

#include <chrono>
#include <deque>

#include "model_import/model_import.h"
#include "model_import/test_util.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos {
namespace {

using test::CtSeriesDir;

std::vector<fs::path> SeriesFiles() {
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(CtSeriesDir())) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

std::string CtErrorMessage(const fs::path& folder) {
  try {
    ReadCtSeries(folder);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

std::string ImportErrorMessage(const fs::path& input, const ModelImportOptions& options = {}) {
  try {
    ImportModel(input, options);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

// Per-slice trunk by the simplest independent means: HU >= -350, 4-connected
// flood fill from the image centre, no opening. Its bounding box in the
// patient frame (mm) and per-slice areas are what the surface must match.
struct TrunkReference {
  Eigen::Vector3d min_mm = Eigen::Vector3d::Constant(1e9), max_mm = Eigen::Vector3d::Constant(-1e9);
  std::vector<double> area_mm2;
};

TrunkReference MeasureTrunk(const CtVolume& ct) {
  const VolumeGeometry& g = ct.geometry;
  TrunkReference ref;
  for (int k = 0; k < g.size[2]; ++k) {
    std::vector<char> seen(static_cast<size_t>(g.size[0]) * g.size[1], 0);
    std::deque<std::pair<int, int>> queue{{g.size[0] / 2, g.size[1] / 2}};
    EXPECT_GE(ct.hu[g.Index(g.size[0] / 2, g.size[1] / 2, k)], -350) << "centre not in the body";
    seen[static_cast<size_t>(g.size[1] / 2) * g.size[0] + g.size[0] / 2] = 1;
    size_t count = 0;
    while (!queue.empty()) {
      const auto [i, j] = queue.front();
      queue.pop_front();
      ++count;
      const Eigen::Vector3d p = g.PatientFromIndexMm(Eigen::Vector3d(i, j, k));
      ref.min_mm = ref.min_mm.cwiseMin(p);
      ref.max_mm = ref.max_mm.cwiseMax(p);
      const int di[4] = {1, -1, 0, 0}, dj[4] = {0, 0, 1, -1};
      for (int n = 0; n < 4; ++n) {
        const int a = i + di[n], b = j + dj[n];
        if (a < 0 || b < 0 || a >= g.size[0] || b >= g.size[1]) continue;
        char& s = seen[static_cast<size_t>(b) * g.size[0] + a];
        if (s || ct.hu[g.Index(a, b, k)] < -350) continue;
        s = 1;
        queue.emplace_back(a, b);
      }
    }
    // Area inside the outline: everything not reachable from the image border
    // without crossing the trunk (lungs and gas count as inside).
    std::deque<std::pair<int, int>> outside;
    for (int i = 0; i < g.size[0]; ++i) {
      for (int j : {0, g.size[1] - 1}) outside.emplace_back(i, j);
    }
    for (int j = 0; j < g.size[1]; ++j) {
      for (int i : {0, g.size[0] - 1}) outside.emplace_back(i, j);
    }
    size_t outside_count = 0;
    for (auto& [i, j] : outside) {
      char& s = seen[static_cast<size_t>(j) * g.size[0] + i];
      if (s) continue;
      s = 2;
    }
    while (!outside.empty()) {
      const auto [i, j] = outside.front();
      outside.pop_front();
      char& here = seen[static_cast<size_t>(j) * g.size[0] + i];
      if (here != 2) continue;  // trunk, or counted already
      here = 3;
      ++outside_count;
      const int di[4] = {1, -1, 0, 0}, dj[4] = {0, 0, 1, -1};
      for (int n = 0; n < 4; ++n) {
        const int a = i + di[n], b = j + dj[n];
        if (a < 0 || b < 0 || a >= g.size[0] || b >= g.size[1]) continue;
        char& s = seen[static_cast<size_t>(b) * g.size[0] + a];
        if (s) continue;
        s = 2;
        outside.emplace_back(a, b);
      }
    }
    const size_t inside = static_cast<size_t>(g.size[0]) * g.size[1] - outside_count;
    EXPECT_GE(inside, count);
    ref.area_mm2.push_back(inside * g.spacing_mm.x() * g.spacing_mm.y());
  }
  return ref;
}

// Read and imported once per process, and only by the tests that need them
// (ctest runs every test in its own process).
class RealCt : public ::testing::Test {
 protected:
  static const CtVolume& Ct() {
    static const CtVolume ct = ReadCtSeries(CtSeriesDir());
    return ct;
  }
  static const ModelImportResult& Model() {
    static const ModelImportResult model = [] {
      const auto start = std::chrono::steady_clock::now();
      ModelImportResult result = ImportModel(CtSeriesDir(), {});
      import_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      return result;
    }();
    return model;
  }
  static double import_s_;
};
double RealCt::import_s_ = 0;

TEST_F(RealCt, SeriesIsSortedByPositionWithHounsfieldUnits) {
  const VolumeGeometry& g = Ct().geometry;
  EXPECT_EQ(g.size[0], 512);
  EXPECT_EQ(g.size[1], 512);
  EXPECT_EQ(g.size[2], 20);
  EXPECT_NEAR(g.spacing_mm.x(), 0.9765625, 1e-9);
  EXPECT_NEAR(g.spacing_mm.y(), 0.9765625, 1e-9);
  EXPECT_NEAR(g.spacing_mm.z(), 2.0, 1e-6);  // 3 mm thick slices every 2 mm
  EXPECT_TRUE(g.patient_from_index_rotation.isIdentity(1e-9));
  EXPECT_LT((g.origin_mm - Eigen::Vector3d(-249.51171875, -437.51171875, -804.5)).norm(), 1e-6);
  // Slice order follows ImagePositionPatient: the file ...16573 is at z = -766.5, the top.
  EXPECT_EQ(Ct().files.back().filename().string(), "CT.1.3.12.2.1107.5.1.4.60064.30000022120808113428000016573");
  // That file stores 0..2460 with intercept -1024 (its header's smallest/largest pixel values).
  const size_t slice = 512 * 512;
  const auto [lo, hi] = std::minmax_element(Ct().hu.end() - slice, Ct().hu.end());
  EXPECT_EQ(*lo, -1024);
  EXPECT_EQ(*hi, 2460 - 1024);
  // Air in the corner and soft tissue in the middle.
  EXPECT_LT(Ct().hu[g.Index(5, 5, 10)], -900);
  EXPECT_GT(Ct().hu[g.Index(256, 256, 10)], -200);
  EXPECT_TRUE(Ct().series_instance_uid.empty());  // anonymised: no UID at all
  EXPECT_FALSE(Ct().frame_of_reference_uid.empty());
}

TEST_F(RealCt, SortingDoesNotDependOnFileNames) {
  TempDir dir;
  const auto files = SeriesFiles();
  // Reverse the name order: file i gets a name that sorts as 19 - i.
  for (size_t i = 0; i < files.size(); ++i) {
    fs::copy_file(files[i], dir.path() / ("IMG" + std::to_string(100 - i) + ".dcm"));
  }
  const CtVolume copy = ReadCtSeries(dir.path());
  EXPECT_EQ(copy.hu, Ct().hu);
  EXPECT_LT((copy.geometry.origin_mm - Ct().geometry.origin_mm).norm(), 1e-9);
}

TEST_F(RealCt, BodySurfaceMatchesTheTrunkAndExcludesCouchAndArms) {
  const ModelImportResult& r = Model();
  const MeshSummary& s = r.summary;
  const TrunkReference ref = MeasureTrunk(Ct());
  std::printf("[ measure  ] CT import %.2f s (read %.2f, segment %.2f, surface %.2f); %d vertices "
              "(%d extracted), %d faces, extent %.1f x %.1f x %.1f mm, closed %d, %d components\n",
              import_s_, r.read_s, r.segment_s, r.surface_s, s.num_vertices,
              r.surface_stats.extracted_vertices, s.num_faces, s.extent().x() * 1000,
              s.extent().y() * 1000, s.extent().z() * 1000, s.closed, s.num_components);
  EXPECT_EQ(r.kind, ModelSourceKind::kCtSeries);
  EXPECT_TRUE(s.closed);
  EXPECT_EQ(s.num_components, 1);
  EXPECT_LE(s.num_vertices, 100000);
  EXPECT_GT(s.signed_volume, 0);
  // In-plane extent: within 2 mm of the trunk (the couch spans the whole
  // field of view width and lies posterior; the arms lie beside the trunk).
  for (int a = 0; a < 2; ++a) {
    EXPECT_NEAR(s.min[a] * 1000, ref.min_mm[a], 2.0) << "axis " << a;
    EXPECT_NEAR(s.max[a] * 1000, ref.max_mm[a], 2.0) << "axis " << a;
  }
  // Along z: capped half a slice spacing beyond the first and last slice.
  EXPECT_NEAR(s.min.z() * 1000, -804.5 - 1.0, 0.5);
  EXPECT_NEAR(s.max.z() * 1000, -766.5 + 1.0, 0.5);
  // Nothing posterior of the trunk (DICOM +y is posterior: the couch side).
  int behind = 0;
  for (const auto& v : r.mesh.vertices) behind += v.y() * 1000 > ref.max_mm.y() + 2.0;
  EXPECT_EQ(behind, 0);
  // Cross-sections at slice positions match the trunk's area within 1.5 %.
  double worst_area_percent = 0;
  for (int k = 1; k + 1 < Ct().geometry.size[2]; ++k) {
    const double z_m = Ct().geometry.PatientFromIndexMm(Eigen::Vector3d(0, 0, k)).z() * 0.001;
    const double area_mm2 = test::CrossSectionAreaZ(r.mesh, z_m) * 1e6;
    EXPECT_NEAR(area_mm2, ref.area_mm2[k], 0.015 * ref.area_mm2[k]) << "slice " << k;
    const double percent = 100 * (area_mm2 - ref.area_mm2[k]) / ref.area_mm2[k];
    if (std::abs(percent) > std::abs(worst_area_percent)) worst_area_percent = percent;
  }
  std::printf("[ measure  ] CT surface vs trunk reference: x %+.1f/%+.1f mm, y %+.1f/%+.1f mm (min/max), "
              "worst slice area %+.2f %%\n",
              s.min.x() * 1000 - ref.min_mm.x(), s.max.x() * 1000 - ref.max_mm.x(), s.min.y() * 1000 - ref.min_mm.y(),
              s.max.y() * 1000 - ref.max_mm.y(), worst_area_percent);
  // The report says what was dropped.
  bool dropped_note = false;
  for (const auto& note : r.notes) dropped_note |= note.find("dropped") != std::string::npos;
  EXPECT_TRUE(dropped_note);
  EXPECT_GE(r.body_mask_stats.num_components, 3);  // trunk, two arms (the couch may be split)
}

TEST_F(RealCt, IsocentreOriginNeedsTheSameFrameOfReference) {
  // The dicompyler RTPLAN belongs to another patient: refused, naming both.
  ModelImportOptions options;
  options.origin = ModelOrigin::kIsocentre;
  options.rtplan_path = test::RtPlanFile();
  const std::string message = ImportErrorMessage(CtSeriesDir(), options);
  EXPECT_NE(message.find("rtplan.dcm"), std::string::npos) << message;
  EXPECT_NE(message.find("FrameOfReferenceUID"), std::string::npos) << message;
}

class BrokenSeries : public ::testing::Test {
 protected:
  // Copies of the real series with one thing broken.
  fs::path CopySeries(const std::string& name) {
    const fs::path dir = temp_.path() / name;
    fs::create_directories(dir);
    for (const auto& f : SeriesFiles()) {
      fs::copy_file(f, dir / f.filename());
      // The shared data is read-only and copy_file keeps that; the tests overwrite copies.
      fs::permissions(dir / f.filename(), fs::perms::owner_write, fs::perm_options::add);
    }
    return dir;
  }
  TempDir temp_;
};

TEST_F(BrokenSeries, MixedSeriesAreRefusedWithTheirUids) {
  const fs::path dir = CopySeries("mixed");
  const auto files = SeriesFiles();
  for (size_t i = 0; i < 5; ++i) {
    test::CopyDicomWithEdits(files[i], dir / files[i].filename(), [](gdcm::DataSet& ds) {
      test::SetText(ds, 0x0020, 0x000e, "UI", "1.2.826.0.1.3680043.2.1125.99");
    });
  }
  const std::string message = CtErrorMessage(dir);
  EXPECT_NE(message.find(dir.string()), std::string::npos) << message;
  EXPECT_NE(message.find("mixes 2 series"), std::string::npos) << message;
  EXPECT_NE(message.find("1.2.826.0.1.3680043.2.1125.99: 5 files"), std::string::npos) << message;
  EXPECT_NE(message.find("(none): 15 files"), std::string::npos) << message;
}

TEST_F(BrokenSeries, OtherObjectsAndNonDicomFilesAreSkipped) {
  const fs::path dir = CopySeries("with_extras");
  fs::copy_file(test::RtStructFile(), dir / "RS.dcm");  // an RTSTRUCT exported alongside
  test::WriteBytes(dir / "README.txt", "exported by a planning system\n");
  const CtVolume ct = ReadCtSeries(dir);
  EXPECT_EQ(ct.geometry.size[2], 20);
  EXPECT_EQ(ct.skipped_non_dicom_files, 1);
}

TEST_F(BrokenSeries, GapsTooFewSlicesAndDuplicatesAreRefused) {
  const auto files = SeriesFiles();
  {
    const fs::path dir = CopySeries("gap");
    fs::remove(dir / files[10].filename());  // a missing slice in the middle
    const std::string message = CtErrorMessage(dir);
    EXPECT_NE(message.find("inconsistent slice spacing"), std::string::npos) << message;
    EXPECT_NE(message.find("4 mm"), std::string::npos) << message;
  }
  {
    const fs::path dir = temp_.path() / "two";
    fs::create_directories(dir);
    fs::copy_file(files[0], dir / "a.dcm");
    fs::copy_file(files[1], dir / "b.dcm");
    const std::string message = CtErrorMessage(dir);
    EXPECT_NE(message.find("too few slices (2)"), std::string::npos) << message;
    EXPECT_NE(message.find(dir.string()), std::string::npos) << message;
  }
  {
    const fs::path dir = CopySeries("duplicate");
    fs::copy_file(files[4], dir / "copy_of_a_slice");
    const std::string message = CtErrorMessage(dir);
    EXPECT_NE(message.find("same position"), std::string::npos) << message;
  }
}

TEST_F(BrokenSeries, InconsistentGeometryIsRefused) {
  const auto files = SeriesFiles();
  {
    const fs::path dir = CopySeries("orientation");
    test::CopyDicomWithEdits(files[7], dir / files[7].filename(), [](gdcm::DataSet& ds) {
      test::SetText(ds, 0x0020, 0x0037, "DS", "0.9998\\0.0175\\0\\-0.0175\\0.9998\\0");
    });
    const std::string message = CtErrorMessage(dir);
    EXPECT_NE(message.find("ImageOrientationPatient"), std::string::npos) << message;
  }
  {
    const fs::path dir = CopySeries("spacing");
    test::CopyDicomWithEdits(files[3], dir / files[3].filename(), [](gdcm::DataSet& ds) {
      test::SetText(ds, 0x0028, 0x0030, "DS", "0.8\\0.8");
    });
    const std::string message = CtErrorMessage(dir);
    EXPECT_NE(message.find("PixelSpacing"), std::string::npos) << message;
  }
  {
    const fs::path dir = CopySeries("modality");
    for (const auto& f : files) {
      test::CopyDicomWithEdits(f, dir / f.filename(), [](gdcm::DataSet& ds) {
        test::SetText(ds, 0x0008, 0x0060, "CS", "MR");
      });
    }
    const std::string message = CtErrorMessage(dir);
    EXPECT_NE(message.find("'MR', expected CT"), std::string::npos) << message;
  }
}

TEST_F(BrokenSeries, EmptyNonDicomAndCorruptFoldersAreRefused) {
  const fs::path empty = temp_.path() / "empty";
  fs::create_directories(empty);
  EXPECT_NE(CtErrorMessage(empty).find("no DICOM image files"), std::string::npos);
  const fs::path text = temp_.path() / "text";
  fs::create_directories(text);
  for (int i = 0; i < 5; ++i) test::WriteBytes(text / ("slice" + std::to_string(i) + ".dcm"), "not DICOM\n");
  const std::string message = CtErrorMessage(text);
  EXPECT_NE(message.find("no DICOM image files"), std::string::npos) << message;
  EXPECT_NE(message.find("5 not DICOM"), std::string::npos) << message;
  // A slice whose compressed pixel data is cut short.
  const fs::path cut = CopySeries("truncated");
  const fs::path victim = cut / SeriesFiles()[12].filename();
  const std::string bytes = test::ReadBytes(victim);
  test::WriteBytes(victim, bytes.substr(0, bytes.size() - 60000));
  const std::string truncated = ImportErrorMessage(cut);
  EXPECT_NE(truncated.find(victim.filename().string()), std::string::npos) << truncated;
}

// A synthetic CT where the couch top touches the patient's back over its
// whole width: only the opening separates them (the real series has a gap).
TEST(BodyMask, CouchTouchingTheBackIsCutOffAndLungsFilled) {
  CtVolume ct;
  VolumeGeometry& g = ct.geometry;
  g.size = {200, 170, 8};
  g.spacing_mm = Eigen::Vector3d(1, 1, 3);
  g.origin_mm = Eigen::Vector3d(-100, -70, 0);
  ct.hu.assign(g.num_voxels(), -1000);
  auto inside_ellipse = [](int i, int j, double ci, double cj, double ri, double rj) {
    const double x = (i - ci) / ri, y = (j - cj) / rj;
    return x * x + y * y <= 1.0;
  };
  for (int k = 0; k < g.size[2]; ++k) {
    for (int j = 0; j < g.size[1]; ++j) {
      for (int i = 0; i < g.size[0]; ++i) {
        int16_t& hu = ct.hu[g.Index(i, j, k)];
        if (inside_ellipse(i, j, 100, 70, 80, 50)) hu = 20;                  // trunk, back at j = 120
        if (inside_ellipse(i, j, 70, 65, 20, 25) || inside_ellipse(i, j, 130, 65, 20, 25)) hu = -800;  // lungs
        if (j >= 120 && j <= 122) hu = 300;                                  // 3 mm couch top, full width
        if (j >= 150 && j <= 152) hu = 300;                                  // couch bottom shell
      }
    }
  }
  BodyMaskOptions no_opening;
  no_opening.opening_radius_mm = 0;
  const BodyMask joined = SegmentBody(ct, no_opening, "synthetic");
  EXPECT_TRUE(joined.inside[g.Index(5, 121, 4)]) << "without the opening the couch top is part of the body";

  const BodyMask mask = SegmentBody(ct, BodyMaskOptions(), "synthetic");
  EXPECT_FALSE(mask.inside[g.Index(5, 121, 4)]);      // couch away from the body
  EXPECT_FALSE(mask.inside[g.Index(100, 151, 4)]);    // couch bottom
  EXPECT_TRUE(mask.inside[g.Index(70, 65, 4)]);       // lung filled
  EXPECT_TRUE(mask.inside[g.Index(100, 118, 4)]);     // back
  size_t couch_rows = 0, below = 0;
  for (int i = 0; i < g.size[0]; ++i) {
    for (int j = 120; j <= 122; ++j) couch_rows += mask.inside[g.Index(i, j, 4)];
    for (int j = 123; j < g.size[1]; ++j) below += mask.inside[g.Index(i, j, 4)];
  }
  EXPECT_EQ(below, 0u);
  EXPECT_LT(couch_rows, 120u);  // a fillet where the back meets the couch, not the 600-pixel couch top
  size_t slice_voxels = 0;
  for (int j = 0; j < g.size[1]; ++j) {
    for (int i = 0; i < g.size[0]; ++i) slice_voxels += mask.inside[g.Index(i, j, 4)];
  }
  EXPECT_NEAR(static_cast<double>(slice_voxels), M_PI * 80 * 50, 0.02 * M_PI * 80 * 50);

  double iso = 0;
  SurfaceOptions options;
  const ScalarVolume field = BodySurfaceField(ct, mask, -350, &iso);
  options.iso_value = iso;
  const MeshSummary s = SummarizeMesh(ExtractSurface(field, options, "synthetic"));
  EXPECT_TRUE(s.closed);
  EXPECT_EQ(s.num_components, 1);
  EXPECT_NEAR(s.min.x() * 1000, -80, 1.0);
  EXPECT_NEAR(s.max.x() * 1000, 80, 1.0);
  EXPECT_NEAR(s.min.y() * 1000, -50, 1.0);
  // The back plus the contact fillet at most, never the shell at 80 mm; the
  // couch top (50-53 mm) would also widen x to +-100 mm (checked above).
  EXPECT_LT(s.max.y() * 1000, 53.5);
  EXPECT_NEAR(s.min.z() * 1000, -1.5, 0.5);  // caps half a slice beyond the end slices
  EXPECT_NEAR(s.max.z() * 1000, 22.5, 0.5);
}

TEST(ModelSource, DetectionAndRefusals) {
  TempDir dir;
  EXPECT_EQ(DetectModelSource(CtSeriesDir()), ModelSourceKind::kCtSeries);
  EXPECT_EQ(DetectModelSource(test::RtStructFile()), ModelSourceKind::kRtStruct);
  EXPECT_EQ(DetectModelSource(test::MakeHumanObj()), ModelSourceKind::kMeshFile);
  auto message = [](const fs::path& p) {
    try {
      DetectModelSource(p);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  const std::string single = message(test::CtSliceFile());
  EXPECT_NE(single.find("single CT slice"), std::string::npos) << single;
  const std::string plan = message(test::RtPlanFile());
  EXPECT_NE(plan.find("RTPLAN"), std::string::npos) << plan;
  test::WriteBytes(dir.path() / "notes.dcm", "this is a text file, not DICOM\n");
  const std::string text = message(dir.path() / "notes.dcm");
  EXPECT_NE(text.find("notes.dcm: not a DICOM file"), std::string::npos) << text;
  test::WriteBytes(dir.path() / "blob.bin", std::string(1000, '\0'));
  EXPECT_NE(message(dir.path() / "blob.bin").find("not a mesh file"), std::string::npos);
  EXPECT_NE(message(dir.path() / "absent").find("no such file"), std::string::npos);
}

}  // namespace
}  // namespace arpos
