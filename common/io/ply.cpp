// SPDX-License-Identifier: Apache-2.0
#include "common/io/ply.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "common/io/text_file.hpp"

namespace plumb::io {
namespace {

enum class BodyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

enum class ScalarType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

std::optional<ScalarType> parseScalarType(const std::string& name) {
    if (name == "char" || name == "int8") return ScalarType::kInt8;
    if (name == "uchar" || name == "uint8") return ScalarType::kUint8;
    if (name == "short" || name == "int16") return ScalarType::kInt16;
    if (name == "ushort" || name == "uint16") return ScalarType::kUint16;
    if (name == "int" || name == "int32") return ScalarType::kInt32;
    if (name == "uint" || name == "uint32") return ScalarType::kUint32;
    if (name == "float" || name == "float32") return ScalarType::kFloat32;
    if (name == "double" || name == "float64") return ScalarType::kFloat64;
    return std::nullopt;
}

size_t sizeOf(ScalarType t) {
    switch (t) {
        case ScalarType::kInt8:
        case ScalarType::kUint8:
            return 1;
        case ScalarType::kInt16:
        case ScalarType::kUint16:
            return 2;
        case ScalarType::kInt32:
        case ScalarType::kUint32:
        case ScalarType::kFloat32:
            return 4;
        case ScalarType::kFloat64:
            return 8;
    }
    return 0;
}

bool isInteger(ScalarType t) { return t != ScalarType::kFloat32 && t != ScalarType::kFloat64; }

struct Property {
    std::string name;
    ScalarType type = ScalarType::kFloat32;  ///< scalar type, or item type of a list
    bool is_list = false;
    ScalarType count_type = ScalarType::kUint8;
};

struct Element {
    std::string name;
    size_t count = 0;
    std::vector<Property> properties;

    /// Smallest number of bytes one binary element can take (lists may be empty).
    size_t minBinarySize() const {
        size_t s = 0;
        for (const Property& p : properties) s += sizeOf(p.is_list ? p.count_type : p.type);
        return s;
    }
    int find(const std::string& property) const {
        for (size_t i = 0; i < properties.size(); ++i) {
            if (properties[i].name == property) return static_cast<int>(i);
        }
        return -1;
    }
};

struct Header {
    BodyFormat format = BodyFormat::kAscii;
    std::vector<Element> elements;
    size_t body_offset = 0;  ///< bytes from the start of the file
    size_t body_line = 0;    ///< 1-based line number where the body starts (ascii)
};

std::vector<std::string> splitWords(const std::string& line) {
    std::vector<std::string> words;
    std::istringstream in(line);
    std::string w;
    while (in >> w) words.push_back(w);
    return words;
}

Result<Header> parseHeader(const std::string& data, const std::string& name) {
    Header header;
    size_t pos = 0;
    size_t line_no = 0;
    bool have_format = false;
    auto nextLine = [&](std::string* line) {
        if (pos >= data.size()) return false;
        const size_t eol = data.find('\n', pos);
        const size_t end = eol == std::string::npos ? data.size() : eol;
        *line = data.substr(pos, end - pos);
        if (!line->empty() && line->back() == '\r') line->pop_back();
        pos = eol == std::string::npos ? data.size() : eol + 1;
        ++line_no;
        return true;
    };
    std::string line;
    if (!nextLine(&line) || line != "ply") {
        return corrupt(fmt::format("{}: not a PLY file (first line is not 'ply')", name));
    }
    while (true) {
        if (!nextLine(&line)) {
            return corrupt(fmt::format("{}: header ends before 'end_header'", name));
        }
        const std::vector<std::string> w = splitWords(line);
        if (w.empty()) continue;
        const std::string where = fmt::format("{}:{}", name, line_no);
        if (w[0] == "end_header") break;
        if (w[0] == "comment" || w[0] == "obj_info") continue;
        if (w[0] == "format") {
            if (w.size() != 3) return corrupt(fmt::format("{}: malformed format line", where));
            if (w[1] == "ascii") {
                header.format = BodyFormat::kAscii;
            } else if (w[1] == "binary_little_endian") {
                header.format = BodyFormat::kBinaryLittleEndian;
            } else if (w[1] == "binary_big_endian") {
                header.format = BodyFormat::kBinaryBigEndian;
            } else {
                return unsupported(fmt::format("{}: unknown PLY format '{}'", where, w[1]));
            }
            if (w[2] != "1.0") {
                return unsupported(fmt::format("{}: unsupported PLY version '{}'", where, w[2]));
            }
            have_format = true;
        } else if (w[0] == "element") {
            if (w.size() != 3) return corrupt(fmt::format("{}: malformed element line", where));
            Element e;
            e.name = w[1];
            unsigned long long count = 0;
            const auto [ptr, ec] = std::from_chars(w[2].data(), w[2].data() + w[2].size(), count);
            if (ec != std::errc() || ptr != w[2].data() + w[2].size()) {
                return corrupt(fmt::format("{}: element count '{}' is not a non-negative integer",
                                           where, w[2]));
            }
            e.count = static_cast<size_t>(count);
            header.elements.push_back(e);
        } else if (w[0] == "property") {
            if (header.elements.empty()) {
                return corrupt(fmt::format("{}: property before any element", where));
            }
            Property p;
            if (w.size() >= 2 && w[1] == "list") {
                if (w.size() != 5)
                    return corrupt(fmt::format("{}: malformed list property", where));
                const auto count_type = parseScalarType(w[2]);
                const auto item_type = parseScalarType(w[3]);
                if (!count_type || !item_type) {
                    return unsupported(fmt::format("{}: unknown property type '{}'", where,
                                                   count_type ? w[3] : w[2]));
                }
                if (!isInteger(*count_type)) {
                    return corrupt(fmt::format("{}: list count type '{}' is not an integer type",
                                               where, w[2]));
                }
                p.is_list = true;
                p.count_type = *count_type;
                p.type = *item_type;
                p.name = w[4];
            } else {
                if (w.size() != 3) return corrupt(fmt::format("{}: malformed property", where));
                const auto type = parseScalarType(w[1]);
                if (!type) {
                    return unsupported(fmt::format("{}: unknown property type '{}'", where, w[1]));
                }
                p.type = *type;
                p.name = w[2];
            }
            header.elements.back().properties.push_back(p);
        } else {
            return corrupt(fmt::format("{}: unknown header keyword '{}'", where, w[0]));
        }
    }
    if (!have_format) return corrupt(fmt::format("{}: header has no 'format' line", name));
    header.body_offset = pos;
    header.body_line = line_no + 1;
    return header;
}

/// Sequential reader of the values of a PLY body in any of the three encodings.
class BodyCursor {
  public:
    BodyCursor(const std::string& data, const Header& header)
        : p_(data.data() + header.body_offset),
          end_(data.data() + data.size()),
          format_(header.format),
          line_(header.body_line) {}

