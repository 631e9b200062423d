#include "model_import/test_util.h"

#include <gdcmDataElement.h>
#include <gdcmDataSet.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmWriter.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <sstream>

namespace arpos::test {

fs::path SharedData(const std::string& relative) { return fs::path(ARPOS_SHARED_DATA_DIR) / relative; }
fs::path CtSeriesDir() { return SharedData("totalseg_ct/example_ct_dicom"); }
fs::path RtStructFile() { return SharedData("dicompyler_rt/rtss.dcm"); }
fs::path RtPlanFile() { return SharedData("dicompyler_rt/rtplan.dcm"); }
fs::path CtSliceFile() { return SharedData("dicompyler_rt/ct.0.dcm"); }
fs::path MakeHumanObj() { return SharedData("makehuman_base/base.obj"); }

TriangleMesh Ellipsoid(const Eigen::Vector3d& radii, const Eigen::Vector3d& centre, int rings,
                       int segments) {
  TriangleMesh mesh;
  mesh.vertices.push_back((centre + Eigen::Vector3d(0, 0, radii.z())).cast<float>());  // north pole
  for (int r = 1; r < rings; ++r) {
    const double theta = M_PI * r / rings;
    for (int s = 0; s < segments; ++s) {
      const double phi = 2 * M_PI * s / segments;
      const Eigen::Vector3d unit(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                                 std::cos(theta));
      mesh.vertices.push_back((centre + radii.cwiseProduct(unit)).cast<float>());
    }
  }
  const int south = static_cast<int>(mesh.vertices.size());
  mesh.vertices.push_back((centre - Eigen::Vector3d(0, 0, radii.z())).cast<float>());
  auto at = [&](int ring, int s) { return 1 + (ring - 1) * segments + (s % segments); };
  for (int s = 0; s < segments; ++s) {
    mesh.faces.emplace_back(0, at(1, s), at(1, s + 1));
    for (int r = 1; r + 1 < rings; ++r) {
      mesh.faces.emplace_back(at(r, s), at(r + 1, s), at(r + 1, s + 1));
      mesh.faces.emplace_back(at(r, s), at(r + 1, s + 1), at(r, s + 1));
    }
    mesh.faces.emplace_back(at(rings - 1, s), south, at(rings - 1, s + 1));
  }
  return mesh;
}

TriangleMesh Scaled(TriangleMesh mesh, double factor) {
  for (auto& v : mesh.vertices) v *= static_cast<float>(factor);
  mesh.vertex_normals.clear();
  return mesh;
}

void WriteBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
  ASSERT_TRUE(out.good()) << path;
}

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

void WriteAsciiObj(const TriangleMesh& mesh, const fs::path& path) {
  std::ostringstream out;
  out.precision(9);
  out << "# test mesh\no body\n";
  for (const auto& v : mesh.vertices) out << "v " << v.x() << " " << v.y() << " " << v.z() << "\n";
  for (const auto& f : mesh.faces) out << "f " << f[0] + 1 << " " << f[1] + 1 << " " << f[2] + 1 << "\n";
  WriteBytes(path, out.str());
}

void WriteAsciiStl(const TriangleMesh& mesh, const fs::path& path) {
  std::ostringstream out;
  out.precision(9);
  out << "solid test\n";
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3f n =
        (mesh.vertices[f[1]] - mesh.vertices[f[0]]).cross(mesh.vertices[f[2]] - mesh.vertices[f[0]]).normalized();
    out << " facet normal " << n.x() << " " << n.y() << " " << n.z() << "\n  outer loop\n";
    for (int k = 0; k < 3; ++k) {
      const auto& v = mesh.vertices[f[k]];
      out << "   vertex " << v.x() << " " << v.y() << " " << v.z() << "\n";
    }
    out << "  endloop\n endfacet\n";
  }
  out << "endsolid test\n";
  WriteBytes(path, out.str());
}

void WriteAsciiOff(const TriangleMesh& mesh, const fs::path& path) {
  std::ostringstream out;
  out.precision(9);
  out << "OFF\n" << mesh.vertices.size() << " " << mesh.faces.size() << " 0\n";
  for (const auto& v : mesh.vertices) out << v.x() << " " << v.y() << " " << v.z() << "\n";
  for (const auto& f : mesh.faces) out << "3 " << f[0] << " " << f[1] << " " << f[2] << "\n";
  WriteBytes(path, out.str());
}

