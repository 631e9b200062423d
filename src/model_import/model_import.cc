#include "model_import/model_import.h"

#include <algorithm>
#include <chrono>
#include <map>
#include <set>
#include <sstream>

#include "geometry/mesh_io.h"
#include "geometry/mesh_file_check.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace fs = std::filesystem;
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

bool IsMeshExtension(const fs::path& path) {
  static const std::set<std::string> kMesh = {".ply", ".stl", ".obj", ".off", ".fbx", ".dae",
                                              ".3ds", ".gltf", ".glb", ".x3d", ".wrl", ".amf"};
  return kMesh.count(ToLower(path.extension().string())) > 0;
}

std::string FormatMm(const Eigen::Vector3d& v_mm) {
  return StringPrintf("(%.1f, %.1f, %.1f) mm", v_mm.x(), v_mm.y(), v_mm.z());
}

// Checks, right after the source is read (before the slow steps), that the
// RTPLAN (if any) shares the source's frame of reference.
void CheckPlanFrame(const std::optional<RtPlanIsocentre>& plan, const ModelImportOptions& options,
                    const std::string& source_frame_uid, const fs::path& input, ModelImportResult* result) {
  result->has_patient_frame = true;
  result->frame_of_reference_uid = source_frame_uid;
  if (!plan) return;
  if (!plan->frame_of_reference_uid.empty() && !source_frame_uid.empty() &&
      plan->frame_of_reference_uid != source_frame_uid) {
    ARPOS_INPUT_ERROR(options.rtplan_path.string()
                      << ": the RTPLAN's FrameOfReferenceUID " << plan->frame_of_reference_uid
                      << " differs from " << input.string() << "'s " << source_frame_uid
                      << ": its isocentre is not in the same patient frame");
  }
  if (plan->frame_of_reference_uid.empty() || source_frame_uid.empty()) {
    result->notes.push_back("cannot check that the RTPLAN and " + input.filename().string() +
                            " share a frame of reference (FrameOfReferenceUID missing)");
  }
  result->isocentre_in_patient_mm = plan->isocentre_mm;
}

// Moves the mesh (patient frame, metres) to the model origin.
void ApplyOrigin(const std::optional<RtPlanIsocentre>& plan, const ModelImportOptions& options,
                 ModelImportResult* result) {
  if (!plan || options.origin != ModelOrigin::kIsocentre) return;
  result->model_from_patient = Rigid3d(Eigen::Quaterniond::Identity(), -plan->isocentre_mm * 0.001);
  result->mesh.Transform(result->model_from_patient);
}

void ImportMeshFile(const fs::path& input, const ModelImportOptions& options, ModelImportResult* result) {
  if (options.origin == ModelOrigin::kIsocentre || !options.rtplan_path.empty()) {
    ARPOS_INPUT_ERROR(input.string() << ": a mesh file has no DICOM patient frame, so an RTPLAN "
                                        "isocentre cannot place it; use a CT series or an RTSTRUCT");
  }
  auto start = Clock::now();
  CheckMeshFileStructure(input);  // assimp crashes on some malformed files
  MeshLoadOptions load;
  load.units_scale = 1.0;  // file units; the scale is decided from the extent
  load.only_group = options.mesh_group;
  TriangleMesh mesh = LoadTriangleMesh(input, load);
  result->read_s = SecondsSince(start);
  Eigen::Vector3f lo, hi;
  mesh.Bounds(&lo, &hi);
  const double extent = static_cast<double>((hi - lo).maxCoeff());
  if (options.units) {
    result->units = *options.units;
    result->units_explanation = StringPrintf("units stated: %s", LengthUnitName(*options.units));
  } else {
    const UnitDetection detection = DetectLengthUnit(extent);
    if (!detection.unit) {
      ARPOS_INPUT_ERROR(input.string() << ": cannot detect the length unit: " << detection.explanation
                                       << "; state it with --units mm|cm|dm|m");
    }
    result->units = *detection.unit;
    result->units_detected = true;
    result->units_explanation = detection.explanation;
    if (detection.ambiguous) {
      result->notes.push_back("unit detection is ambiguous (" + detection.explanation +
                              "); state --units if the size is wrong");
    }
  }
  const double scale = MetresPerUnit(result->units);
  const double extent_m = extent * scale;
  if (extent_m < kMinBodyExtentM || extent_m > kMaxBodyExtentM) {
    ARPOS_INPUT_ERROR(input.string() << ": largest extent " << extent << " file units in "
                                     << LengthUnitName(result->units) << " is " << extent_m
                                     << " m, not a body or body part (" << kMinBodyExtentM << "-"
                                     << kMaxBodyExtentM << " m); state the right --units mm|cm|dm|m");
  }
  for (auto& v : mesh.vertices) v *= static_cast<float>(scale);
  start = Clock::now();
  const size_t before = mesh.vertices.size();
  mesh = DecimateMesh(mesh, options.surface.max_vertices);
  if (mesh.vertices.size() != before) {
    result->notes.push_back(StringPrintf("decimated from %zu to %zu vertices", before, mesh.vertices.size()));
  }
  result->surface_s = SecondsSince(start);
  if (mesh.IsClosed()) {
    result->flipped_faces = OrientOutwards(&mesh);
    if (result->flipped_faces) result->notes.push_back("faces pointed inwards; reversed them");
  } else {
    result->notes.push_back("the mesh is not closed (has boundary or non-manifold edges)");
  }
  mesh.ComputeVertexNormals();
  result->mesh = std::move(mesh);
}

