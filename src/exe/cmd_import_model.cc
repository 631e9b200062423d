#include "exe/cmd_import_model.h"

#include <iostream>

#include "exe/args.h"
#include "geometry/mesh_io.h"
#include "model_import/model_import.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

constexpr const char* kUsage =
    "usage: arpos import-model INPUT --out MODEL.ply [options]\n"
    "Imports the patient's reference body surface for a plan and writes it as a\n"
    "binary PLY in metres. INPUT is one of:\n"
    "  a mesh file (.ply .stl .obj .off ...)  units stated or detected from the size\n"
    "  a folder with one DICOM CT series       body segmented, skin surface extracted\n"
    "  a DICOM RTSTRUCT file                   body ROI contours stacked into a surface\n"
    "DICOM sources give the model in the DICOM patient frame (LPS axes).\n"
    "options:\n"
    "  --out FILE            output PLY (required)\n"
    "  --units mm|cm|dm|m    unit of a mesh file (default: detected; the unit that\n"
    "                        makes the largest extent 0.2-2 m)\n"
    "  --group NAME          mesh file: keep only this group/object (e.g. body)\n"
    "  --roi NAME            RTSTRUCT: ROI to use (default: EXTERNAL/BODY/... or\n"
    "                        the ROI of type EXTERNAL)\n"
    "  --threshold-hu V      CT: body threshold in HU (default -350)\n"
    "  --max-vertices N      decimate to at most N vertices (default 100000; 0 = no limit)\n"
    "  --origin patient|isocentre\n"
    "                        DICOM sources: model origin at the patient-frame origin\n"
    "                        (default) or at the RTPLAN isocentre (needs --rtplan)\n"
    "  --rtplan FILE         RTPLAN of the same frame of reference\n";

void PrintReport(const ModelImportResult& r, const std::string& input, const std::string& output,
                 std::ostream& out) {
  out << "input:     " << input << " (" << ModelSourceKindName(r.kind) << ")\n";
  switch (r.kind) {
    case ModelSourceKind::kMeshFile:
      out << "units:     " << LengthUnitName(r.units) << (r.units_detected ? " (detected: " : " (")
          << r.units_explanation << ")\n";
      break;
    case ModelSourceKind::kCtSeries:
      out << "series:    " << (r.series_instance_uid.empty() ? "(no SeriesInstanceUID)" : r.series_instance_uid)
          << (r.series_description.empty() ? "" : " '" + r.series_description + "'") << ", "
          << r.num_slices << " slices, voxels "
          << StringPrintf("%.3f x %.3f x %.3f mm", r.voxel_spacing_mm.x(), r.voxel_spacing_mm.y(),
                          r.voxel_spacing_mm.z())
          << "\n";
      break;
    case ModelSourceKind::kRtStruct:
      out << "roi:       '" << r.roi_name << "'"
          << (r.roi_interpreted_type.empty() ? "" : " (" + r.roi_interpreted_type + ")")
          << ", chosen by " << r.roi_selection << ", " << r.num_slices << " contour planes, grid "
          << StringPrintf("%.2f x %.2f x %.2f mm", r.voxel_spacing_mm.x(), r.voxel_spacing_mm.y(),
                          r.voxel_spacing_mm.z())
          << "\n";
      break;
  }
  if (r.has_patient_frame) {
    out << "frame:     DICOM patient frame (LPS axes), metres, origin at the "
        << (r.model_from_patient.translation.isZero() ? "patient-frame origin" : "RTPLAN isocentre")
        << "\n";
  } else {
    out << "frame:     the file's own axes, metres\n";
  }
  const MeshSummary& s = r.summary;
  const Eigen::Vector3d lo = s.min * 1000.0, hi = s.max * 1000.0, e = s.extent() * 1000.0;
  out << StringPrintf("extent:    %.1f x %.1f x %.1f mm  (x %.1f..%.1f, y %.1f..%.1f, z %.1f..%.1f mm)\n",
                      e.x(), e.y(), e.z(), lo.x(), hi.x(), lo.y(), hi.y(), lo.z(), hi.z());
  out << "vertices:  " << s.num_vertices << ", faces: " << s.num_faces << "\n";
  out << StringPrintf("area:      %.4f m^2, enclosed volume %.2f L\n", s.surface_area,
                      s.signed_volume * 1000.0);
  out << "closed:    " << (s.closed ? "yes" : "no");
  if (!s.closed) {
    out << " (" << s.boundary_edges << " boundary edges, " << s.non_manifold_edges << " non-manifold)";
  }
  out << ", " << s.num_components << (s.num_components == 1 ? " component" : " components") << "\n";
  out << StringPrintf("time:      %.2f s (read %.2f, segment %.2f, surface %.2f)\n", r.total_s, r.read_s,
                      r.segment_s, r.surface_s);
  if (r.surface_stats.extracted_vertices > 0) {
    const SurfaceStats& t = r.surface_stats;
    out << StringPrintf("surface:   %d vertices at full resolution; grid %.2f x %.2f x %.2f mm -> %d vertices "
                        "(extract %.2f s, smooth %.2f s, decimate %.2f s)\n",
                        t.full_resolution_vertices, t.grid_spacing_mm.x(), t.grid_spacing_mm.y(),
                        t.grid_spacing_mm.z(), t.extracted_vertices, t.extract_s, t.smooth_s, t.decimate_s);
  }
  for (const auto& note : r.notes) out << "note:      " << note << "\n";
  out << "wrote:     " << output << "\n";
}

