#include "model_import/dicom_io.h"

#include <gdcmAttribute.h>
#include <gdcmDataSet.h>
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmPixelFormat.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmTag.h>
#include <gdcmTrace.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>

#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace fs = std::filesystem;
namespace {

// GDCM reports problems on std::cerr through its Trace class; library code
// must not print, and every failure we care about is turned into InputError.
void SilenceGdcm() {
  static std::once_flag once;
  std::call_once(once, [] {
    gdcm::Trace::SetDebug(false);
    gdcm::Trace::SetWarning(false);
    gdcm::Trace::SetError(false);
  });
}

bool HasDicmPreamble(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  char buffer[132];
  if (!in.read(buffer, sizeof(buffer))) return false;
  return std::memcmp(buffer + 128, "DICM", 4) == 0;
}

// String value of a (non-sequence, text VR) element, DICOM padding removed;
// empty if absent.
std::string GetString(const gdcm::DataSet& ds, uint16_t group, uint16_t element) {
  const gdcm::Tag tag(group, element);
  if (!ds.FindDataElement(tag)) return {};
  const gdcm::DataElement& de = ds.GetDataElement(tag);
  const gdcm::ByteValue* bv = de.GetByteValue();
  if (bv == nullptr || bv->GetPointer() == nullptr) return {};
  std::string value(bv->GetPointer(), bv->GetLength());
  while (!value.empty() && (value.back() == '\0' || value.back() == ' ')) value.pop_back();
  return Trim(value);
}

// Multi-valued decimal string ("1.5\-2\3e1"). Returns false on a token that is
// not a finite number.
bool ParseDecimalStrings(const std::string& text, std::vector<double>* values) {
  values->clear();
  if (text.empty()) return true;
  size_t start = 0;
  while (true) {
    const size_t end = text.find('\\', start);
    const std::string token = Trim(text.substr(start, end - start));
    double value = 0;
    if (!ParseDouble(token, &value)) return false;
    values->push_back(value);
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return true;
}

// Like ParseDecimalStrings for an element; `what` names it in the error.
std::vector<double> GetDecimals(const gdcm::DataSet& ds, uint16_t group, uint16_t element,
                                const fs::path& file, const char* what) {
  std::vector<double> values;
  if (!ParseDecimalStrings(GetString(ds, group, element), &values)) {
    ARPOS_INPUT_ERROR(file.string() << ": " << what << " is not a list of numbers");
  }
  return values;
}

// Sequence items' data sets (empty if the element is absent or not a sequence).
std::vector<const gdcm::DataSet*> GetItems(const gdcm::DataSet& ds, uint16_t group,
                                           uint16_t element,
                                           std::vector<gdcm::SmartPointer<gdcm::SequenceOfItems>>* keep) {
  std::vector<const gdcm::DataSet*> items;
  const gdcm::Tag tag(group, element);
  if (!ds.FindDataElement(tag)) return items;
  gdcm::SmartPointer<gdcm::SequenceOfItems> sq = ds.GetDataElement(tag).GetValueAsSQ();
  if (!sq) return items;
  keep->push_back(sq);
  for (gdcm::SequenceOfItems::SizeType i = 1; i <= sq->GetNumberOfItems(); ++i) {
    items.push_back(&sq->GetItem(i).GetNestedDataSet());
  }
  return items;
}

// A US element (Rows, Columns, ...) through gdcm::Attribute, which decodes the
// binary value in any transfer syntax; -1 if absent or empty.
template <uint16_t Group, uint16_t Element>
int GetUnsignedShort(const gdcm::DataSet& ds) {
  gdcm::Attribute<Group, Element> attribute;
  const gdcm::Tag tag(Group, Element);
  if (!ds.FindDataElement(tag) || ds.GetDataElement(tag).IsEmpty()) return -1;
  attribute.SetFromDataSet(ds);
  return static_cast<int>(attribute.GetValue());
}

// Reads the header (everything before the pixel data). Throws InputError if
// GDCM cannot parse it.
void ReadHeader(const fs::path& file, gdcm::Reader* reader) {
  SilenceGdcm();
  reader->SetFileName(file.string().c_str());
  bool ok = false;
  try {
    ok = reader->ReadUpToTag(gdcm::Tag(0x7fe0, 0x0010));
  } catch (const std::exception& e) {
    ARPOS_INPUT_ERROR(file.string() << ": cannot parse DICOM header: " << e.what());
  }
  if (!ok) ARPOS_INPUT_ERROR(file.string() << ": not a readable DICOM file");
}

// Full read (sequences included) for RT objects.
void ReadWholeFile(const fs::path& file, gdcm::Reader* reader, const char* expected_modality) {
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) {
    ARPOS_INPUT_ERROR(file.string() << ": file does not exist or is not a regular file");
  }
  const DicomFileInfo info = ProbeDicomFile(file);
  if (!info.is_dicom) ARPOS_INPUT_ERROR(file.string() << ": not a DICOM file");
  if (info.modality != expected_modality) {
    ARPOS_INPUT_ERROR(file.string() << ": DICOM " << (info.modality.empty() ? "(no modality)" : info.modality)
                                    << " object, expected " << expected_modality);
  }
  SilenceGdcm();
  reader->SetFileName(file.string().c_str());
  bool ok = false;
  try {
    ok = reader->Read();
  } catch (const std::exception& e) {
    ARPOS_INPUT_ERROR(file.string() << ": cannot parse DICOM file: " << e.what());
  }
  if (!ok) ARPOS_INPUT_ERROR(file.string() << ": cannot parse DICOM file (truncated or corrupt?)");
}

std::string DescribeUid(const std::string& uid) { return uid.empty() ? "(none)" : uid; }

struct SliceHeader {
  fs::path file;
  std::string series_uid, frame_of_reference_uid, modality, description;
  Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d row_dir = Eigen::Vector3d::Zero(), col_dir = Eigen::Vector3d::Zero();
  double row_spacing_mm = 0, col_spacing_mm = 0;  // PixelSpacing: between rows, between columns
  int rows = -1, columns = -1;
  double slope = 1, intercept = 0;
  int frames = 1;
  int samples_per_pixel = 1;
  double distance_mm = 0;  // along the slice normal
};

bool IsNonImageModality(const std::string& modality) {
  static const std::set<std::string> kNonImage = {"RTSTRUCT", "RTPLAN", "RTDOSE", "RTRECORD",
                                                  "RTIMAGE",  "REG",    "SR",     "KO",
                                                  "PR",       "SEG",    "DOC",    "PLAN"};
  return kNonImage.count(modality) > 0;
}

SliceHeader ReadSliceHeader(const fs::path& file) {
  gdcm::Reader reader;
  ReadHeader(file, &reader);
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  SliceHeader h;
  h.file = file;
  h.series_uid = GetString(ds, 0x0020, 0x000e);
  h.frame_of_reference_uid = GetString(ds, 0x0020, 0x0052);
  h.modality = GetString(ds, 0x0008, 0x0060);
  h.description = GetString(ds, 0x0008, 0x103e);
  if (IsNonImageModality(h.modality)) return h;
  const std::vector<double> ipp = GetDecimals(ds, 0x0020, 0x0032, file, "ImagePositionPatient");
  const std::vector<double> iop = GetDecimals(ds, 0x0020, 0x0037, file, "ImageOrientationPatient");
  const std::vector<double> ps = GetDecimals(ds, 0x0028, 0x0030, file, "PixelSpacing");
  if (ipp.size() != 3) ARPOS_INPUT_ERROR(file.string() << ": missing or malformed ImagePositionPatient");
  if (iop.size() != 6) ARPOS_INPUT_ERROR(file.string() << ": missing or malformed ImageOrientationPatient");
  if (ps.size() != 2 || !(ps[0] > 0) || !(ps[1] > 0)) {
    ARPOS_INPUT_ERROR(file.string() << ": missing or malformed PixelSpacing");
  }
  h.position_mm = Eigen::Vector3d(ipp[0], ipp[1], ipp[2]);
  h.row_dir = Eigen::Vector3d(iop[0], iop[1], iop[2]);
  h.col_dir = Eigen::Vector3d(iop[3], iop[4], iop[5]);
  h.row_spacing_mm = ps[0];
  h.col_spacing_mm = ps[1];
  h.rows = GetUnsignedShort<0x0028, 0x0010>(ds);
  h.columns = GetUnsignedShort<0x0028, 0x0011>(ds);
  h.samples_per_pixel = GetUnsignedShort<0x0028, 0x0002>(ds);
  const std::string frames = GetString(ds, 0x0028, 0x0008);
  long long frame_count = 1;
  if (!frames.empty() && ParseInt(frames, &frame_count)) h.frames = static_cast<int>(frame_count);
  const std::vector<double> slope = GetDecimals(ds, 0x0028, 0x1053, file, "RescaleSlope");
  const std::vector<double> intercept = GetDecimals(ds, 0x0028, 0x1052, file, "RescaleIntercept");
  if (!slope.empty()) h.slope = slope[0];
  if (!intercept.empty()) h.intercept = intercept[0];
  if (!(h.slope != 0) || !std::isfinite(h.slope) || !std::isfinite(h.intercept)) {
    ARPOS_INPUT_ERROR(file.string() << ": invalid RescaleSlope/RescaleIntercept");
  }
  return h;
}

template <typename T>
void ConvertToHu(const char* buffer, size_t count, double slope, double intercept, int16_t* out) {
  for (size_t n = 0; n < count; ++n) {
    T raw;
    std::memcpy(&raw, buffer + n * sizeof(T), sizeof(T));
    const double hu = std::round(slope * static_cast<double>(raw) + intercept);
    out[n] = static_cast<int16_t>(std::clamp(hu, -32768.0, 32767.0));
  }
}

void ReadSlicePixels(const SliceHeader& h, int16_t* out) {
  SilenceGdcm();
  gdcm::ImageReader reader;
  reader.SetFileName(h.file.string().c_str());
  bool ok = false;
  try {
    ok = reader.Read();
  } catch (const std::exception& e) {
    ARPOS_INPUT_ERROR(h.file.string() << ": cannot read pixel data: " << e.what());
  }
  if (!ok) ARPOS_INPUT_ERROR(h.file.string() << ": cannot read pixel data (truncated or unsupported)");
  const gdcm::Image& image = reader.GetImage();
  const unsigned columns = image.GetDimension(0), rows = image.GetDimension(1);
  if (static_cast<int>(columns) != h.columns || static_cast<int>(rows) != h.rows) {
    ARPOS_INPUT_ERROR(h.file.string() << ": pixel data is " << columns << "x" << rows
                                      << ", header says " << h.columns << "x" << h.rows);
  }
  const gdcm::PixelFormat& pf = image.GetPixelFormat();
  if (pf.GetSamplesPerPixel() != 1) {
    ARPOS_INPUT_ERROR(h.file.string() << ": colour image (" << pf.GetSamplesPerPixel()
                                      << " samples per pixel); a CT slice is grey");
  }
  const size_t count = static_cast<size_t>(columns) * rows;
  std::vector<char> buffer(image.GetBufferLength());
  bool got = false;
  try {
    got = image.GetBuffer(buffer.data());
  } catch (const std::exception& e) {
    ARPOS_INPUT_ERROR(h.file.string() << ": cannot decode pixel data: " << e.what());
  }
  if (!got) ARPOS_INPUT_ERROR(h.file.string() << ": cannot decode pixel data (truncated or unsupported)");
  const size_t bytes = pf.GetPixelSize();
  if (buffer.size() < count * bytes) {
    ARPOS_INPUT_ERROR(h.file.string() << ": pixel data too short (" << buffer.size() << " bytes for "
                                      << count << " pixels)");
  }
  switch (pf.GetScalarType()) {
    case gdcm::PixelFormat::UINT8: ConvertToHu<uint8_t>(buffer.data(), count, h.slope, h.intercept, out); break;
    case gdcm::PixelFormat::INT8: ConvertToHu<int8_t>(buffer.data(), count, h.slope, h.intercept, out); break;
    case gdcm::PixelFormat::UINT16: ConvertToHu<uint16_t>(buffer.data(), count, h.slope, h.intercept, out); break;
    case gdcm::PixelFormat::INT16: ConvertToHu<int16_t>(buffer.data(), count, h.slope, h.intercept, out); break;
    case gdcm::PixelFormat::UINT32: ConvertToHu<uint32_t>(buffer.data(), count, h.slope, h.intercept, out); break;
    case gdcm::PixelFormat::INT32: ConvertToHu<int32_t>(buffer.data(), count, h.slope, h.intercept, out); break;
    default:
      ARPOS_INPUT_ERROR(h.file.string() << ": unsupported pixel format " << pf.GetScalarTypeAsString());
  }
}

}  // namespace

