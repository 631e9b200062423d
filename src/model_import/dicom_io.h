#pragma once
/// Reading the DICOM objects a plan's reference surface comes from: a CT
/// series (folder), an RTSTRUCT and the isocentre of an RTPLAN. GDCM does the
/// parsing (every transfer syntax it supports, compressed included); nothing
/// of GDCM shows in this header.
///
/// Frames and units: everything is in the DICOM patient frame (LPS), in mm,
/// exactly as stored in the files. Every function throws arpos::InputError
/// whose message names the file or folder when the input is missing, not
/// DICOM, of the wrong kind, or inconsistent; GDCM's own diagnostics are
/// silenced (library code never prints). Not thread-safe with respect to
/// GDCM's global trace settings (set once per call, harmless).

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "model_import/volume.h"

namespace arpos {

/// What a single file is, judged from its header only.
struct DicomFileInfo {
  bool is_dicom = false;   ///< has the DICM preamble and GDCM can parse its header
  std::string modality;    ///< (0008,0060), e.g. "CT", "RTSTRUCT", "RTPLAN"
  std::string sop_class_uid;
};

/// Never throws for an unreadable or non-DICOM file (is_dicom = false); throws
/// InputError only if the file does not exist.
DicomFileInfo ProbeDicomFile(const std::filesystem::path& file);

struct CtSeriesReadOptions {
  /// Fewer slices than this cannot make a surface and are refused.
  int min_slices = 3;
  /// Largest allowed deviation of any slice gap from the median gap (a missing
  /// or duplicated slice, or irregular spacing, is refused).
  double spacing_tolerance_mm = 0.05;
  /// Largest allowed difference between direction cosines of two slices.
  double orientation_tolerance = 1e-4;
  bool Check(std::string* reason) const;
};

/// A CT series as one volume in Hounsfield units.
struct CtVolume {
  /// i = column (along the row direction cosine), j = row (along the column
  /// direction cosine), k = slice, sorted by ImagePositionPatient along the
  /// slice normal (row x column), ascending. origin_mm is the first slice's
  /// ImagePositionPatient.
  VolumeGeometry geometry;
  /// HU = RescaleSlope * stored + RescaleIntercept, clamped to int16.
  std::vector<int16_t> hu;
  std::string series_instance_uid;
  std::string frame_of_reference_uid;
  std::string series_description;
  /// Files in slice order (index k).
  std::vector<std::filesystem::path> files;
  /// Files of the folder skipped because they are not DICOM (or DICOMDIR).
  int skipped_non_dicom_files = 0;
};

/// Reads every DICOM file directly in `folder` (not recursive) as one CT
/// series. Refuses (InputError naming the folder and, where it applies, the
/// file): no DICOM file, several SeriesInstanceUIDs (listed with their file
/// counts), a modality other than CT, multi-frame or colour images, differing
/// image sizes, pixel spacings or orientations, coincident slices, missing or
/// irregular slice gaps, fewer than options.min_slices slices, unreadable
/// pixel data.
CtVolume ReadCtSeries(const std::filesystem::path& folder,
                      const CtSeriesReadOptions& options = CtSeriesReadOptions());

/// One contour of an RTSTRUCT ROI (ROIContourSequence > ContourSequence).
struct RtContour {
  std::string geometric_type;                ///< (3006,0042), e.g. "CLOSED_PLANAR"
  std::vector<Eigen::Vector3d> points_mm;    ///< (3006,0050), patient frame
};

struct RtRoi {
  int number = 0;                 ///< ROINumber (3006,0022)
  std::string name;               ///< ROIName (3006,0026)
  std::string interpreted_type;   ///< RTROIInterpretedType (3006,00A4), e.g. "EXTERNAL"
  std::vector<RtContour> contours;
};

struct RtStructureSet {
  std::string label;                    ///< StructureSetLabel (3006,0002)
  std::string frame_of_reference_uid;   ///< of the first referenced frame of reference
  std::vector<RtRoi> rois;              ///< in StructureSetROISequence order
};

/// Reads an RTSTRUCT. Refuses a file that is not DICOM, not an RTSTRUCT, or
/// whose contour data are malformed (point count mismatch, non-numbers).
/// An RTSTRUCT without ROIs is returned as such (the caller decides).
RtStructureSet ReadRtStruct(const std::filesystem::path& file);

/// The treatment isocentre of an RTPLAN.
struct RtPlanIsocentre {
  Eigen::Vector3d isocentre_mm = Eigen::Vector3d::Zero();  ///< patient frame
  std::string frame_of_reference_uid;
  std::string plan_label;
  int num_beams = 0;
};

/// IsocenterPosition (300A,012C) from the first control point of every beam
/// (BeamSequence, or IonBeamSequence). Refuses a plan without one, or whose
/// beams have different isocentres (more than 0.01 mm apart: the model origin
/// would be ambiguous).
RtPlanIsocentre ReadRtPlanIsocentre(const std::filesystem::path& file);

}  // namespace arpos