int Run(const std::vector<std::string>& argv, std::ostream& out, std::ostream& err) {
  const Args args(argv,
                  {"out", "units", "group", "roi", "threshold-hu", "max-vertices", "origin", "rtplan"},
                  {"help"});
  if (args.Has("help")) {
    out << kUsage;
    return 0;
  }
  if (args.positional().size() != 1 || !args.Has("out")) {
    err << "arpos import-model: give one INPUT and --out FILE\n" << kUsage;
    return 2;
  }
  const std::string input = args.positional()[0];
  const std::string output = args.Require("out");
  ModelImportOptions options;
  if (args.Has("units")) {
    options.units = ParseLengthUnit(args.Require("units"));
    if (!options.units) ARPOS_INPUT_ERROR("--units must be mm, cm, dm or m, not '" << args.Require("units") << "'");
  }
  options.mesh_group = args.GetOr("group", "");
  options.roi_name = args.GetOr("roi", "");
  options.body.threshold_hu = args.GetDouble("threshold-hu", options.body.threshold_hu);
  const long long max_vertices = args.GetInt("max-vertices", options.surface.max_vertices);
  if (max_vertices < 0 || max_vertices > 50000000) ARPOS_INPUT_ERROR("--max-vertices out of range");
  options.surface.max_vertices = static_cast<int>(max_vertices);
  const std::string origin = ToLower(args.GetOr("origin", "patient"));
  if (origin == "isocentre" || origin == "isocenter") {
    options.origin = ModelOrigin::kIsocentre;
  } else if (origin != "patient") {
    ARPOS_INPUT_ERROR("--origin must be patient or isocentre, not '" << origin << "'");
  }
  options.rtplan_path = args.GetOr("rtplan", "");
  std::string reason;
  if (!options.Check(&reason)) ARPOS_INPUT_ERROR(reason);
  const ModelImportResult result = ImportModel(input, options);
  SaveTriangleMeshPly(result.mesh, output, Trim(ModelProvenanceComment(result, input)));
  PrintReport(result, input, output, out);
  return 0;
}

}  // namespace

int RunImportModelCommandWithOutput(const std::vector<std::string>& args, std::ostream& out,
                                    std::ostream& err) {
  try {
    return Run(args, out, err);
  } catch (const InputError& e) {
    err << "arpos import-model: error: " << e.what() << "\n";
    return 2;
  }
}

int RunImportModelCommand(const std::vector<std::string>& args) {
  return RunImportModelCommandWithOutput(args, std::cout, std::cerr);
}

}  // namespace arpos