DicomFileInfo ProbeDicomFile(const fs::path& file) {
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) {
    ARPOS_INPUT_ERROR(file.string() << ": file does not exist or is not a regular file");
  }
  DicomFileInfo info;
  // The 128-byte preamble + "DICM" is mandatory for DICOM files (PS3.10);
  // requiring it keeps GDCM from "parsing" arbitrary bytes as implicit VR.
  if (!HasDicmPreamble(file)) return info;
  SilenceGdcm();
  gdcm::Reader reader;
  reader.SetFileName(file.string().c_str());
  try {
    if (!reader.ReadUpToTag(gdcm::Tag(0x7fe0, 0x0010))) return info;
  } catch (const std::exception&) {
    return info;
  }
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  info.modality = GetString(ds, 0x0008, 0x0060);
  info.sop_class_uid = GetString(ds, 0x0008, 0x0016);
  info.is_dicom = true;
  return info;
}

bool CtSeriesReadOptions::Check(std::string* reason) const {
  if (min_slices < 2) {
    *reason = "min_slices must be at least 2";
    return false;
  }
  if (!(spacing_tolerance_mm > 0) || !(orientation_tolerance > 0)) {
    *reason = "tolerances must be positive";
    return false;
  }
  return true;
}

CtVolume ReadCtSeries(const fs::path& folder, const CtSeriesReadOptions& options) {
  std::string reason;
  ARPOS_CHECK(options.Check(&reason), "invalid CtSeriesReadOptions: " << reason);
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) {
    ARPOS_INPUT_ERROR(folder.string() << ": not a folder (a CT series is read from the folder holding its slices)");
  }
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    if (!entry.is_regular_file(ec)) continue;
    const std::string name = entry.path().filename().string();
    if (StartsWith(name, ".") || ToLower(name) == "dicomdir") continue;
    files.push_back(entry.path());
  }
  if (ec) ARPOS_INPUT_ERROR(folder.string() << ": cannot list folder: " << ec.message());
  std::sort(files.begin(), files.end());

  CtVolume volume;
  std::map<std::string, std::vector<const SliceHeader*>> by_series;
  std::vector<SliceHeader> headers;
  headers.reserve(files.size());
  int other_objects = 0;
  for (const auto& file : files) {
    const DicomFileInfo info = ProbeDicomFile(file);
    if (!info.is_dicom) {
      ++volume.skipped_non_dicom_files;
      continue;
    }
    SliceHeader h = ReadSliceHeader(file);
    if (IsNonImageModality(h.modality)) {
      ++other_objects;  // RTSTRUCT/RTPLAN/... exported next to the images
      continue;
    }
    headers.push_back(std::move(h));
  }
  if (headers.empty()) {
    ARPOS_INPUT_ERROR(folder.string() << ": no DICOM image files in this folder ("
                                      << files.size() << " files, " << volume.skipped_non_dicom_files
                                      << " not DICOM, " << other_objects << " DICOM non-image objects)");
  }
  for (const auto& h : headers) by_series[h.series_uid].push_back(&h);
  if (by_series.size() > 1) {
    std::ostringstream list;
    for (const auto& [uid, members] : by_series) {
      list << "\n  " << DescribeUid(uid) << ": " << members.size() << " files (e.g. "
           << members.front()->file.filename().string() << ", " << members.front()->modality
           << (members.front()->description.empty() ? "" : " '" + members.front()->description + "'")
           << ")";
    }
    ARPOS_INPUT_ERROR(folder.string() << ": folder mixes " << by_series.size()
                                      << " series (SeriesInstanceUID); put one CT series per folder:"
                                      << list.str());
  }
  const SliceHeader& first = headers.front();
  for (const auto& h : headers) {
    if (h.modality != "CT") {
      ARPOS_INPUT_ERROR(h.file.string() << ": modality '" << h.modality
                                        << "', expected CT (the body threshold is in Hounsfield units)");
    }
    if (h.frames != 1) {
      ARPOS_INPUT_ERROR(h.file.string() << ": multi-frame image (" << h.frames
                                        << " frames) is not supported; export single-frame CT slices");
    }
    if (h.samples_per_pixel > 1) {
      ARPOS_INPUT_ERROR(h.file.string() << ": colour image; a CT slice is grey");
    }
    if (h.rows <= 0 || h.columns <= 0) ARPOS_INPUT_ERROR(h.file.string() << ": missing Rows/Columns");
    if (h.rows != first.rows || h.columns != first.columns) {
      ARPOS_INPUT_ERROR(folder.string() << ": slices differ in size: " << first.file.filename().string()
                                        << " is " << first.columns << "x" << first.rows << ", "
                                        << h.file.filename().string() << " is " << h.columns << "x"
                                        << h.rows);
    }
    if (std::abs(h.row_spacing_mm - first.row_spacing_mm) > 1e-3 ||
        std::abs(h.col_spacing_mm - first.col_spacing_mm) > 1e-3) {
      ARPOS_INPUT_ERROR(folder.string() << ": slices differ in PixelSpacing ("
                                        << first.file.filename().string() << " vs "
                                        << h.file.filename().string() << ")");
    }
    if ((h.row_dir - first.row_dir).cwiseAbs().maxCoeff() > options.orientation_tolerance ||
        (h.col_dir - first.col_dir).cwiseAbs().maxCoeff() > options.orientation_tolerance) {
      ARPOS_INPUT_ERROR(folder.string() << ": slices differ in ImageOrientationPatient ("
                                        << first.file.filename().string() << " vs "
                                        << h.file.filename().string() << ")");
    }
  }
  if (std::abs(first.row_dir.norm() - 1) > 1e-3 || std::abs(first.col_dir.norm() - 1) > 1e-3 ||
      std::abs(first.row_dir.dot(first.col_dir)) > 1e-3) {
    ARPOS_INPUT_ERROR(first.file.string() << ": ImageOrientationPatient is not two orthonormal directions");
  }
  if (static_cast<int>(headers.size()) < options.min_slices) {
    ARPOS_INPUT_ERROR(folder.string() << ": too few slices (" << headers.size() << ") to make a surface; need at least "
                                      << options.min_slices << " slices of one CT series");
  }
  // Orthonormalise (Gram-Schmidt) so the frame is exactly rigid.
  const Eigen::Vector3d row = first.row_dir.normalized();
  const Eigen::Vector3d col = (first.col_dir - row * row.dot(first.col_dir)).normalized();
  const Eigen::Vector3d normal = row.cross(col);
  for (auto& h : headers) h.distance_mm = normal.dot(h.position_mm);
  // Sort by position along the normal: file names say nothing reliable.
  std::sort(headers.begin(), headers.end(),
            [](const SliceHeader& a, const SliceHeader& b) { return a.distance_mm < b.distance_mm; });
  std::vector<double> gaps;
  for (size_t k = 1; k < headers.size(); ++k) {
    const double gap = headers[k].distance_mm - headers[k - 1].distance_mm;
    if (gap < 1e-3) {
      ARPOS_INPUT_ERROR(folder.string() << ": two slices at the same position ("
                                        << headers[k - 1].file.filename().string() << " and "
                                        << headers[k].file.filename().string() << ", "
                                        << headers[k].distance_mm << " mm along the normal): duplicate slice or a second series");
    }
    gaps.push_back(gap);
  }
  std::vector<double> sorted_gaps = gaps;
  std::nth_element(sorted_gaps.begin(), sorted_gaps.begin() + sorted_gaps.size() / 2, sorted_gaps.end());
  const double spacing = sorted_gaps[sorted_gaps.size() / 2];
  for (size_t k = 0; k < gaps.size(); ++k) {
    if (std::abs(gaps[k] - spacing) > options.spacing_tolerance_mm) {
      ARPOS_INPUT_ERROR(folder.string() << ": inconsistent slice spacing: " << gaps[k] << " mm between "
                                        << headers[k].file.filename().string() << " and "
                                        << headers[k + 1].file.filename().string() << ", "
                                        << spacing << " mm elsewhere (missing slice?)");
    }
  }
  for (const auto& h : headers) {
    // Positions must lie on the line through the first one along the normal
    // (a gantry tilt or a stack of shifted slices would shear the volume).
    const Eigen::Vector3d offset = h.position_mm - headers.front().position_mm;
    if ((offset - normal * normal.dot(offset)).norm() > 0.1) {
      ARPOS_INPUT_ERROR(folder.string() << ": slice " << h.file.filename().string()
                                        << " is shifted sideways relative to the first slice (gantry tilt?); not supported");
    }
  }

  volume.geometry.size = {first.columns, first.rows, static_cast<int>(headers.size())};
  volume.geometry.spacing_mm = Eigen::Vector3d(first.col_spacing_mm, first.row_spacing_mm, spacing);
  volume.geometry.patient_from_index_rotation.col(0) = row;
  volume.geometry.patient_from_index_rotation.col(1) = col;
  volume.geometry.patient_from_index_rotation.col(2) = normal;
  volume.geometry.origin_mm = headers.front().position_mm;
  volume.series_instance_uid = first.series_uid;
  volume.frame_of_reference_uid = first.frame_of_reference_uid;
  volume.series_description = first.description;
  volume.hu.resize(volume.geometry.num_voxels());
  const size_t slice_size = static_cast<size_t>(first.columns) * first.rows;
  for (size_t k = 0; k < headers.size(); ++k) {
    ReadSlicePixels(headers[k], volume.hu.data() + k * slice_size);
    volume.files.push_back(headers[k].file);
  }
  return volume;
}

