// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/calibration_aligner.hpp"

#include <utility>

namespace plumb::tools {

calibration::FrameAligner icpFrameAligner(const CalibrationAlignerConfig& config,
                                          size_t* failures) {
    return [config, failures](size_t /*k*/, const DepthImage& depth, const PinholeCamera& camera,
                              const tsdf::TsdfVolume& model,
                              const Eigen::Isometry3d& T_W_C) -> Result<Eigen::Isometry3d> {
        Result<device::FramePyramid> frame = device::preprocess(depth, camera, config.preprocess);
        if (!frame.isOk()) return frame.status();
        // `depth` was fused into the model from T_W_C: the raycast marches from it.
        const std::vector<device::ModelLevel> prediction =
            device::predictModel(model, *frame, T_W_C, config.raycast, 0, &depth);
        const device::IcpResult icp =
            device::alignFrameToModel(*frame, prediction, T_W_C, T_W_C, config.icp);
        if (icp.ok) return icp.T_M_C;
        if (failures != nullptr) ++*failures;
        return T_W_C;
    };
}

}  // namespace plumb::tools
