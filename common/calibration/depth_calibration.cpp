// SPDX-License-Identifier: Apache-2.0
#include "common/calibration/depth_calibration.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <utility>
#include <vector>

namespace plumb {

Result<DepthCalibration> DepthCalibration::load(const std::filesystem::path& path) {
    auto table = DistortionTable::load(path);
    if (!table.isOk()) return table.status();
    return DepthCalibration(std::move(table).value(), path.string());
}

DepthCalibration::DepthCalibration(DistortionTable table, std::string source)
    : table_(std::move(table)), source_(std::move(source)) {}

DepthImage DepthCalibration::undistort(DepthImage depth) const {
    const int w = depth.width();
    const int h = depth.height();
    // The table's cells are defined on a 640x480 image and, as in the sensor model (reference
    // §1.4.A.2-3), looked up at the origin of the pixel's 2x2 disparity block.
    std::vector<int> cell_x(static_cast<size_t>(w));
    for (int u = 0; u < w; ++u) cell_x[u] = DistortionTable::cellX((u - u % 2) * 640 / w);
    // Rows are independent: any split gives the same image.
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 16), [&](const tbb::blocked_range<int>& rows) {
        for (int v = rows.begin(); v < rows.end(); ++v) {
            const int cell_y = DistortionTable::cellY((v - v % 2) * 480 / h);
            for (int u = 0; u < w; ++u) {
                const float measured = depth(u, v);
                if (!(measured > 0.0F)) {
                    depth(u, v) = 0.0F;  // invalid stays invalid, NaN included
                    continue;
                }
                double z = measured;
                for (int i = 0; i < kMaxIterations; ++i) {
                    const double next =
                        measured * static_cast<double>(table_.cellFactor(cell_x[u], cell_y, z));
                    const bool converged = std::abs(next - z) < kTolerance;
                    z = next;
                    if (converged || z <= 0.0) break;
                }
                depth(u, v) = static_cast<float>(z);
            }
        }
    });
    return depth;
}

}  // namespace plumb