RtStructureSet ReadRtStruct(const fs::path& file) {
  gdcm::Reader reader;
  ReadWholeFile(file, &reader, "RTSTRUCT");
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  std::vector<gdcm::SmartPointer<gdcm::SequenceOfItems>> keep;
  RtStructureSet result;
  result.label = GetString(ds, 0x3006, 0x0002);
  for (const gdcm::DataSet* item : GetItems(ds, 0x3006, 0x0010, &keep)) {
    result.frame_of_reference_uid = GetString(*item, 0x0020, 0x0052);
    if (!result.frame_of_reference_uid.empty()) break;
  }
  std::map<int, size_t> index_of_number;
  for (const gdcm::DataSet* item : GetItems(ds, 0x3006, 0x0020, &keep)) {
    RtRoi roi;
    long long number = 0;
    if (!ParseInt(GetString(*item, 0x3006, 0x0022), &number)) {
      ARPOS_INPUT_ERROR(file.string() << ": StructureSetROISequence item without a valid ROINumber");
    }
    roi.number = static_cast<int>(number);
    roi.name = GetString(*item, 0x3006, 0x0026);
    if (result.frame_of_reference_uid.empty()) {
      result.frame_of_reference_uid = GetString(*item, 0x3006, 0x0024);
    }
    index_of_number[roi.number] = result.rois.size();
    result.rois.push_back(std::move(roi));
  }
  for (const gdcm::DataSet* item : GetItems(ds, 0x3006, 0x0080, &keep)) {
    long long number = 0;
    if (!ParseInt(GetString(*item, 0x3006, 0x0084), &number)) continue;
    const auto it = index_of_number.find(static_cast<int>(number));
    if (it != index_of_number.end()) {
      result.rois[it->second].interpreted_type = GetString(*item, 0x3006, 0x00a4);
    }
  }
  for (const gdcm::DataSet* item : GetItems(ds, 0x3006, 0x0039, &keep)) {
    long long number = 0;
    if (!ParseInt(GetString(*item, 0x3006, 0x0084), &number)) {
      ARPOS_INPUT_ERROR(file.string() << ": ROIContourSequence item without a valid ReferencedROINumber");
    }
    const auto it = index_of_number.find(static_cast<int>(number));
    if (it == index_of_number.end()) continue;  // contours of an undeclared ROI: not selectable
    RtRoi& roi = result.rois[it->second];
    for (const gdcm::DataSet* contour_item : GetItems(*item, 0x3006, 0x0040, &keep)) {
      RtContour contour;
      contour.geometric_type = GetString(*contour_item, 0x3006, 0x0042);
      std::vector<double> data;
      if (!ParseDecimalStrings(GetString(*contour_item, 0x3006, 0x0050), &data)) {
        ARPOS_INPUT_ERROR(file.string() << ": ROI '" << roi.name << "': ContourData is not a list of numbers");
      }
      if (data.size() % 3 != 0) {
        ARPOS_INPUT_ERROR(file.string() << ": ROI '" << roi.name << "': ContourData has " << data.size()
                                        << " numbers, not a multiple of 3");
      }
      long long declared = 0;
      const std::string declared_text = GetString(*contour_item, 0x3006, 0x0046);
      if (!declared_text.empty() && ParseInt(declared_text, &declared) &&
          static_cast<size_t>(declared) != data.size() / 3) {
        ARPOS_INPUT_ERROR(file.string() << ": ROI '" << roi.name << "': NumberOfContourPoints " << declared
                                        << " but ContourData holds " << data.size() / 3 << " points");
      }
      for (size_t n = 0; n + 2 < data.size(); n += 3) {
        contour.points_mm.emplace_back(data[n], data[n + 1], data[n + 2]);
      }
      roi.contours.push_back(std::move(contour));
    }
  }
  return result;
}

