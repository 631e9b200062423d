#pragma once
/// Importing the patient's reference body surface for a plan.
///
/// Sources (DetectModelSource tells which from the path):
///  - a mesh file (PLY, STL, OBJ, OFF and other assimp formats) in a stated or
///    detected length unit (length_units.h); coordinates keep the file's
///    frame and axes, only the unit changes;
///  - a folder holding one DICOM CT series: the body is segmented
///    (body_mask.h) and its skin surface extracted; the scan's first and last
///    slices cap the surface with flat ends (the body goes on beyond the scan);
///  - a DICOM RTSTRUCT: the body ROI's closed planar contours are stacked into
///    a closed surface (contour_raster.h).
///
/// Output frame and units: METRES. For DICOM sources the model frame is the
/// DICOM patient frame (LPS) of the CT / structure set, with its origin either
/// at the patient-frame origin or, with ModelOrigin::kIsocentre, at the RTPLAN
/// isocentre (axes unchanged): point_in_model = model_from_patient *
/// point_in_patient. Mesh files have no patient frame: the model frame is the
/// file's own.
///
/// Errors: bad or hostile input throws arpos::InputError whose message names
/// the file or folder and says what is wrong (and, where it helps, which
/// option to use); library failures (GDCM, VTK, assimp) are caught and turned
/// into InputError or arpos::Error. Nothing is printed; `notes` carries what a
/// person should read. Thread-compatible.

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "model_import/body_mask.h"
#include "model_import/contour_raster.h"
#include "model_import/dicom_io.h"
#include "model_import/length_units.h"
#include "model_import/mesh_stats.h"
#include "model_import/surface_extraction.h"

namespace arpos {

enum class ModelSourceKind { kMeshFile, kCtSeries, kRtStruct };
/// "mesh file", "CT series", "RTSTRUCT".
const char* ModelSourceKindName(ModelSourceKind kind);

enum class ModelOrigin {
  kPatient,    ///< DICOM patient-frame origin (coordinates as in the files)
  kIsocentre,  ///< RTPLAN isocentre (ModelImportOptions::rtplan_path required)
};

struct ModelImportOptions {
  /// Mesh files: the unit of the file's coordinates; empty = detect.
  std::optional<LengthUnit> units;
  /// Mesh files: keep only this group / object (e.g. "body" of MakeHuman).
  std::string mesh_group;
  /// RTSTRUCT: ROI name (case-insensitive); empty = the body ROI (see
  /// SelectBodyRoi).
  std::string roi_name;
  BodyMaskOptions body;             ///< CT segmentation (threshold_hu, opening)
  ContourRasterOptions contours;    ///< RTSTRUCT rasterisation
  /// RTSTRUCT: keep only the largest connected part of the ROI (body
  /// outlines often include couch rails, immobilisation or marker contours
  /// lying apart from the body) and fill enclosed cavities slice by slice
  /// (holes of the even-odd fill, e.g. air pockets), so that the model is the
  /// outer skin only. A CT series always gets both (body_mask.h).
  bool rtstruct_keep_largest_part = true;
  bool rtstruct_fill_holes = true;
  /// Decimation budget and smoothing of extracted surfaces (iso_value is set
  /// by the importer). max_vertices also caps mesh files.
  SurfaceOptions surface;
  ModelOrigin origin = ModelOrigin::kPatient;
  /// RTPLAN whose isocentre is the model origin (kIsocentre); with kPatient
  /// it is only read to report where the isocentre lies. Its
  /// FrameOfReferenceUID must match the CT's / structure set's.
  std::filesystem::path rtplan_path;
  bool Check(std::string* reason) const;
};

struct ModelImportResult {
  ModelSourceKind kind = ModelSourceKind::kMeshFile;
  TriangleMesh mesh;    ///< metres, model frame, faces outwards where closed
  MeshSummary summary;  ///< of `mesh` (metres)

  // Mesh files.
  LengthUnit units = LengthUnit::kMetre;
  bool units_detected = false;
  std::string units_explanation;
  bool flipped_faces = false;  ///< a closed mesh came with inward faces

  // DICOM sources.
  bool has_patient_frame = false;
  /// Identity, or a translation by minus the isocentre (metres).
  Rigid3d model_from_patient;
  std::optional<Eigen::Vector3d> isocentre_in_patient_mm;
  std::string frame_of_reference_uid;
  std::string series_instance_uid;   ///< CT
  std::string series_description;    ///< CT
  int num_slices = 0;                ///< CT slices or contour planes
  Eigen::Vector3d voxel_spacing_mm = Eigen::Vector3d::Zero();  ///< grid the surface came from
  std::string roi_name;              ///< RTSTRUCT
  std::string roi_interpreted_type;  ///< RTSTRUCT
  std::string roi_selection;         ///< how the ROI was chosen, for the report
  BodyMask body_mask_stats;          ///< CT (the voxel mask itself is dropped)
  SurfaceStats surface_stats;

  std::vector<std::string> notes;  ///< warnings and facts a person should read
  double read_s = 0, segment_s = 0, surface_s = 0, total_s = 0;
};

/// Which source `input` is: a folder is a CT series; a file with a mesh
/// extension is a mesh; a DICOM file must be an RTSTRUCT. Throws InputError
/// naming the path for a missing path, a single CT slice (give the folder), a
/// DICOM object of another kind, or a file that is neither mesh nor DICOM.
ModelSourceKind DetectModelSource(const std::filesystem::path& input);

/// Index into structure_set.rois of the body ROI: `requested` if not empty
/// (case-insensitive name), else the first ROI named EXTERNAL, BODY, OUTER
/// CONTOUR, OUTLINE, SKIN (case-insensitive, in that order of preference),
/// else the first ROI whose RTROIInterpretedType is EXTERNAL. Throws
/// InputError naming `file` and listing the ROIs found if none qualifies or
/// the structure set has no ROIs. `how` (optional) says which rule chose it.
size_t SelectBodyRoi(const RtStructureSet& structure_set, const std::string& requested,
                     const std::filesystem::path& file, std::string* how = nullptr);

/// Imports `input` (any source above) as the plan's reference model.
ModelImportResult ImportModel(const std::filesystem::path& input, const ModelImportOptions& options);

/// Provenance lines for the PLY header: source, kind, frame, unit, UIDs.
std::string ModelProvenanceComment(const ModelImportResult& result,
                                   const std::filesystem::path& input);

}  // namespace arpos
