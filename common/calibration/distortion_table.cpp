// SPDX-License-Identifier: Apache-2.0
#include "common/calibration/distortion_table.hpp"

#include <fmt/format.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "common/core/check.hpp"
#include "common/io/text_file.hpp"

namespace plumb {
namespace {

// Numbers per cell of dist-model.txt: a "10 5 2" header and four blocks of 5 (counts, two sums,
// factors).
constexpr int kNumbersPerCell = 23;

}  // namespace

Result<DistortionTable> DistortionTable::parse(const std::string& text, const std::string& source) {
    std::istringstream in(text);
    std::string line;
    int line_no = 0;
    std::vector<double> numbers;
    numbers.reserve(kCells * kCells * kNumbersPerCell);
    while (std::getline(in, line)) {
        ++line_no;
        if (line_no <= 5) continue;  // header: 8 6 2 80 80
        const size_t pct = line.find('%');
        if (pct != std::string::npos) line.resize(pct);
        std::istringstream fields(line);
        std::string token;
        while (fields >> token) {
            char* end = nullptr;
            const double v = std::strtod(token.c_str(), &end);
            if (end == token.c_str() || *end != '\0' || !std::isfinite(v)) {
                return corrupt(fmt::format("{}:{}: '{}' is not a number", source, line_no, token));
            }
            numbers.push_back(v);
        }
    }
    const size_t needed = static_cast<size_t>(kCells) * kCells * kNumbersPerCell;
    if (line_no <= 5 || numbers.size() < needed) {
        return corrupt(fmt::format(
            "{}: distortion table has {} numbers after the 5 header lines, need {} (80x80 cells "
            "x 23)",
            source, numbers.size(), needed));
    }
    DistortionTable table;
    table.cells_.resize(kCells * kCells);
    for (int c = 0; c < kCells * kCells; ++c) {
        const size_t base = static_cast<size_t>(c) * kNumbersPerCell + 3;
        bool all_low = true;
        for (int i = 0; i < 5; ++i) all_low &= numbers[base + i] < 8000.0;
        for (int i = 0; i < 5; ++i) {
            table.cells_[c][i] = all_low ? 0.0F : static_cast<float>(numbers[base + 15 + i]);
        }
    }
    return table;
}

Result<DistortionTable> DistortionTable::load(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return notFound(fmt::format("{}: cannot open the distortion table", path.string()));
    std::ostringstream text;
    text << in.rdbuf();
    return parse(text.str(), path.string());
}

DistortionTable DistortionTable::fromCells(std::vector<std::array<float, 5>> cells) {
    PLUMB_CHECK(cells.size() == static_cast<size_t>(kCells) * kCells)
        << "a distortion table has 80x80 cells, got " << cells.size();
    DistortionTable table;
    table.cells_ = std::move(cells);
    return table;
}

DistortionTable DistortionTable::neutral() {
    std::array<float, 5> one;
    one.fill(1.0F);
    return fromCells(std::vector<std::array<float, 5>>(static_cast<size_t>(kCells) * kCells, one));
}

std::string DistortionTable::format() const {
    std::string out = "8\n6\n2\n80\n80\n";
    out.reserve(static_cast<size_t>(kCells) * kCells * 160);
    for (const std::array<float, 5>& c : cells_) {
        const bool valid = std::any_of(c.begin(), c.end(), [](float f) { return f != 0.0F; });
        out += "10\n5\n2\n% 5 1\n";
        for (int i = 0; i < 5; ++i) out += valid ? "8000\n" : "0\n";
        for (int sum = 0; sum < 2; ++sum) out += "% 5 1\n0\n0\n0\n0\n0\n";
        out += "% 5 1\n";
        for (int i = 0; i < 5; ++i) {
            out += fmt::format("{:.17g}\n", valid ? static_cast<double>(c[i]) : 0.0);
        }
    }
    return out;
}

Status DistortionTable::save(const std::filesystem::path& path) const {
    return io::writeText(path, format());
}

int DistortionTable::cellX(int x640) { return std::clamp(x640 / 8, 0, kCells - 1); }

int DistortionTable::cellY(int y480) { return std::clamp(y480 / 6, 0, kCells - 1); }

}  // namespace plumb