void ImportCtSeries(const fs::path& input, const ModelImportOptions& options,
                    const std::optional<RtPlanIsocentre>& plan, ModelImportResult* result) {
  auto start = Clock::now();
  const CtVolume ct = ReadCtSeries(input);
  result->read_s = SecondsSince(start);
  result->series_instance_uid = ct.series_instance_uid;
  result->series_description = ct.series_description;
  CheckPlanFrame(plan, options, ct.frame_of_reference_uid, input, result);
  result->num_slices = ct.geometry.size[2];
  result->voxel_spacing_mm = ct.geometry.spacing_mm;
  if (ct.series_instance_uid.empty()) {
    result->notes.push_back(
        "the slices carry no SeriesInstanceUID (anonymised?): one series is assumed from their "
        "matching size, orientation and regular spacing");
  }
  if (ct.skipped_non_dicom_files > 0) {
    result->notes.push_back(StringPrintf("skipped %d non-DICOM files in the folder", ct.skipped_non_dicom_files));
  }
  start = Clock::now();
  BodyMask mask = SegmentBody(ct, options.body, input.string());
  // Where the body reaches the edge of the field of view, the surface is
  // capped by the scan, not by skin.
  int touching = 0;
  const VolumeGeometry& g = ct.geometry;
  for (int k = 0; k < g.size[2]; ++k) {
    for (int j = 0; j < g.size[1]; ++j) {
      for (int i = 0; i < g.size[0]; ++i) {
        if ((i == 0 || j == 0 || i == g.size[0] - 1 || j == g.size[1] - 1) && mask.inside[g.Index(i, j, k)]) {
          ++touching;
        }
      }
    }
  }
  double iso = 0;
  const ScalarVolume field = BodySurfaceField(ct, mask, options.body.threshold_hu, &iso);
  result->segment_s = SecondsSince(start);
  mask.inside.clear();
  mask.inside.shrink_to_fit();
  result->body_mask_stats = mask;
  const double voxel_mm3 = g.spacing_mm.prod();
  if (mask.second_component_voxels > 0) {
    result->notes.push_back(StringPrintf(
        "kept the largest of %d connected parts (%.0f cm^3); dropped %.0f cm^3 in the others "
        "(largest dropped part %.0f cm^3: couch, cushions, arms lying apart)",
        mask.num_components, mask.body_voxels * voxel_mm3 * 1e-3, mask.dropped_voxels * voxel_mm3 * 1e-3,
        mask.second_component_voxels * voxel_mm3 * 1e-3));
  }
  if (touching > 0) {
    result->notes.push_back(StringPrintf(
        "the body reaches the edge of the CT's field of view (%d voxels): the surface is cut flat there",
        touching));
  }
  result->notes.push_back(StringPrintf(
      "the surface is capped flat at the first and last slice (the scan covers %.0f mm)",
      (g.size[2] - 1) * g.spacing_mm.z()));
  start = Clock::now();
  SurfaceOptions surface = options.surface;
  surface.iso_value = iso;
  result->mesh = ExtractSurface(field, surface, input.string(), &result->surface_stats);
  result->surface_s = SecondsSince(start);
  ApplyOrigin(plan, options, result);
}

