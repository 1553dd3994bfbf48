// SPDX-License-Identifier: Apache-2.0
#include "common/tsdf/tsdf_config.hpp"

#include <array>

namespace plumb::tsdf {
namespace {

constexpr std::array<config::EnumName<RaycastNormals>, 3> kRaycastNormalNames{{
    {RaycastNormals::kGradient, "gradient"},
    {RaycastNormals::kCell, "cell"},
    {RaycastNormals::kNeighbours, "neighbours"},
}};

}  // namespace

void describe(config::Schema& s, TsdfConfig& c) {
    s.field("voxel_size_m", c.voxel_size_m, "voxel edge length (KinFu: 3 m / 512)", "m")
        .positive()
        .max(0.5);
    s.field("truncation_m", c.truncation_m,
            "truncation distance mu: the band [-mu, +mu] around surfaces that is fused", "m")
        .positive();
    s.field("max_depth_m", c.max_depth_m, "depth readings beyond this are not integrated", "m")
        .positive();
    s.field("min_depth_m", c.min_depth_m, "depth readings below this are not integrated", "m")
        .min(0.0);
    s.field("max_weight", c.max_weight,
            "voxel weights saturate here so old observations can be overruled (KinFu 128)")
        .min(1.0);
    s.field("max_blocks", c.max_blocks,
            "block budget (8^3 voxels, 4 KiB each); reaching it closes the fragment; 0 = "
            "unlimited",
            "blocks");
    s.field("allocation_stride_px", c.allocation_stride_px,
            "pixel stride of block allocation (1 = every pixel)", "px")
        .range(1, 8);
    s.field("colour_band", c.colour_band,
            "colour is fused into voxels within this fraction of the truncation from the "
            "measured surface")
        .greaterThan(0.0)
        .max(1.0);
    s.field("num_threads", c.num_threads, "worker threads (0 = all); results do not depend on it")
        .min(0);
}

void describe(config::Schema& s, RaycastConfig& c) {
    s.field("min_depth_m", c.min_depth_m, "rays start at this camera z-depth", "m").min(0.0);
    s.field("max_depth_m", c.max_depth_m, "rays stop at this camera z-depth", "m").positive();
    s.field("step_fraction", c.step_fraction,
            "free-space step = step_fraction * truncation * |F| (at least one voxel); within "
            "two voxels in front of a surface the step aims half a voxel past the crossing "
            "F * truncation predicts")
        .positive()
        .max(1.0);
    s.field("hint_near_voxels", c.hint_near_voxels,
            "with a start hint (the depth last fused from this pose), rays march from this many "
            "voxels in front of it first, from one truncation in front when that sample is not "
            "free space (0 = always from one truncation in front)",
            "voxels")
        .min(0.0);
    s.field("hint_hole_radius_px", c.hint_hole_radius_px,
            "with a start hint: a ray over a hole in it starts from the nearest hinted depth "
            "within this many pixels and is not cast when there is none (-1 = such rays march in "
            "full)",
            "px")
        .min(-1);
    s.field("skip_hints_beyond_end", c.skip_hints_beyond_end,
            "with a start hint: a ray whose hinted depth lies beyond the end of its march "
            "(max_depth_m, or the farthest block along it) is not cast (false: it marches in "
            "full)");
    s.field("secant_hits", c.secant_hits,
            "a sample aimed at the surface by the last one that lands within half a voxel of it "
            "gives the hit by one secant step through the two (two samples a hinted ray instead "
            "of four)");
    s.field("min_weight", c.min_weight, "voxels with a smaller weight count as unobserved")
        .greaterThan(0.0);
    s.field("normals", c.normals,
            "the hits' normals: gradient (central differences of the TSDF, 32 more voxels a "
            "hit), cell (the trilinear interpolant's gradient from the 8 voxels of the last "
            "sample, summed over the 3x3 neighbouring hits: no more voxels), neighbours (the cross "
            "product of the neighbouring hits, as for the frames; border hits and hits next to a "
            "depth jump are dropped)",
            kRaycastNormalNames);
    s.field("max_normal_depth_jump_m", c.max_normal_depth_jump_m,
            "with normals = neighbours or cell: a neighbour whose depth differs by more is across "
            "a depth edge (neighbours: the hit gets no normal; cell: it is not summed)",
            "m")
        .positive();
    s.field("num_threads", c.num_threads, "worker threads (0 = all); results do not depend on it")
        .min(0);
}

void describe(config::Schema& s, SurfaceConfig& c) {
    s.field("min_weight", c.min_weight,
            "voxels with a smaller weight are not surface (2 = seen at least twice)")
        .greaterThan(0.0);
    s.field("max_tsdf_jump", c.max_tsdf_jump,
            "sign changes across an edge whose TSDF values differ by more than this are seams "
            "behind occluding contours, not surface")
        .positive()
        .max(2.0);
    s.field("num_threads", c.num_threads, "worker threads (0 = all); results do not depend on it")
        .min(0);
}

}  // namespace plumb::tsdf
