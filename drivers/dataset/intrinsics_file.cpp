// SPDX-License-Identifier: Apache-2.0
#include "drivers/dataset/intrinsics_file.hpp"

#include <fmt/format.h>

#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include "common/io/text_file.hpp"

namespace plumb::dataset {
namespace {

Result<std::string> readWholeFile(const std::filesystem::path& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) {
        return notFound(fmt::format("intrinsics file {} does not exist", path.string()));
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) return ioError(fmt::format("cannot open intrinsics file {}", path.string()));
    std::ostringstream text;
    text << in.rdbuf();
    if (in.bad()) return ioError(fmt::format("cannot read intrinsics file {}", path.string()));
    return text.str();
}

/// Checks what every format shares: a usable camera and, when given, a positive depth scale.
Result<IntrinsicsFile> finish(const std::filesystem::path& path, IntrinsicsFile file) {
    if (Status s = file.camera.validate(); !s.isOk()) {
        return invalidArgument(fmt::format("{}: {}", path.string(), s.message()));
    }
    if (file.depth_scale && !(std::isfinite(*file.depth_scale) && *file.depth_scale > 0.0)) {
        return invalidArgument(fmt::format("{}: depth_scale {} is not a positive number",
                                           path.string(), *file.depth_scale));
    }
    return file;
}

Result<double> jsonNumber(const nlohmann::json& j, const char* key,
                          const std::filesystem::path& path) {
    const auto it = j.find(key);
    if (it == j.end()) return corrupt(fmt::format("{}: missing field '{}'", path.string(), key));
    if (!it->is_number()) {
        return corrupt(fmt::format("{}: field '{}' is not a number", path.string(), key));
    }
    return it->get<double>();
}

Result<int> jsonSize(const nlohmann::json& j, const char* key, const std::filesystem::path& path) {
    auto v = jsonNumber(j, key, path);
    if (!v.isOk()) return v.status();
    if (*v != std::floor(*v) || *v < 1.0 || *v > 1e5) {
        return invalidArgument(fmt::format("{}: field '{}' = {} is not a positive image size",
                                           path.string(), key, *v));
    }
    return static_cast<int>(*v);
}

Result<IntrinsicsFile> parseJson(const std::filesystem::path& path, const std::string& text) {
    const nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (j.is_discarded()) return corrupt(fmt::format("{}: not valid JSON", path.string()));
    if (!j.is_object()) return corrupt(fmt::format("{}: expected a JSON object", path.string()));
    IntrinsicsFile out;
    auto width = jsonSize(j, "width", path);
    if (!width.isOk()) return width.status();
    auto height = jsonSize(j, "height", path);
    if (!height.isOk()) return height.status();
    out.camera.width = *width;
    out.camera.height = *height;
    if (j.contains("intrinsic_matrix")) {
        // Open3D: K stored column-major, so entries 0, 4, 6, 7 are fx, fy, cx, cy.
        const auto& k = j["intrinsic_matrix"];
        if (!k.is_array() || k.size() != 9) {
            return corrupt(
                fmt::format("{}: 'intrinsic_matrix' must hold 9 numbers", path.string()));
        }
        for (const auto& e : k) {
            if (!e.is_number()) {
                return corrupt(
                    fmt::format("{}: 'intrinsic_matrix' holds a non-number", path.string()));
            }
        }
        out.camera.fx = k[0].get<double>();
        out.camera.fy = k[4].get<double>();
        out.camera.cx = k[6].get<double>();
        out.camera.cy = k[7].get<double>();
    } else {
        double* fields[] = {&out.camera.fx, &out.camera.fy, &out.camera.cx, &out.camera.cy};
        const char* names[] = {"fx", "fy", "cx", "cy"};
        for (int i = 0; i < 4; ++i) {
            auto v = jsonNumber(j, names[i], path);
            if (!v.isOk()) return v.status();
            *fields[i] = *v;
        }
    }
    if (j.contains("depth_scale")) {
        auto scale = jsonNumber(j, "depth_scale", path);
        if (!scale.isOk()) return scale.status();
        out.depth_scale = *scale;
    }
    return finish(path, out);
}

Result<IntrinsicsFile> parseText(const std::filesystem::path& path, const std::string& text,
                                 const PinholeCamera& default_size) {
    std::vector<double> numbers;
    std::istringstream lines(text);
    std::string line;
    int line_number = 0;
    while (std::getline(lines, line)) {
        ++line_number;
        if (const auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
        for (char& c : line) {
            if (c == ',' || c == ';' || c == '[' || c == ']') c = ' ';
        }
        std::istringstream tokens(line);
        std::string token;
        while (tokens >> token) {
            double v = 0.0;
            const char* end = token.data() + token.size();
            const auto [ptr, ec] = std::from_chars(token.data(), end, v);
            if (ec != std::errc() || ptr != end || !std::isfinite(v)) {
                return corrupt(
                    fmt::format("{}:{}: '{}' is not a number", path.string(), line_number, token));
            }
            numbers.push_back(v);
        }
    }
    IntrinsicsFile out;
    out.camera = default_size;
    switch (numbers.size()) {
        case 4:
            out.camera.fx = numbers[0];
            out.camera.fy = numbers[1];
            out.camera.cx = numbers[2];
            out.camera.cy = numbers[3];
            break;
        case 6:
            if (numbers[0] != std::floor(numbers[0]) || numbers[1] != std::floor(numbers[1]) ||
                numbers[0] < 1.0 || numbers[1] < 1.0 || numbers[0] > 1e5 || numbers[1] > 1e5) {
                return invalidArgument(fmt::format("{}: image size {}x{} is not positive integers",
                                                   path.string(), numbers[0], numbers[1]));
            }
            out.camera.width = static_cast<int>(numbers[0]);
            out.camera.height = static_cast<int>(numbers[1]);
            out.camera.fx = numbers[2];
            out.camera.fy = numbers[3];
            out.camera.cx = numbers[4];
            out.camera.cy = numbers[5];
            break;
        case 9:
            if (numbers[1] != 0.0 || numbers[3] != 0.0 || numbers[6] != 0.0 || numbers[7] != 0.0 ||
                numbers[8] != 1.0) {
                return corrupt(
                    fmt::format("{}: 9 numbers must form K = [fx 0 cx; 0 fy cy; 0 0 1] (row-major)",
                                path.string()));
            }
            out.camera.fx = numbers[0];
            out.camera.cx = numbers[2];
            out.camera.fy = numbers[4];
            out.camera.cy = numbers[5];
            break;
        default:
            return corrupt(fmt::format(
                "{}: expected 4 (fx fy cx cy), 6 (width height fx fy cx cy) or 9 (K row-major) "
                "numbers, found {}",
                path.string(), numbers.size()));
    }
    return finish(path, out);
}

std::string lowerExtension(const std::filesystem::path& path) {
    std::string ext = path.extension().string();
    for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

}  // namespace

Result<IntrinsicsFile> readIntrinsicsFile(const std::filesystem::path& path,
                                          const PinholeCamera& default_size) {
    auto text = readWholeFile(path);
    if (!text.isOk()) return text.status();
    if (lowerExtension(path) == ".json") return parseJson(path, *text);
    return parseText(path, *text, default_size);
}

Status writeIntrinsicsJson(const std::filesystem::path& path, const PinholeCamera& camera,
                           double depth_scale) {
    PLUMB_CHECK(depth_scale > 0.0) << "depth scale " << depth_scale;
    nlohmann::json j;
    j["width"] = camera.width;
    j["height"] = camera.height;
    j["fx"] = camera.fx;
    j["fy"] = camera.fy;
    j["cx"] = camera.cx;
    j["cy"] = camera.cy;
    j["depth_scale"] = depth_scale;
    return io::writeText(path, j.dump(2) + '\n');
}

}  // namespace plumb::dataset