// Largest part only and cavities filled, on the coverage volume: a voxel is
// inside where coverage >= 0.5 (the iso-value).
void CleanCoverage(const ModelImportOptions& options, ScalarVolume* coverage, ModelImportResult* result) {
  if (!options.rtstruct_keep_largest_part && !options.rtstruct_fill_holes) return;
  const VolumeGeometry& g = coverage->geometry;
  std::vector<uint8_t> inside(coverage->values.size());
  for (size_t n = 0; n < inside.size(); ++n) inside[n] = coverage->values[n] >= 0.5f ? 1 : 0;
  const std::vector<uint8_t> before = inside;
  const double voxel_cm3 = g.spacing_mm.prod() * 1e-3;
  if (options.rtstruct_keep_largest_part) {
    const ComponentStats stats = KeepLargestComponent(g, &inside);
    if (stats.num_components > 1) {
      result->notes.push_back(StringPrintf(
          "kept the largest of %d separate parts of the ROI (%.0f cm^3); dropped %.1f cm^3 "
          "(largest dropped part %.1f cm^3: couch rails, markers, immobilisation?)",
          stats.num_components, stats.kept_voxels * voxel_cm3, stats.dropped_voxels * voxel_cm3,
          stats.second_component_voxels * voxel_cm3));
    }
  }
  if (options.rtstruct_fill_holes) {
    const size_t filled = FillHolesPerSlice(g, &inside);
    if (filled > 0) {
      result->notes.push_back(StringPrintf("filled %.1f cm^3 of cavities enclosed by the outline",
                                           filled * voxel_cm3));
    }
  }
  for (size_t n = 0; n < inside.size(); ++n) {
    if (before[n] && !inside[n]) coverage->values[n] = 0.0f;  // dropped part
    if (!before[n] && inside[n]) coverage->values[n] = 1.0f;  // filled cavity
  }
}

void ImportRtStruct(const fs::path& input, const ModelImportOptions& options,
                    const std::optional<RtPlanIsocentre>& plan, ModelImportResult* result) {
  auto start = Clock::now();
  const RtStructureSet structure_set = ReadRtStruct(input);
  result->read_s = SecondsSince(start);
  CheckPlanFrame(plan, options, structure_set.frame_of_reference_uid, input, result);
  const size_t index = SelectBodyRoi(structure_set, options.roi_name, input, &result->roi_selection);
  const RtRoi& roi = structure_set.rois[index];
  result->roi_name = roi.name;
  result->roi_interpreted_type = roi.interpreted_type;
  if (roi.contours.empty()) {
    ARPOS_INPUT_ERROR(input.string() << ": ROI '" << roi.name << "' has no contours");
  }
  std::map<std::string, int> types;
  for (const auto& c : roi.contours) ++types[c.geometric_type.empty() ? "(none)" : c.geometric_type];
  if (types.size() != 1 || types.begin()->first != "CLOSED_PLANAR") {
    std::ostringstream list;
    for (const auto& [type, count] : types) list << " " << count << " " << type << ";";
    ARPOS_INPUT_ERROR(input.string() << ": ROI '" << roi.name << "' has contours that are not CLOSED_PLANAR ("
                                     << Trim(list.str()) << "); only closed planar contours outline a body");
  }
  std::vector<std::vector<Eigen::Vector3d>> contours;
  for (const auto& c : roi.contours) contours.push_back(c.points_mm);
  start = Clock::now();
  const std::string source = input.string() + ", ROI '" + roi.name + "'";
  ContourRasterResult raster = RasterizeContours(contours, options.contours, source);
  result->num_slices = raster.num_planes;
  result->voxel_spacing_mm = raster.coverage.geometry.spacing_mm;
  if (raster.skipped_degenerate > 0) {
    result->notes.push_back(StringPrintf("skipped %d contours with fewer than 3 points or no area",
                                         raster.skipped_degenerate));
  }
  if (raster.filled_missing_slices > 0) {
    result->notes.push_back(StringPrintf(
        "%d slices between contour planes had no contour; filled from the nearest plane",
        raster.filled_missing_slices));
  }
  result->notes.push_back(StringPrintf(
      "the surface is capped flat half a slice (%.1f mm) beyond the first and last contour",
      0.5 * raster.slice_spacing_mm));
  ScalarVolume coverage = std::move(raster.coverage);
  CleanCoverage(options, &coverage, result);
  result->segment_s = SecondsSince(start);
  start = Clock::now();
  SurfaceOptions surface = options.surface;
  surface.iso_value = 0.5;
  surface.largest_component_only = options.rtstruct_keep_largest_part;
  result->mesh = ExtractSurface(coverage, surface, source, &result->surface_stats);
  result->surface_s = SecondsSince(start);
  ApplyOrigin(plan, options, result);
}

}  // namespace

