// SPDX-License-Identifier: Apache-2.0
#pragma once

// Distance from reconstructed points to a ground-truth surface given as dense oriented samples
// (e.g. sim::sampleSurfaces): for each query the closest sample q with normal n gives the
// point-to-plane distance |n . (p - q)|, which, unlike the point-to-point distance, has no bias
// of about a third of the sample spacing on flat surfaces. Samples without normals fall back to
// |p - q|. No I/O; thread-safe.

#include <Eigen/Core>
#include <vector>

#include "common/cloud/point_cloud.hpp"
#include "common/core/status.hpp"

namespace plumb::eval {

/// Point-to-plane distance of every query to its closest reference sample, in query order.
/// `max_point_distance_m` > 0 caps the search: a query whose closest sample lies further away
/// gets that point-to-point distance instead (off the sampled surface). Deterministic for any
/// `num_threads` (0 = all). Errors: empty reference, non-finite points.
Result<std::vector<double>> pointToSurfaceDistances(const std::vector<Eigen::Vector3f>& queries,
                                                    const PointCloud& reference,
                                                    double max_point_distance_m = 0.0,
                                                    int num_threads = 0);

/// Median of `values` (mean of the middle two for an even count); 0 for an empty list.
double median(std::vector<double> values);

}  // namespace plumb::eval