void CopyDicomWithEdits(const fs::path& src, const fs::path& dst,
                        const std::function<void(gdcm::DataSet&)>& edit) {
  gdcm::Reader reader;
  reader.SetFileName(src.string().c_str());
  ASSERT_TRUE(reader.Read()) << src;
  edit(reader.GetFile().GetDataSet());
  std::error_code ec;
  fs::remove(dst, ec);  // copies of the read-only shared data may be read-only
  gdcm::Writer writer;
  // The anonymised CT has empty SOP UIDs, from which GDCM would rebuild the
  // file meta information and fail: keep the meta header as read.
  writer.SetCheckFileMetaInformation(false);
  writer.SetFile(reader.GetFile());
  writer.SetFileName(dst.string().c_str());
  ASSERT_TRUE(writer.Write()) << dst;
}

void SetText(gdcm::DataSet& ds, uint16_t group, uint16_t element, const std::string& vr,
             const std::string& value) {
  std::string padded = value;
  if (padded.size() % 2 == 1) padded.push_back(vr == "UI" ? '\0' : ' ');
  gdcm::DataElement de(gdcm::Tag(group, element));
  de.SetVR(gdcm::VR::GetVRType(vr.c_str()));
  de.SetByteValue(padded.data(), static_cast<uint32_t>(padded.size()));
  ds.Replace(de);
}

std::string GetText(const gdcm::DataSet& ds, uint16_t group, uint16_t element) {
  const gdcm::Tag tag(group, element);
  if (!ds.FindDataElement(tag)) return {};
  const gdcm::ByteValue* bv = ds.GetDataElement(tag).GetByteValue();
  if (bv == nullptr) return {};
  std::string s(bv->GetPointer(), bv->GetLength());
  while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
  return s;
}

void EditSequence(gdcm::DataSet& ds, uint16_t group, uint16_t element,
                  const std::function<void(gdcm::DataSet&)>& edit,
                  const std::function<bool(const gdcm::DataSet&)>& keep) {
  const gdcm::Tag tag(group, element);
  if (!ds.FindDataElement(tag)) return;  // e.g. an ROI without ContourSequence
  gdcm::DataElement de = ds.GetDataElement(tag);
  gdcm::SmartPointer<gdcm::SequenceOfItems> sq = de.GetValueAsSQ();
  ASSERT_TRUE(sq);
  gdcm::SmartPointer<gdcm::SequenceOfItems> out = new gdcm::SequenceOfItems;
  out->SetLengthToUndefined();
  for (gdcm::SequenceOfItems::SizeType i = 1; i <= sq->GetNumberOfItems(); ++i) {
    gdcm::Item item = sq->GetItem(i);
    if (keep && !keep(item.GetNestedDataSet())) continue;
    if (edit) edit(item.GetNestedDataSet());
    item.SetVLToUndefined();
    out->AddItem(item);
  }
  de.SetValue(*out);
  de.SetVR(gdcm::VR::SQ);
  de.SetVLToUndefined();
  ds.Replace(de);
}

double CrossSectionAreaZ(const TriangleMesh& mesh, double z) {
  double twice_area = 0;
  for (const auto& f : mesh.faces) {
    Eigen::Vector3d p[3];
    for (int k = 0; k < 3; ++k) p[k] = mesh.vertices[f[k]].cast<double>();
    std::vector<Eigen::Vector3d> hits;
    for (int e = 0; e < 3; ++e) {
      const Eigen::Vector3d& a = p[e];
      const Eigen::Vector3d& b = p[(e + 1) % 3];
      if ((a.z() < z) != (b.z() < z)) hits.push_back(a + (b - a) * ((z - a.z()) / (b.z() - a.z())));
    }
    if (hits.size() != 2) continue;
    const Eigen::Vector3d normal = (p[1] - p[0]).cross(p[2] - p[0]);
    // Counter-clockwise (seen from +z) around the inside: along z x outward normal.
    Eigen::Vector3d a = hits[0], b = hits[1];
    if ((b - a).dot(Eigen::Vector3d::UnitZ().cross(normal)) < 0) std::swap(a, b);
    twice_area += a.x() * b.y() - b.x() * a.y();
  }
  return 0.5 * twice_area;
}

}  // namespace arpos::test