const char* ModelSourceKindName(ModelSourceKind kind) {
  switch (kind) {
    case ModelSourceKind::kMeshFile: return "mesh file";
    case ModelSourceKind::kCtSeries: return "CT series";
    case ModelSourceKind::kRtStruct: return "RTSTRUCT";
  }
  return "?";
}

bool ModelImportOptions::Check(std::string* reason) const {
  if (!body.Check(reason) || !contours.Check(reason)) return false;
  SurfaceOptions s = surface;
  s.iso_value = 0;
  if (!s.Check(reason)) return false;
  if (origin == ModelOrigin::kIsocentre && rtplan_path.empty()) {
    *reason = "origin at the isocentre needs an RTPLAN (--rtplan FILE)";
    return false;
  }
  return true;
}

ModelSourceKind DetectModelSource(const fs::path& input) {
  std::error_code ec;
  const fs::file_status status = fs::status(input, ec);
  if (ec || !fs::exists(status)) ARPOS_INPUT_ERROR(input.string() << ": no such file or folder");
  if (fs::is_directory(status)) return ModelSourceKind::kCtSeries;
  if (!fs::is_regular_file(status)) ARPOS_INPUT_ERROR(input.string() << ": not a regular file or folder");
  if (IsMeshExtension(input)) return ModelSourceKind::kMeshFile;
  const DicomFileInfo info = ProbeDicomFile(input);
  if (!info.is_dicom) {
    ARPOS_INPUT_ERROR(input.string() << ": not a DICOM file (no DICM preamble or unreadable header)"
                                     << (ToLower(input.extension().string()) == ".dcm"
                                             ? ""
                                             : " and not a mesh file (.ply .stl .obj .off)"));
  }
  if (info.modality == "RTSTRUCT") return ModelSourceKind::kRtStruct;
  if (info.modality == "CT") {
    ARPOS_INPUT_ERROR(input.string() << ": a single CT slice; give the folder holding the whole series ("
                                     << input.parent_path().string() << ")");
  }
  ARPOS_INPUT_ERROR(input.string() << ": DICOM " << (info.modality.empty() ? "object without modality" : info.modality)
                                   << " is no body surface source; give a CT series folder, an RTSTRUCT or a mesh file");
}

size_t SelectBodyRoi(const RtStructureSet& structure_set, const std::string& requested,
                     const fs::path& file, std::string* how) {
  std::string local;
  if (how == nullptr) how = &local;
  auto list_rois = [&]() {
    std::ostringstream out;
    for (size_t r = 0; r < structure_set.rois.size(); ++r) {
      const RtRoi& roi = structure_set.rois[r];
      out << (r ? ", " : "") << "'" << roi.name << "'";
      if (!roi.interpreted_type.empty()) out << " (" << roi.interpreted_type << ")";
    }
    return out.str();
  };
  if (structure_set.rois.empty()) {
    ARPOS_INPUT_ERROR(file.string() << ": the RTSTRUCT has no ROIs (empty structure set)");
  }
  if (!requested.empty()) {
    const std::string wanted = ToLower(Trim(requested));
    for (size_t r = 0; r < structure_set.rois.size(); ++r) {
      if (ToLower(structure_set.rois[r].name) == wanted) {
        *how = "named with --roi";
        return r;
      }
    }
    ARPOS_INPUT_ERROR(file.string() << ": no ROI named '" << requested << "'; ROIs found: " << list_rois());
  }
  static const char* kBodyNames[] = {"external", "body", "outer contour", "outline", "skin"};
  for (const char* name : kBodyNames) {
    for (size_t r = 0; r < structure_set.rois.size(); ++r) {
      if (ToLower(Trim(structure_set.rois[r].name)) == name) {
        *how = std::string("name '") + structure_set.rois[r].name + "'";
        return r;
      }
    }
  }
  for (size_t r = 0; r < structure_set.rois.size(); ++r) {
    if (ToLower(structure_set.rois[r].interpreted_type) == "external") {
      *how = "RTROIInterpretedType EXTERNAL";
      return r;
    }
  }
  ARPOS_INPUT_ERROR(file.string() << ": no body ROI (named EXTERNAL, BODY, Outer contour, Outline or Skin, "
                                     "or of type EXTERNAL); ROIs found: "
                                  << list_rois() << "; choose one with --roi NAME");
}

