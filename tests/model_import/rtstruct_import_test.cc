// The real RTSTRUCT (dicompyler-core example, breast case): body ROI to a
// closed surface, isocentre origin, and hostile structure sets.
#include <gdcmDataSet.h>
#include <gtest/gtest.h>

#include <chrono>
#include <map>

#include "model_import/model_import.h"
#include "model_import/test_util.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos {
namespace {

using test::RtPlanFile;
using test::RtStructFile;

std::string ImportErrorMessage(const fs::path& input, const ModelImportOptions& options = {}) {
  try {
    ImportModel(input, options);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

// Parsed and imported once per process, and only by the tests that need them
// (ctest runs every test in its own process).
class RealRtStruct : public ::testing::Test {
 protected:
  static const RtStructureSet& StructureSet() {
    static const RtStructureSet structure_set = ReadRtStruct(RtStructFile());
    return structure_set;
  }
  static const ModelImportResult& Model() {
    static const ModelImportResult model = [] {
      const auto start = std::chrono::steady_clock::now();
      ModelImportOptions options;
      options.rtplan_path = RtPlanFile();  // read to report the isocentre; origin stays
      ModelImportResult result = ImportModel(RtStructFile(), options);
      import_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      return result;
    }();
    return model;
  }
  static const RtRoi& Body() {
    for (const auto& roi : StructureSet().rois) {
      if (roi.name == "BODY") return roi;
    }
    throw std::runtime_error("no BODY");
  }
  static double import_s_;
};
double RealRtStruct::import_s_ = 0;

TEST_F(RealRtStruct, ParsesRoisAndContours) {
  // SOURCE.txt: ROI 1 "BODY" (EXTERNAL): 141 closed planar contours on 98 slices, z -122.4..168.6.
  EXPECT_EQ(StructureSet().label, "CT_1");
  EXPECT_FALSE(StructureSet().frame_of_reference_uid.empty());
  const RtRoi& body = Body();
  EXPECT_EQ(body.number, 1);
  EXPECT_EQ(body.interpreted_type, "EXTERNAL");
  EXPECT_EQ(body.contours.size(), 141u);
  double zmin = 1e9, zmax = -1e9;
  for (const auto& c : body.contours) {
    EXPECT_EQ(c.geometric_type, "CLOSED_PLANAR");
    for (const auto& p : c.points_mm) {
      zmin = std::min(zmin, p.z());
      zmax = std::max(zmax, p.z());
    }
  }
  EXPECT_NEAR(zmin, -122.44, 0.01);
  EXPECT_NEAR(zmax, 168.56, 0.01);
  EXPECT_EQ(SelectBodyRoi(StructureSet(), "", RtStructFile()), 0u);
  EXPECT_EQ(StructureSet().rois[SelectBodyRoi(StructureSet(), "heart", RtStructFile())].name, "Heart");
}

TEST_F(RealRtStruct, BodySurfaceIsClosedAndItsCrossSectionsMatchTheContours) {
  const ModelImportResult& r = Model();
  const MeshSummary& s = r.summary;
  std::printf("[ measure  ] RTSTRUCT import %.2f s (read %.2f, raster %.2f, surface %.2f); %d vertices "
              "(%d extracted), %d faces, extent %.1f x %.1f x %.1f mm, closed %d, %d components\n",
              import_s_, r.read_s, r.segment_s, r.surface_s, s.num_vertices,
              r.surface_stats.extracted_vertices, s.num_faces, s.extent().x() * 1000,
              s.extent().y() * 1000, s.extent().z() * 1000, s.closed, s.num_components);
  EXPECT_EQ(r.kind, ModelSourceKind::kRtStruct);
  EXPECT_EQ(r.roi_name, "BODY");
  EXPECT_EQ(r.num_slices, 98);
  EXPECT_TRUE(s.closed);
  EXPECT_EQ(s.num_components, 1);
  EXPECT_LE(s.num_vertices, 100000);
  EXPECT_GT(s.signed_volume, 0);
  // Capped half a slice (1.5 mm) beyond the end contours.
  EXPECT_NEAR(s.min.z() * 1000, -122.44 - 1.5, 0.5);
  EXPECT_NEAR(s.max.z() * 1000, 168.56 + 1.5, 0.5);
  // Cross-sections at contour planes with one contour: the polygon's area
  // within 2 %; the extent in x and y within 2 mm of the polygon's.
  std::map<double, std::vector<std::vector<Eigen::Vector3d>>> planes;
  for (const auto& c : Body().contours) planes[std::round(c.points_mm[0].z() * 100) / 100].push_back(c.points_mm);
  int checked = 0;
  double worst_percent = 0;
  for (const auto& [z, contours] : planes) {
    if (contours.size() != 1) continue;
    ++checked;
    const double polygon_mm2 = EvenOddArea(contours, Eigen::Vector3d::UnitZ());
    const double surface_mm2 = test::CrossSectionAreaZ(r.mesh, z * 0.001) * 1e6;
    EXPECT_NEAR(surface_mm2, polygon_mm2, 0.02 * polygon_mm2) << "z = " << z;
    const double percent = 100 * (surface_mm2 - polygon_mm2) / polygon_mm2;
    if (std::abs(percent) > std::abs(worst_percent)) worst_percent = percent;
  }
  EXPECT_GT(checked, 60);
  std::printf("[ measure  ] RTSTRUCT cross-sections vs polygons on %d single-contour planes: worst %+.2f %%\n",
              checked, worst_percent);
  // The notes say what was dropped (a couch rail drawn as part of BODY) and where the isocentre is.
  bool dropped = false, isocentre = false;
  for (const auto& note : r.notes) {
    dropped |= note.find("dropped") != std::string::npos;
    isocentre |= note.find("isocentre at (72.5, -304.3, -9.3) mm") != std::string::npos;
  }
  EXPECT_TRUE(dropped);
  EXPECT_TRUE(isocentre);
}

TEST_F(RealRtStruct, IsocentreOriginShiftsTheModel) {
  const RtPlanIsocentre plan = ReadRtPlanIsocentre(RtPlanFile());
  EXPECT_EQ(plan.frame_of_reference_uid, StructureSet().frame_of_reference_uid);
  EXPECT_GT(plan.num_beams, 0);
  ModelImportOptions options;
  options.origin = ModelOrigin::kIsocentre;
  options.rtplan_path = RtPlanFile();
  options.roi_name = "Heart";  // small and fast; the shift is what is checked
  const ModelImportResult shifted = ImportModel(RtStructFile(), options);
  ModelImportOptions patient = options;
  patient.origin = ModelOrigin::kPatient;
  const ModelImportResult unshifted = ImportModel(RtStructFile(), patient);
  ASSERT_EQ(shifted.mesh.vertices.size(), unshifted.mesh.vertices.size());
  const Eigen::Vector3f shift = -(plan.isocentre_mm * 0.001).cast<float>();
  for (size_t v = 0; v < shifted.mesh.vertices.size(); v += 97) {
    ASSERT_LT((shifted.mesh.vertices[v] - (unshifted.mesh.vertices[v] + shift)).norm(), 1e-6);
  }
  EXPECT_LT((shifted.model_from_patient.translation + plan.isocentre_mm * 0.001).norm(), 1e-12);
  // A plan of another frame of reference is refused.
  TempDir dir;
  test::CopyDicomWithEdits(RtPlanFile(), dir.path() / "other_plan.dcm", [](gdcm::DataSet& ds) {
    test::SetText(ds, 0x0020, 0x0052, "UI", "1.2.826.0.1.3680043.2.1125.7");
  });
  options.rtplan_path = dir.path() / "other_plan.dcm";
  const std::string message = ImportErrorMessage(RtStructFile(), options);
  EXPECT_NE(message.find("other_plan.dcm"), std::string::npos) << message;
  EXPECT_NE(message.find("differs"), std::string::npos) << message;
  // Origin at the isocentre without a plan is an option error.
  ModelImportOptions no_plan;
  no_plan.origin = ModelOrigin::kIsocentre;
  EXPECT_NE(ImportErrorMessage(RtStructFile(), no_plan).find("--rtplan"), std::string::npos);
}

TEST_F(RealRtStruct, ChosenRoiAndMissingRoiNamesAreReported) {
  ModelImportOptions options;
  options.roi_name = "lt lung";
  options.surface.max_vertices = 10000;
  const ModelImportResult lung = ImportModel(RtStructFile(), options);
  EXPECT_EQ(lung.roi_name, "Lt Lung");
  EXPECT_TRUE(lung.summary.closed);
  options.roi_name = "Couch";
  const std::string message = ImportErrorMessage(RtStructFile(), options);
  EXPECT_NE(message.find("no ROI named 'Couch'"), std::string::npos) << message;
  EXPECT_NE(message.find("'Heart' (ORGAN)"), std::string::npos) << message;
  options.roi_name = "Areola";  // declared, but without contours
  EXPECT_NE(ImportErrorMessage(RtStructFile(), options).find("'Areola' has no contours"), std::string::npos);
}

TEST(BrokenRtStruct, HostileStructureSetsAreRefused) {
  TempDir dir;
  // No body ROI: BODY renamed and retyped. The message lists what is there.
  const fs::path no_body = dir.path() / "no_body.dcm";
  test::CopyDicomWithEdits(RtStructFile(), no_body, [](gdcm::DataSet& ds) {
    test::EditSequence(ds, 0x3006, 0x0020, [](gdcm::DataSet& item) {
      if (test::GetText(item, 0x3006, 0x0026) == "BODY") test::SetText(item, 0x3006, 0x0026, "LO", "Patient");
    });
    test::EditSequence(ds, 0x3006, 0x0080, [](gdcm::DataSet& item) {
      if (test::GetText(item, 0x3006, 0x00a4) == "EXTERNAL") test::SetText(item, 0x3006, 0x00a4, "CS", "ORGAN");
    });
  });
  const std::string none = ImportErrorMessage(no_body);
  EXPECT_NE(none.find("no_body.dcm: no body ROI"), std::string::npos) << none;
  EXPECT_NE(none.find("'Patient' (ORGAN)"), std::string::npos) << none;
  EXPECT_NE(none.find("'Heart'"), std::string::npos) << none;
  EXPECT_NE(none.find("--roi"), std::string::npos) << none;

  // Empty structure set: every ROI removed.
  const fs::path empty = dir.path() / "empty.dcm";
  test::CopyDicomWithEdits(RtStructFile(), empty, [](gdcm::DataSet& ds) {
    auto none_kept = [](const gdcm::DataSet&) { return false; };
    test::EditSequence(ds, 0x3006, 0x0020, nullptr, none_kept);
    test::EditSequence(ds, 0x3006, 0x0039, nullptr, none_kept);
    test::EditSequence(ds, 0x3006, 0x0080, nullptr, none_kept);
  });
  const std::string no_rois = ImportErrorMessage(empty);
  EXPECT_NE(no_rois.find("empty.dcm: the RTSTRUCT has no ROIs"), std::string::npos) << no_rois;

  // Body contours that are not CLOSED_PLANAR.
  const fs::path open = dir.path() / "open.dcm";
  test::CopyDicomWithEdits(RtStructFile(), open, [](gdcm::DataSet& ds) {
    test::EditSequence(ds, 0x3006, 0x0039, [](gdcm::DataSet& roi) {
      if (test::GetText(roi, 0x3006, 0x0084) != "1") return;
      test::EditSequence(roi, 0x3006, 0x0040, [](gdcm::DataSet& contour) {
        test::SetText(contour, 0x3006, 0x0042, "CS", "OPEN_PLANAR");
      });
    });
  });
  const std::string not_closed = ImportErrorMessage(open);
  EXPECT_NE(not_closed.find("open.dcm: ROI 'BODY' has contours that are not CLOSED_PLANAR (141 OPEN_PLANAR"),
            std::string::npos)
      << not_closed;

  // Contour data that is not numbers, or disagrees with its point count.
  const fs::path garbled = dir.path() / "garbled.dcm";
  test::CopyDicomWithEdits(RtStructFile(), garbled, [](gdcm::DataSet& ds) {
    test::EditSequence(ds, 0x3006, 0x0039, [](gdcm::DataSet& roi) {
      test::EditSequence(roi, 0x3006, 0x0040, [](gdcm::DataSet& contour) {
        test::SetText(contour, 0x3006, 0x0050, "DS", "1.0\\2.0\\abc");
      });
    });
  });
  const std::string bad_numbers = ImportErrorMessage(garbled);
  EXPECT_NE(bad_numbers.find("garbled.dcm"), std::string::npos) << bad_numbers;
  EXPECT_NE(bad_numbers.find("ContourData"), std::string::npos) << bad_numbers;

  // Truncated file, text file named .dcm, an RTSTRUCT tag soup without preamble.
  const std::string bytes = test::ReadBytes(RtStructFile());
  test::WriteBytes(dir.path() / "truncated.dcm", bytes.substr(0, bytes.size() / 3));
  const std::string truncated = ImportErrorMessage(dir.path() / "truncated.dcm");
  EXPECT_NE(truncated.find("truncated.dcm"), std::string::npos) << truncated;
  test::WriteBytes(dir.path() / "text.dcm", "hello\n");
  EXPECT_NE(ImportErrorMessage(dir.path() / "text.dcm").find("text.dcm: not a DICOM file"), std::string::npos);
  test::WriteBytes(dir.path() / "no_preamble.dcm", bytes.substr(132));
  EXPECT_NE(ImportErrorMessage(dir.path() / "no_preamble.dcm").find("not a DICOM file"), std::string::npos);
}

}  // namespace
}  // namespace arpos
