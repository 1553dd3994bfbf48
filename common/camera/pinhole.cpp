// SPDX-License-Identifier: Apache-2.0
#include "common/camera/pinhole.hpp"

#include <fmt/format.h>
#include <cmath>

namespace plumb {

PinholeCamera PinholeCamera::scaled(double factor) const {
    PinholeCamera c = *this;
    c.width = static_cast<int>(std::lround(width * factor));
    c.height = static_cast<int>(std::lround(height * factor));
    c.fx = fx * factor;
    c.fy = fy * factor;
    // Pixel centres sit at integer coordinates: the continuous image edge is at -0.5.
    c.cx = (cx + 0.5) * factor - 0.5;
    c.cy = (cy + 0.5) * factor - 0.5;
    return c;
}

Eigen::Matrix3d PinholeCamera::K() const {
    Eigen::Matrix3d k;
    k << fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0;
    return k;
}

Status PinholeCamera::validate() const {
    if (width <= 0 || height <= 0) {
        return invalidArgument(fmt::format("camera size {}x{} is not positive", width, height));
    }
    if (!std::isfinite(fx) || !std::isfinite(fy) || fx == 0.0 || fy == 0.0 || !std::isfinite(cx) ||
        !std::isfinite(cy)) {
        return invalidArgument("camera intrinsics are not finite and non-zero: " + toString());
    }
    return Status::ok();
}

std::string PinholeCamera::toString() const {
    return fmt::format("{}x{} fx={} fy={} cx={} cy={}", width, height, fx, fy, cx, cy);
}

Result<PinholeCamera> cameraPreset(const std::string& name) {
    if (name == "primesense" || name == "redwood")
        return PinholeCamera{640, 480, 525.0, 525.0, 319.5, 239.5};
    if (name == "icl-nuim") return PinholeCamera{640, 480, 481.20, -480.00, 319.5, 239.5};
    // TUM RGB-D depth images are registered to the colour camera: use its intrinsics.
    if (name == "tum-fr1") return PinholeCamera{640, 480, 517.3, 516.5, 318.6, 255.3};
    if (name == "tum-fr2") return PinholeCamera{640, 480, 520.9, 521.0, 325.1, 249.7};
    if (name == "tum-fr3") return PinholeCamera{640, 480, 535.4, 539.2, 320.1, 247.6};
    if (name == "7-scenes") return PinholeCamera{640, 480, 585.0, 585.0, 320.0, 240.0};
    if (name == "ci") return PinholeCamera{160, 120, 131.25, 131.25, 79.5, 59.5};
    // PrimeSense at half resolution (QVGA).
    if (name == "qvga") return PinholeCamera{320, 240, 262.5, 262.5, 159.5, 119.5};
    return notFound("no camera preset named '" + name +
                    "' (known: primesense, redwood, icl-nuim, tum-fr1, tum-fr2, tum-fr3, "
                    "7-scenes, ci, qvga)");
}

}  // namespace plumb
