#include "geometry/mesh_file_check.h"

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace fs = std::filesystem;

size_t TextMeshStart(const std::string& data) {
  static const std::string kBom = "\xEF\xBB\xBF";
  if (data.compare(0, kBom.size(), kBom) != 0) return 0;
  // Only before a text format's keyword: a binary STL's 80-byte header is
  // free text and may begin with anything.
  for (const char* keyword :
       {"ply", "OFF", "COFF", "NOFF", "solid", "v ", "#", "o ", "g ", "mtllib", "\n", "\r\n"}) {
    if (data.compare(kBom.size(), std::strlen(keyword), keyword) == 0) return kBom.size();
  }
  return 0;
}

namespace {

std::string ReadAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) ARPOS_INPUT_ERROR(path.string() << ": cannot open mesh file");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  std::string data = buffer.str();
  const size_t text = TextMeshStart(data);
  if (text > 0) data.erase(0, text);
  return data;
}

// ---------------------------------------------------------------- PLY

enum class PlyFormat { kAscii, kBinaryLittle, kBinaryBig };

struct PlyProperty {
  bool is_list = false;
  int count_size = 0;  // bytes of the list count type
  bool count_signed = false;
  int value_size = 0;  // bytes of the (element) value type
  bool value_float = false;
  bool value_signed = false;
  std::string name;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

// Size, float-ness and signedness of a PLY scalar type; false if unknown.
bool PlyType(const std::string& type, int* size, bool* is_float, bool* is_signed) {
  struct Type {
    const char* name;
    int size;
    bool is_float, is_signed;
  };
  static const Type kTypes[] = {
      {"char", 1, false, true},     {"int8", 1, false, true},     {"uchar", 1, false, false},
      {"uint8", 1, false, false},   {"short", 2, false, true},    {"int16", 2, false, true},
      {"ushort", 2, false, false},  {"uint16", 2, false, false},  {"int", 4, false, true},
      {"int32", 4, false, true},    {"uint", 4, false, false},    {"uint32", 4, false, false},
      {"float", 4, true, true},     {"float32", 4, true, true},   {"double", 8, true, true},
      {"float64", 8, true, true}};
  for (const auto& t : kTypes) {
    if (type == t.name) {
      *size = t.size;
      *is_float = t.is_float;
      *is_signed = t.is_signed;
      return true;
    }
  }
  return false;
}

// Reads an integer of `size` bytes from binary PLY data.
int64_t ReadBinaryInt(const char* p, int size, bool is_signed, bool big_endian) {
  uint64_t raw = 0;
  for (int b = 0; b < size; ++b) {
    const uint8_t byte = static_cast<uint8_t>(p[big_endian ? b : size - 1 - b]);
    raw = (raw << 8) | byte;
  }
  if (is_signed && size < 8 && (raw >> (8 * size - 1)) & 1u) {
    raw |= ~uint64_t{0} << (8 * size);  // sign-extend
  }
  return static_cast<int64_t>(raw);
}

// Reads a float (4 bytes) or double (8 bytes) from binary PLY data.
double ReadBinaryFloat(const char* p, int size, bool big_endian) {
  const uint64_t raw = static_cast<uint64_t>(ReadBinaryInt(p, size, false, big_endian));
  if (size == 4) {
    const uint32_t bits = static_cast<uint32_t>(raw);
    float value;
    std::memcpy(&value, &bits, 4);
    return value;
  }
  double value;
  std::memcpy(&value, &raw, 8);
  return value;
}

void CheckPly(const fs::path& path, const std::string& data, PlyContents* out) {
  const std::string name = path.string();
  const size_t header_end = data.find("end_header");
  if (data.compare(0, 3, "ply") != 0 || header_end == std::string::npos) {
    ARPOS_INPUT_ERROR(name << ": not a PLY file (no 'ply' magic or no end_header)");
  }
  size_t body = data.find('\n', header_end);
  if (body == std::string::npos) ARPOS_INPUT_ERROR(name << ": PLY header not terminated");
  ++body;
  std::istringstream header(data.substr(0, header_end));
  std::string line;
  std::getline(header, line);  // "ply"
  PlyFormat format = PlyFormat::kAscii;
  bool have_format = false;
  std::vector<PlyElement> elements;
  const uint64_t file_size = data.size();
  while (std::getline(header, line)) {
    const std::vector<std::string> t = SplitWhitespace(line);
    if (t.empty() || t[0] == "comment" || t[0] == "obj_info") continue;
    if (t[0] == "format" && t.size() >= 2) {
      have_format = true;
      if (t[1] == "ascii") {
        format = PlyFormat::kAscii;
      } else if (t[1] == "binary_little_endian") {
        format = PlyFormat::kBinaryLittle;
      } else if (t[1] == "binary_big_endian") {
        format = PlyFormat::kBinaryBig;
      } else {
        ARPOS_INPUT_ERROR(name << ": unknown PLY format '" << t[1] << "'");
      }
    } else if (t[0] == "element" && t.size() == 3) {
      long long count = 0;
      if (!ParseInt(t[2], &count) || count < 0 || static_cast<uint64_t>(count) > file_size) {
        ARPOS_INPUT_ERROR(name << ": PLY element '" << t[1] << "' has an impossible count '" << t[2]
                               << "' for a file of " << file_size << " bytes");
      }
      elements.push_back({t[1], static_cast<uint64_t>(count), {}});
    } else if (t[0] == "property" && !elements.empty()) {
      PlyProperty p;
      bool ok = false;
      if (t.size() == 5 && t[1] == "list") {
        p.is_list = true;
        bool count_float = false;
        ok = PlyType(t[2], &p.count_size, &count_float, &p.count_signed) && !count_float &&
             PlyType(t[3], &p.value_size, &p.value_float, &p.value_signed);
        p.name = t[4];
      } else if (t.size() == 3) {
        ok = PlyType(t[1], &p.value_size, &p.value_float, &p.value_signed);
        p.name = t[2];
      }
      if (!ok) ARPOS_INPUT_ERROR(name << ": malformed PLY property line '" << Trim(line) << "'");
      elements.back().properties.push_back(p);
    } else {
      ARPOS_INPUT_ERROR(name << ": malformed PLY header line '" << Trim(line) << "'");
    }
  }
  if (!have_format) ARPOS_INPUT_ERROR(name << ": PLY header has no format line");
  uint64_t num_vertices = 0;
  for (const auto& e : elements) {
    if (e.name == "vertex") num_vertices = e.count;
  }

  const bool binary = format != PlyFormat::kAscii;
  const bool big = format == PlyFormat::kBinaryBig;
  size_t pos = body;
  // ASCII: next whitespace-separated token, or empty at the end of the data.
  auto next_token = [&]() -> std::string {
    while (pos < data.size() && std::isspace(static_cast<unsigned char>(data[pos]))) ++pos;
    const size_t start = pos;
    while (pos < data.size() && !std::isspace(static_cast<unsigned char>(data[pos]))) ++pos;
    return data.substr(start, pos - start);
  };
  for (const auto& e : elements) {
    const bool is_face = e.name == "face";
    const bool is_vertex = e.name == "vertex";
    // What is kept when reading: a vertex's x y z nx ny nz (slots 0-5), a
    // face's index list ('vertex_indices', 'vertex_index', else the first
    // integer list).
    std::vector<int> slot(e.properties.size(), -1);
    bool normals = false;
    int face_list = -1;
    if (out != nullptr && is_vertex) {
      static const char* const kNames[] = {"x", "y", "z", "nx", "ny", "nz"};
      int found = 0;
      for (size_t k = 0; k < e.properties.size(); ++k) {
        for (int j = 0; j < 6; ++j) {
          if (!e.properties[k].is_list && e.properties[k].name == kNames[j])
            slot[k] = j, found |= 1 << j;
        }
      }
      if ((found & 7) != 7) ARPOS_INPUT_ERROR(name << ": PLY vertices lack x, y or z");
      normals = (found & 56) == 56;
      out->positions.reserve(e.count);
      if (normals) out->normals.reserve(e.count);
    }
    if (out != nullptr && is_face) {
      for (size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& p = e.properties[k];
        if (!p.is_list || p.value_float) continue;
        if (p.name == "vertex_indices" || p.name == "vertex_index") {
          face_list = static_cast<int>(k);
          break;
        }
        if (face_list < 0) face_list = static_cast<int>(k);
      }
      out->face_sizes.reserve(e.count);
      out->face_indices.reserve(3 * e.count);
    }
    double vertex[6] = {0, 0, 0, 0, 0, 0};
    for (uint64_t n = 0; n < e.count; ++n) {
      uint32_t face_size = 0;
      for (size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& p = e.properties[k];
        const bool keep_index = static_cast<int>(k) == face_list;
        auto truncated = [&]() {
          ARPOS_INPUT_ERROR(name << ": PLY data ends early (truncated file?): header declares " << e.count
                                 << " " << e.name << " elements, the data stops in number " << n);
        };
        auto bad_number = [&](const std::string& token) {
          ARPOS_INPUT_ERROR(name << ": PLY " << e.name << " " << n << ": '" << token
                                 << "' is not a finite number");
        };
        auto not_finite = [&](double value) {
          const bool coordinate = p.name == "x" || p.name == "y" || p.name == "z";
          ARPOS_INPUT_ERROR(name << ": PLY " << e.name << " " << n << " has " << p.name << " = " << value << ": "
                                 << (coordinate ? "coordinates must be finite numbers" : "must be a finite number"));
        };
        uint64_t items = 1;
        if (p.is_list) {
          int64_t count = 0;
          if (binary) {
            if (pos + p.count_size > data.size()) truncated();
            count = ReadBinaryInt(data.data() + pos, p.count_size, p.count_signed, big);
            pos += p.count_size;
          } else {
            const std::string token = next_token();
            if (token.empty()) truncated();
            long long value = 0;
            if (!ParseInt(token, &value)) bad_number(token);
            count = value;
          }
          if (count < 0 || static_cast<uint64_t>(count) > data.size()) {
            ARPOS_INPUT_ERROR(name << ": PLY " << e.name << " " << n << " has an impossible list length " << count);
          }
          items = static_cast<uint64_t>(count);
        }
        const bool indices = is_face && p.is_list && !p.value_float;
        for (uint64_t i = 0; i < items; ++i) {
          int64_t index = 0;
          double value = 0;
          if (binary) {
            if (pos + p.value_size > data.size()) truncated();
            if (p.value_float) {
              value = ReadBinaryFloat(data.data() + pos, p.value_size, big);
              if (!std::isfinite(value)) not_finite(value);
            } else {
              index = ReadBinaryInt(data.data() + pos, p.value_size, p.value_signed, big);
              value = static_cast<double>(index);
            }
            pos += p.value_size;
          } else {
            const std::string token = next_token();
            if (token.empty()) truncated();
            if (!ParseDouble(token, &value)) bad_number(token);
            index = static_cast<int64_t>(value);
          }
          if (indices && (index < 0 || static_cast<uint64_t>(index) >= num_vertices)) {
            ARPOS_INPUT_ERROR(name << ": PLY face " << n << " refers to vertex " << index << " of "
                                   << num_vertices);
          }
          if (slot[k] >= 0) vertex[slot[k]] = value;
          if (keep_index) out->face_indices.push_back(index), ++face_size;  // only when reading
        }
      }
      if (out != nullptr && is_vertex) {
        out->positions.emplace_back(vertex[0], vertex[1], vertex[2]);
        if (normals) out->normals.emplace_back(vertex[3], vertex[4], vertex[5]);
      }
      if (out != nullptr && is_face) out->face_sizes.push_back(face_size);
    }
  }
}

// ---------------------------------------------------------------- OFF

void CheckOff(const fs::path& path, const std::string& data) {
  const std::string name = path.string();
  std::istringstream in(data);
  std::string line;
  // Lines without comments; blank lines skipped.
  auto next_line = [&](std::vector<std::string>* tokens) {
    while (std::getline(in, line)) {
      const size_t hash = line.find('#');
      if (hash != std::string::npos) line.resize(hash);
      *tokens = SplitWhitespace(line);
      if (!tokens->empty()) return true;
    }
    return false;
  };
  std::vector<std::string> t;
  if (!next_line(&t) || !EndsWith(t[0], "OFF")) ARPOS_INPUT_ERROR(name << ": not an OFF file (no OFF keyword)");
  if (t[0] != "OFF") return;  // COFF, NOFF, STOFF...: extra per-vertex data; left to assimp
  if (t.size() > 1 && t[1] == "BINARY") ARPOS_INPUT_ERROR(name << ": binary OFF is not supported");
  std::vector<std::string> counts(t.begin() + 1, t.end());
  if (counts.empty() && !next_line(&counts)) ARPOS_INPUT_ERROR(name << ": OFF file has no counts line");
  long long nv = 0, nf = 0;
  if (counts.size() < 2 || !ParseInt(counts[0], &nv) || !ParseInt(counts[1], &nf) || nv < 0 || nf < 0 ||
      static_cast<uint64_t>(nv) > data.size() || static_cast<uint64_t>(nf) > data.size()) {
    ARPOS_INPUT_ERROR(name << ": OFF counts line is not 'vertices faces edges' with possible counts");
  }
  for (long long v = 0; v < nv; ++v) {
    if (!next_line(&t)) {
      ARPOS_INPUT_ERROR(name << ": OFF data ends early (truncated file?): " << nv << " vertices declared, "
                             << v << " found");
    }
    double value = 0;
    if (t.size() < 3 || !ParseDouble(t[0], &value) || !ParseDouble(t[1], &value) || !ParseDouble(t[2], &value)) {
      ARPOS_INPUT_ERROR(name << ": OFF vertex " << v << " is not three numbers");
    }
  }
  for (long long f = 0; f < nf; ++f) {
    if (!next_line(&t)) {
      ARPOS_INPUT_ERROR(name << ": OFF data ends early (truncated file?): " << nf << " faces declared, " << f
                             << " found");
    }
    long long n = 0;
    if (!ParseInt(t[0], &n) || n < 1 || static_cast<size_t>(n) + 1 > t.size()) {
      ARPOS_INPUT_ERROR(name << ": OFF face " << f << " is malformed");
    }
    for (long long i = 1; i <= n; ++i) {
      long long index = 0;
      if (!ParseInt(t[static_cast<size_t>(i)], &index) || index < 0 || index >= nv) {
        ARPOS_INPUT_ERROR(name << ": OFF face " << f << " refers to vertex '" << t[static_cast<size_t>(i)]
                               << "' of " << nv);
      }
    }
  }
}

// ---------------------------------------------------------------- STL

void CheckStl(const fs::path& path, const std::string& data) {
  // ASCII STL starts with "solid" (some binary files do too: decide by size).
  if (data.size() >= 84) {
    const uint32_t count = static_cast<uint32_t>(ReadBinaryInt(data.data() + 80, 4, false, false));
    if (data.size() == 84 + 50ull * count) return;  // consistent binary STL
    if (data.compare(0, 5, "solid") == 0) return;    // ASCII: assimp checks it
    ARPOS_INPUT_ERROR(path.string() << ": binary STL declares " << count << " triangles ("
                                    << 84 + 50ull * count << " bytes) but has " << data.size()
                                    << " bytes (truncated file?)");
  }
  if (data.compare(0, 5, "solid") != 0) {
    ARPOS_INPUT_ERROR(path.string() << ": STL file too short (" << data.size() << " bytes)");
  }
}

}  // namespace

void CheckMeshFileStructure(const fs::path& path) {
  const std::string extension = ToLower(path.extension().string());
  if (extension != ".ply" && extension != ".off" && extension != ".stl") return;
  const std::string data = ReadAll(path);
  if (data.empty()) ARPOS_INPUT_ERROR(path.string() << ": mesh file is empty");
  if (extension == ".ply") CheckPly(path, data, nullptr);
  if (extension == ".off") CheckOff(path, data);
  if (extension == ".stl") CheckStl(path, data);
}

PlyContents ReadPlyFile(const fs::path& path) {
  const std::string data = ReadAll(path);
  if (data.empty()) ARPOS_INPUT_ERROR(path.string() << ": mesh file is empty");
  PlyContents out;
  CheckPly(path, data, &out);
  return out;
}

}  // namespace arpos