    enum class Outcome { kOk, kEnd, kBadToken };

    /// Reads one value of type t into *value.
    Outcome read(ScalarType t, double* value) {
        if (format_ == BodyFormat::kAscii) return readAscii(value);
        const size_t n = sizeOf(t);
        if (static_cast<size_t>(end_ - p_) < n) return Outcome::kEnd;
        // The value's bytes in native order (every PLY scalar is at most 8 bytes).
        unsigned char bytes[8] = {};
        const bool file_little = format_ == BodyFormat::kBinaryLittleEndian;
        const bool swap = file_little != (std::endian::native == std::endian::little);
        for (size_t i = 0; i < n && i < sizeof bytes; ++i) {
            bytes[i] = static_cast<unsigned char>(p_[swap ? n - 1 - i : i]);
        }
        p_ += n;
        *value = decode(t, bytes);
        return Outcome::kOk;
    }

    size_t bytesLeft() const { return static_cast<size_t>(end_ - p_); }
    size_t line() const { return line_; }
    const std::string& badToken() const { return bad_token_; }

  private:
    static double decode(ScalarType t, const unsigned char* b) {
        switch (t) {
            case ScalarType::kInt8:
                return static_cast<double>(load<int8_t>(b));
            case ScalarType::kUint8:
                return static_cast<double>(load<uint8_t>(b));
            case ScalarType::kInt16:
                return static_cast<double>(load<int16_t>(b));
            case ScalarType::kUint16:
                return static_cast<double>(load<uint16_t>(b));
            case ScalarType::kInt32:
                return static_cast<double>(load<int32_t>(b));
            case ScalarType::kUint32:
                return static_cast<double>(load<uint32_t>(b));
            case ScalarType::kFloat32:
                return static_cast<double>(load<float>(b));
            case ScalarType::kFloat64:
                return load<double>(b);
        }
        return 0.0;
    }

