#pragma once
// Helpers for the model-import tests: synthetic meshes in any unit, edited
// copies of real DICOM files (GDCM), and mesh cross-sections.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "geometry/triangle_mesh.h"

namespace gdcm {
class DataSet;
}

namespace arpos::test {

namespace fs = std::filesystem;

fs::path SharedData(const std::string& relative);
fs::path CtSeriesDir();  // totalseg_ct/example_ct_dicom
fs::path RtStructFile();
fs::path RtPlanFile();
fs::path CtSliceFile();  // dicompyler_rt/ct.0.dcm
fs::path MakeHumanObj();

// Closed ellipsoid (UV sphere) centred at `centre`, semi-axes `radii`,
// outward faces.
TriangleMesh Ellipsoid(const Eigen::Vector3d& radii, const Eigen::Vector3d& centre, int rings = 24,
                       int segments = 48);
TriangleMesh Scaled(TriangleMesh mesh, double factor);
void WriteAsciiObj(const TriangleMesh& mesh, const fs::path& path);
void WriteAsciiStl(const TriangleMesh& mesh, const fs::path& path);
void WriteAsciiOff(const TriangleMesh& mesh, const fs::path& path);
void WriteBytes(const fs::path& path, const std::string& bytes);
std::string ReadBytes(const fs::path& path);

// Reads `src` fully with GDCM, lets `edit` change its data set, writes `dst`.
void CopyDicomWithEdits(const fs::path& src, const fs::path& dst,
                        const std::function<void(gdcm::DataSet&)>& edit);
// Replaces (or inserts) a text element (VR given as "UI", "CS", "LO", "DS"...).
void SetText(gdcm::DataSet& ds, uint16_t group, uint16_t element, const std::string& vr,
             const std::string& value);
// Applies `edit` to every item of the sequence (group, element) of `ds` and
// stores the sequence back; `keep` (optional) decides which items remain.
// Does nothing if the sequence is absent.
void EditSequence(gdcm::DataSet& ds, uint16_t group, uint16_t element,
                  const std::function<void(gdcm::DataSet&)>& edit,
                  const std::function<bool(const gdcm::DataSet&)>& keep = nullptr);
std::string GetText(const gdcm::DataSet& ds, uint16_t group, uint16_t element);

// Area (unit^2) of the cross-section of a closed, outward-oriented mesh with
// the plane z = `z` (holes count negative).
double CrossSectionAreaZ(const TriangleMesh& mesh, double z);

}  // namespace arpos::test