ModelImportResult ImportModel(const fs::path& input, const ModelImportOptions& options) {
  std::string reason;
  if (!options.Check(&reason)) ARPOS_INPUT_ERROR("invalid import options: " << reason);
  const auto start = Clock::now();
  ModelImportResult result;
  result.kind = DetectModelSource(input);
  // Our own checks throw InputError; anything else escaping GDCM, VTK or
  // assimp (bad_alloc on absurd sizes, length_error, ...) is reported as a
  // problem with this input rather than a crash.
  try {
    std::optional<RtPlanIsocentre> plan;
    if (!options.rtplan_path.empty() && result.kind != ModelSourceKind::kMeshFile) {
      plan = ReadRtPlanIsocentre(options.rtplan_path);
    }
    switch (result.kind) {
      case ModelSourceKind::kMeshFile: ImportMeshFile(input, options, &result); break;
      case ModelSourceKind::kCtSeries: ImportCtSeries(input, options, plan, &result); break;
      case ModelSourceKind::kRtStruct: ImportRtStruct(input, options, plan, &result); break;
    }
  } catch (const Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    ARPOS_INPUT_ERROR(input.string() << ": out of memory while importing (input too large or corrupt)");
  } catch (const std::exception& e) {
    ARPOS_INPUT_ERROR(input.string() << ": cannot import: " << e.what());
  }
  if (result.has_patient_frame && result.isocentre_in_patient_mm) {
    const Eigen::Vector3d iso_model_mm =
        result.model_from_patient * (*result.isocentre_in_patient_mm * 0.001) * 1000.0;
    result.notes.push_back("RTPLAN isocentre at " + FormatMm(*result.isocentre_in_patient_mm) +
                           " in the patient frame, " + FormatMm(iso_model_mm) + " in the model frame");
  }
  const SurfaceStats& surface = result.surface_stats;
  if (options.surface.max_vertices > 0 && surface.full_resolution_vertices > options.surface.max_vertices) {
    result.notes.push_back(StringPrintf(
        "%d vertices at full resolution exceed the budget of %d: extracted on a %.2f x %.2f mm grid, %s",
        surface.full_resolution_vertices, options.surface.max_vertices, surface.grid_spacing_mm.x(),
        surface.grid_spacing_mm.y(),
        surface.decimation_broke_surface ? "not decimated (decimation left the surface open)"
                                         : "then decimated"));
  }
  if (surface.dropped_faces > 0) {
    result.notes.push_back(StringPrintf("dropped %d faces in small pieces apart from the surface",
                                        surface.dropped_faces));
  }
  result.summary = SummarizeMesh(result.mesh);
  if (!result.summary.closed && result.kind != ModelSourceKind::kMeshFile) {
    result.notes.push_back(StringPrintf("the surface is not closed: %d boundary, %d non-manifold edges",
                                        result.summary.boundary_edges, result.summary.non_manifold_edges));
  }
  result.total_s = SecondsSince(start);
  return result;
}

std::string ModelProvenanceComment(const ModelImportResult& result, const fs::path& input) {
  std::ostringstream out;
  out << "arpos import-model: reference body surface from " << ModelSourceKindName(result.kind) << " "
      << input.filename().string() << "\n";
  if (result.has_patient_frame) {
    out << "frame: DICOM patient (LPS) axes, metres, origin "
        << (result.model_from_patient.translation.isZero() ? "patient-frame origin" : "RTPLAN isocentre") << "\n";
    if (!result.frame_of_reference_uid.empty()) out << "FrameOfReferenceUID " << result.frame_of_reference_uid << "\n";
    if (!result.series_instance_uid.empty()) out << "SeriesInstanceUID " << result.series_instance_uid << "\n";
    if (!result.roi_name.empty()) out << "ROI " << result.roi_name << "\n";
  } else {
    out << "frame: the file's own axes, metres (read as " << LengthUnitName(result.units) << ")\n";
  }
  return out.str();
}

}  // namespace arpos