    template <typename T>
    static T load(const unsigned char* b) {
        T v;
        std::memcpy(&v, b, sizeof(T));
        return v;
    }

    Outcome readAscii(double* value) {
        while (p_ < end_ && (*p_ == ' ' || *p_ == '\t' || *p_ == '\n' || *p_ == '\r')) {
            if (*p_ == '\n') ++line_;
            ++p_;
        }
        if (p_ == end_) return Outcome::kEnd;
        const char* start = p_;
        while (p_ < end_ && !(*p_ == ' ' || *p_ == '\t' || *p_ == '\n' || *p_ == '\r')) ++p_;
        const char* first = start;
        if (*first == '+') ++first;
        const auto [ptr, ec] = std::from_chars(first, p_, *value);
        if (ec != std::errc() || ptr != p_) {
            bad_token_.assign(start, std::min<size_t>(static_cast<size_t>(p_ - start), 40));
            return Outcome::kBadToken;
        }
        return Outcome::kOk;
    }

    const char* p_;
    const char* end_;
    BodyFormat format_;
    size_t line_;
    std::string bad_token_;
};

Result<std::string> slurp(const std::filesystem::path& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) {
        return notFound(fmt::format("{}: no such file", path.string()));
    }
    if (!std::filesystem::is_regular_file(path, ec)) {
        return invalidArgument(fmt::format("{}: not a regular file", path.string()));
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) return ioError(fmt::format("{}: cannot open for reading", path.string()));
    std::string data;
    in.seekg(0, std::ios::end);
    const std::streamoff size = in.tellg();
    in.seekg(0, std::ios::beg);
    if (size < 0) return ioError(fmt::format("{}: cannot determine the file size", path.string()));
    data.resize(static_cast<size_t>(size));
    in.read(data.data(), size);
    if (in.gcount() != size) return ioError(fmt::format("{}: read failed", path.string()));
    return data;
}

uint8_t toColorChannel(double v, ScalarType t) {
    if (!std::isfinite(v)) return 0;
    if (!isInteger(t)) v = v * 255.0;
    return static_cast<uint8_t>(std::clamp(std::round(v), 0.0, 255.0));
}

/// Where the vertex element keeps its coordinates, normals and colours (property indices).
struct VertexLayout {
    const Element* element = nullptr;
    int ix = -1, iy = -1, iz = -1;
    int inx = -1, iny = -1, inz = -1;
    int ir = -1, ig = -1, ib = -1;
    bool has_normals = false;
    bool has_colors = false;
};

/// Finds the vertex element and its properties; corrupt or unsupported without x, y, z.
Result<VertexLayout> vertexLayout(const Header& header, const std::string& name) {
    VertexLayout layout;
    for (const Element& e : header.elements) {
        if (e.name == "vertex") layout.element = &e;
    }
    const Element* vertex = layout.element;
    if (vertex == nullptr) return corrupt(fmt::format("{}: no 'vertex' element", name));
    if (vertex->count > static_cast<size_t>(INT32_MAX)) {
        return unsupported(
            fmt::format("{}: {} vertices is more than supported", name, vertex->count));
    }
    layout.ix = vertex->find("x");
    layout.iy = vertex->find("y");
    layout.iz = vertex->find("z");
    if (layout.ix < 0 || layout.iy < 0 || layout.iz < 0) {
        return unsupported(fmt::format("{}: vertex element lacks x, y or z", name));
    }
    for (int i : {layout.ix, layout.iy, layout.iz}) {
        if (vertex->properties[static_cast<size_t>(i)].is_list) {
            return corrupt(fmt::format("{}: vertex coordinate '{}' is a list", name,
                                       vertex->properties[static_cast<size_t>(i)].name));
        }
    }
    auto scalarIndex = [&](const char* prop) {
        const int i = vertex->find(prop);
        return (i >= 0 && !vertex->properties[static_cast<size_t>(i)].is_list) ? i : -1;
    };
    layout.inx = scalarIndex("nx");
    layout.iny = scalarIndex("ny");
    layout.inz = scalarIndex("nz");
    layout.ir = scalarIndex("red");
    layout.ig = scalarIndex("green");
    layout.ib = scalarIndex("blue");
    layout.has_normals = layout.inx >= 0 && layout.iny >= 0 && layout.inz >= 0;
    layout.has_colors = layout.ir >= 0 && layout.ig >= 0 && layout.ib >= 0;
    return layout;
}

/// The index of a face element's vertex index list ('vertex_indices' or 'vertex_index', an
/// integer list); corrupt without one.
Result<int> faceListIndex(const Element& e, const std::string& name) {
    int face_list = e.find("vertex_indices");
    if (face_list < 0) face_list = e.find("vertex_index");
    if (face_list < 0 || !e.properties[static_cast<size_t>(face_list)].is_list) {
        return corrupt(
            fmt::format("{}: face element has no 'vertex_indices' or 'vertex_index' list", name));
    }
    if (!isInteger(e.properties[static_cast<size_t>(face_list)].type)) {
        return corrupt(fmt::format("{}: face vertex indices are not an integer type", name));
    }
    return face_list;
}

/// Refuses element counts that cannot fit in the bytes left of a binary body, before anything
/// is allocated for them.
Status checkElementFits(const Element& e, const Header& header, const BodyCursor& cursor,
                        const std::string& name) {
    if (header.format == BodyFormat::kAscii || e.minBinarySize() == 0 ||
        e.count <= cursor.bytesLeft() / e.minBinarySize()) {
        return Status::ok();
    }
    const bool fixed_size = std::none_of(e.properties.begin(), e.properties.end(),
                                         [](const Property& p) { return p.is_list; });
    if (fixed_size) {
        return corrupt(fmt::format("{}: truncated: expected {} {} elements, read {}", name, e.count,
                                   e.name, cursor.bytesLeft() / e.minBinarySize()));
    }
    return corrupt(fmt::format(
        "{}: truncated: expected {} {} elements of at least {} bytes, only {} bytes left", name,
        e.count, e.name, e.minBinarySize(), cursor.bytesLeft()));
}

/// Adds vertex k from its property values (coordinates and normals must be finite).
Status addVertex(const VertexLayout& layout, const std::vector<double>& values, size_t k,
                 const std::string& name, TriangleMesh* mesh) {
    const Eigen::Vector3d x(values[layout.ix], values[layout.iy], values[layout.iz]);
    if (!x.allFinite()) {
        return corrupt(fmt::format("{}: vertex {} has a non-finite coordinate", name, k));
    }
    mesh->vertices.push_back(x.cast<float>());
    if (layout.has_normals) {
        const Eigen::Vector3d n(values[layout.inx], values[layout.iny], values[layout.inz]);
        if (!n.allFinite()) {
            return corrupt(fmt::format("{}: vertex {} has a non-finite normal", name, k));
        }
        mesh->normals.push_back(n.cast<float>());
    }
    if (layout.has_colors) {
        const std::vector<Property>& props = layout.element->properties;
        mesh->colors.emplace_back(toColorChannel(values[layout.ir], props[layout.ir].type),
                                  toColorChannel(values[layout.ig], props[layout.ig].type),
                                  toColorChannel(values[layout.ib], props[layout.ib].type));
    }
    return Status::ok();
}

/// Checks face k (at least 3 vertices, each index below the vertex count of the header: the
/// vertex element may come after the faces) and, with keep_faces, adds its fan triangulation
/// (v0, v_j, v_j+1): a quad gives two triangles.
Status addFace(const std::vector<double>& polygon, size_t k, size_t num_vertices, bool keep_faces,
               const std::string& name, TriangleMesh* mesh) {
    if (polygon.size() < 3) {
        return corrupt(fmt::format("{}: face {} has {} vertices; at least 3 are needed", name, k,
                                   polygon.size()));
    }
    for (double index : polygon) {
        if (index < 0.0 || index >= static_cast<double>(num_vertices)) {
            return corrupt(
                fmt::format("{}: face {} refers to vertex {}, but there are only {} vertices", name,
                            k, static_cast<long long>(index), num_vertices));
        }
    }
    if (keep_faces) {
        for (size_t j = 1; j + 1 < polygon.size(); ++j) {
            mesh->triangles.emplace_back(static_cast<int>(polygon[0]), static_cast<int>(polygon[j]),
                                         static_cast<int>(polygon[j + 1]));
        }
    }
    return Status::ok();
}

/// Reads vertices and faces; `keep_faces` = false still validates faces.
Result<TriangleMesh> readPly(const std::filesystem::path& path, bool keep_faces) {
    auto data_or = slurp(path);
    if (!data_or.isOk()) return data_or.status();
    const std::string& data = *data_or;
    const std::string name = path.string();
    auto header_or = parseHeader(data, name);
    if (!header_or.isOk()) return header_or.status();
    const Header& header = *header_or;
    auto layout_or = vertexLayout(header, name);
    if (!layout_or.isOk()) return layout_or.status();
    const VertexLayout& layout = *layout_or;
    const Element* vertex = layout.element;

    BodyCursor cursor(data, header);
    TriangleMesh mesh;
    std::vector<double> values;
    auto failValue = [&](BodyCursor::Outcome outcome, const Element& e, size_t index,
                         size_t read_count) -> Status {
        if (outcome == BodyCursor::Outcome::kEnd) {
            return corrupt(fmt::format("{}: truncated: expected {} {} elements, read {}", name,
                                       e.count, e.name, read_count));
        }
        return corrupt(fmt::format("{}:{}: '{}' is not a number ({} {})", name, cursor.line(),
                                   cursor.badToken(), e.name, index));
    };

    for (const Element& e : header.elements) {
        const bool is_vertex = &e == vertex;
        const bool is_face = e.name == "face";
        int face_list = -1;
        if (is_face) {
            auto list_or = faceListIndex(e, name);
            if (!list_or.isOk()) return list_or.status();
            face_list = *list_or;
        }
        PLUMB_RETURN_IF_ERROR(checkElementFits(e, header, cursor, name));
        const size_t reserve = std::min(e.count, data.size() / 2);
        if (is_vertex) {
            mesh.vertices.reserve(reserve);
            if (layout.has_normals) mesh.normals.reserve(reserve);
            if (layout.has_colors) mesh.colors.reserve(reserve);
        }
        values.resize(e.properties.size());
        std::vector<double> polygon;
        for (size_t k = 0; k < e.count; ++k) {
            for (size_t pi = 0; pi < e.properties.size(); ++pi) {
                const Property& p = e.properties[pi];
                double v = 0.0;
                BodyCursor::Outcome outcome = cursor.read(p.is_list ? p.count_type : p.type, &v);
                if (outcome != BodyCursor::Outcome::kOk) return failValue(outcome, e, k, k);
                values[pi] = v;
                if (!p.is_list) continue;
                if (!(v >= 0.0) || v != std::floor(v)) {
                    return corrupt(
                        fmt::format("{}: {} {}: list length {} is invalid", name, e.name, k, v));
                }
                const auto n = static_cast<size_t>(v);
                if (header.format != BodyFormat::kAscii &&
                    n > cursor.bytesLeft() / sizeOf(p.type)) {
                    return corrupt(fmt::format("{}: truncated: expected {} {} elements, read {}",
                                               name, e.count, e.name, k));
                }
                const bool keep = is_face && static_cast<int>(pi) == face_list;
                if (keep) polygon.assign(n, 0.0);
                for (size_t j = 0; j < n; ++j) {
                    outcome = cursor.read(p.type, &v);
                    if (outcome != BodyCursor::Outcome::kOk) return failValue(outcome, e, k, k);
                    if (keep) polygon[j] = v;
                }
            }
            if (is_vertex) {
                PLUMB_RETURN_IF_ERROR(addVertex(layout, values, k, name, &mesh));
            } else if (is_face) {
                PLUMB_RETURN_IF_ERROR(addFace(polygon, k, vertex->count, keep_faces, name, &mesh));
            }
        }
    }
    return mesh;
}

// ---- writing ----

void appendBinary(std::string* out, const void* data, size_t n) {
    const auto* b = static_cast<const char*>(data);
    if constexpr (std::endian::native == std::endian::little) {
        out->append(b, n);
    } else {
        for (size_t i = 0; i < n; ++i) out->push_back(b[n - 1 - i]);
    }
}

Status writePly(const std::filesystem::path& path, const std::vector<Eigen::Vector3f>& vertices,
                const std::vector<Eigen::Vector3f>& normals, const std::vector<Color3u8>& colors,
                const std::vector<Eigen::Vector3i>* triangles, PlyFormat format) {
    const size_t n = vertices.size();
    if (!normals.empty() && normals.size() != n) {
        return invalidArgument(
            fmt::format("{}: {} normals for {} vertices", path.string(), normals.size(), n));
    }
    if (!colors.empty() && colors.size() != n) {
        return invalidArgument(
            fmt::format("{}: {} colours for {} vertices", path.string(), colors.size(), n));
    }
    for (size_t i = 0; i < n; ++i) {
        if (!vertices[i].allFinite() || (!normals.empty() && !normals[i].allFinite())) {
            return invalidArgument(
                fmt::format("{}: vertex {} has a non-finite position or normal", path.string(), i));
        }
    }
    if (triangles != nullptr) {
        for (size_t t = 0; t < triangles->size(); ++t) {
            const Eigen::Vector3i& tri = (*triangles)[t];
            if ((tri.array() < 0).any() || (tri.array() >= static_cast<int>(n)).any()) {
                return invalidArgument(fmt::format(
                    "{}: triangle {} refers to a vertex outside 0..{}", path.string(), t, n - 1));
            }
        }
    }
    const bool ascii = format == PlyFormat::kAscii;
    std::string out;
    out += "ply\n";
    out += ascii ? "format ascii 1.0\n" : "format binary_little_endian 1.0\n";
    out += "comment written by plumb\n";
    out += fmt::format("element vertex {}\n", n);
    out += "property float x\nproperty float y\nproperty float z\n";
    if (!normals.empty()) out += "property float nx\nproperty float ny\nproperty float nz\n";
    if (!colors.empty()) out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    if (triangles != nullptr) {
        out += fmt::format("element face {}\n", triangles->size());
        out += "property list uchar int vertex_indices\n";
    }
    out += "end_header\n";
    const size_t per_vertex = 12 + (normals.empty() ? 0 : 12) + (colors.empty() ? 0 : 3);
    out.reserve(out.size() + n * (ascii ? 3 * per_vertex : per_vertex) +
                (triangles ? triangles->size() * 13 : 0));
    for (size_t i = 0; i < n; ++i) {
        if (ascii) {
            const Eigen::Vector3f& p = vertices[i];
            fmt::format_to(std::back_inserter(out), "{} {} {}", p.x(), p.y(), p.z());
            if (!normals.empty()) {
                const Eigen::Vector3f& q = normals[i];
                fmt::format_to(std::back_inserter(out), " {} {} {}", q.x(), q.y(), q.z());
            }
            if (!colors.empty()) {
                const Color3u8& c = colors[i];
                fmt::format_to(std::back_inserter(out), " {} {} {}", int{c.x()}, int{c.y()},
                               int{c.z()});
            }
            out += '\n';
        } else {
            for (int k = 0; k < 3; ++k) appendBinary(&out, &vertices[i][k], 4);
            if (!normals.empty()) {
                for (int k = 0; k < 3; ++k) appendBinary(&out, &normals[i][k], 4);
            }
            if (!colors.empty()) {
                for (int k = 0; k < 3; ++k) appendBinary(&out, &colors[i][k], 1);
            }
        }
    }
    if (triangles != nullptr) {
        for (const Eigen::Vector3i& t : *triangles) {
            if (ascii) {
                fmt::format_to(std::back_inserter(out), "3 {} {} {}\n", t.x(), t.y(), t.z());
            } else {
                const uint8_t three = 3;
                appendBinary(&out, &three, 1);
                for (int k = 0; k < 3; ++k) {
                    const int32_t index = t[k];
                    appendBinary(&out, &index, 4);
                }
            }
        }
    }
    return io::writeText(path, out);
}

}  // namespace

Result<PointCloud> readPointCloud(const std::filesystem::path& path) {
    auto mesh = readPly(path, /*keep_faces=*/false);
    if (!mesh.isOk()) return mesh.status();
    PointCloud cloud;
    cloud.points = std::move(mesh->vertices);
    cloud.normals = std::move(mesh->normals);
    cloud.colors = std::move(mesh->colors);
    return cloud;
}

Result<TriangleMesh> readTriangleMesh(const std::filesystem::path& path) {
    return readPly(path, /*keep_faces=*/true);
}

Status writePointCloud(const std::filesystem::path& path, const PointCloud& cloud,
                       PlyFormat format) {
    return writePly(path, cloud.points, cloud.normals, cloud.colors, nullptr, format);
}

Status writeTriangleMesh(const std::filesystem::path& path, const TriangleMesh& mesh,
                         PlyFormat format) {
    return writePly(path, mesh.vertices, mesh.normals, mesh.colors, &mesh.triangles, format);
}

}  // namespace plumb::io
