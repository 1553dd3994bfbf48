// SPDX-License-Identifier: Apache-2.0
#include "common/image/image.hpp"

#include <cmath>
#include <limits>

namespace plumb {

DepthImage toMetres(const Depth16Image& raw, double depth_scale, double min_depth_m,
                    double max_depth_m) {
    PLUMB_CHECK(depth_scale > 0.0) << "depth scale " << depth_scale;
    DepthImage out(raw.width(), raw.height(), 0.0f);
    const double inv = 1.0 / depth_scale;
    for (size_t i = 0; i < raw.size(); ++i) {
        const uint16_t r = raw.data()[i];
        if (r == 0) continue;
        const double d = r * inv;
        if (d < min_depth_m || (max_depth_m > 0.0 && d > max_depth_m)) continue;
        out.data()[i] = static_cast<float>(d);
    }
    return out;
}

Depth16Image toRaw(const DepthImage& depth, double depth_scale) {
    PLUMB_CHECK(depth_scale > 0.0) << "depth scale " << depth_scale;
    Depth16Image out(depth.width(), depth.height(), 0);
    constexpr double kMax = std::numeric_limits<uint16_t>::max();
    for (size_t i = 0; i < depth.size(); ++i) {
        const float d = depth.data()[i];
        if (!(d > 0.0f) || !std::isfinite(d)) continue;
        const double units = std::round(d * depth_scale);
        if (units < 1.0 || units > kMax) continue;
        out.data()[i] = static_cast<uint16_t>(units);
    }
    return out;
}

Image<float> toIntensity(const ColourImage& colour) {
    Image<float> out(colour.width(), colour.height());
    for (size_t i = 0; i < colour.size(); ++i) out.data()[i] = intensity(colour.data()[i]);
    return out;
}

size_t countValid(const DepthImage& depth) {
    size_t n = 0;
    for (float d : depth.pixels()) n += (d > 0.0f && std::isfinite(d)) ? 1 : 0;
    return n;
}

}  // namespace plumb