RtPlanIsocentre ReadRtPlanIsocentre(const fs::path& file) {
  gdcm::Reader reader;
  ReadWholeFile(file, &reader, "RTPLAN");
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  std::vector<gdcm::SmartPointer<gdcm::SequenceOfItems>> keep;
  RtPlanIsocentre result;
  result.frame_of_reference_uid = GetString(ds, 0x0020, 0x0052);
  result.plan_label = GetString(ds, 0x300a, 0x0002);
  std::vector<const gdcm::DataSet*> beams = GetItems(ds, 0x300a, 0x00b0, &keep);
  bool ion = false;
  if (beams.empty()) {
    beams = GetItems(ds, 0x300a, 0x03a2, &keep);
    ion = true;
  }
  std::vector<Eigen::Vector3d> isocentres;
  for (const gdcm::DataSet* beam : beams) {
    const auto points = GetItems(*beam, 0x300a, ion ? 0x03a8 : 0x0111, &keep);
    if (points.empty()) continue;
    const std::vector<double> iso = GetDecimals(*points.front(), 0x300a, 0x012c, file, "IsocenterPosition");
    if (iso.size() != 3) continue;
    isocentres.emplace_back(iso[0], iso[1], iso[2]);
  }
  result.num_beams = static_cast<int>(beams.size());
  if (isocentres.empty()) {
    ARPOS_INPUT_ERROR(file.string() << ": RTPLAN has no IsocenterPosition in its beams' first control points");
  }
  for (const auto& iso : isocentres) {
    if ((iso - isocentres.front()).norm() > 0.01) {
      ARPOS_INPUT_ERROR(file.string() << ": RTPLAN beams have different isocentres ("
                                      << isocentres.front().transpose() << " and " << iso.transpose()
                                      << " mm); the model origin would be ambiguous");
    }
  }
  result.isocentre_mm = isocentres.front();
  return result;
}

}  // namespace arpos
