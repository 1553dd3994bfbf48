// SPDX-License-Identifier: Apache-2.0
#include "common/tsdf/surface.hpp"

#include <array>
#include <cmath>
#include <utility>
#include <vector>

#include "common/core/parallel.hpp"

namespace plumb::tsdf {
namespace {

// ---- Marching-cubes case tables, derived from the cube's topology -------------------------------
// Corner c of a cube sits at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1). A corner is "inside" when
// its TSDF is negative. For each face, walked counter-clockwise as seen from outside the cube, the
// crossing edges alternate between entering (outside -> inside) and exiting; every entering edge
// is joined to the next exiting edge, which cuts off each run of inside corners on its own (the
// ambiguous face is resolved by separating inside corners, identically for both cubes sharing it).
// A crossing edge is entering on one of its two faces and exiting on the other, so the segments
// chain into closed loops, which are fanned into triangles.

struct CubeEdge {
    int a;     ///< lower corner
    int b;     ///< upper corner (a with bit `axis` set)
    int axis;  ///< 0 = x, 1 = y, 2 = z
};

struct McTables {
    std::array<CubeEdge, 12> edges{};
    std::array<std::vector<std::array<int, 3>>, 256> triangles;  ///< per case, edge triples
};

Eigen::Vector3f cornerOffset(int c) {
    return {static_cast<float>(c & 1), static_cast<float>((c >> 1) & 1),
            static_cast<float>((c >> 2) & 1)};
}

McTables buildTables() {
    McTables t;
    int edge_of[8][8] = {};
    int n = 0;
    for (int axis = 0; axis < 3; ++axis) {
        for (int a = 0; a < 8; ++a) {
            if ((a >> axis) & 1) continue;
            const int b = a | (1 << axis);
            t.edges[static_cast<size_t>(n)] = CubeEdge{a, b, axis};
            edge_of[a][b] = edge_of[b][a] = n++;
        }
    }
    std::array<std::array<int, 4>, 6> faces{};
    int f = 0;
    for (int axis = 0; axis < 3; ++axis) {
        const int b = (axis + 1) % 3, c = (axis + 2) % 3;
        for (int side = 0; side < 2; ++side) {
            const int s = side << axis;
            // (b, c) = (0,0), (1,0), (1,1), (0,1) is counter-clockwise about +axis.
            std::array<int, 4> q = {s, s | (1 << b), s | (1 << b) | (1 << c), s | (1 << c)};
            if (side == 0) std::swap(q[1], q[3]);
            faces[static_cast<size_t>(f++)] = q;
        }
    }
    for (int mask = 0; mask < 256; ++mask) {
        std::array<int, 12> next;
        next.fill(-1);
        for (const auto& q : faces) {
            auto in = [&](int k) { return ((mask >> q[static_cast<size_t>(k & 3)]) & 1) != 0; };
            for (int k = 0; k < 4; ++k) {
                if (in(k) || !in(k + 1)) continue;  // not entering
                for (int j = k + 1; j < k + 5; ++j) {
                    if (in(j) && !in(j + 1)) {
                        const int from = edge_of[q[static_cast<size_t>(k)]][q[(k + 1) & 3]];
                        const int to = edge_of[q[static_cast<size_t>(j & 3)]][q[(j + 1) & 3]];
                        next[static_cast<size_t>(from)] = to;
                        break;
                    }
                }
            }
        }
        std::array<bool, 12> used{};
        for (int e = 0; e < 12; ++e) {
            if (next[static_cast<size_t>(e)] < 0 || used[static_cast<size_t>(e)]) continue;
            std::vector<int> loop;
            for (int cur = e; !used[static_cast<size_t>(cur)];
                 cur = next[static_cast<size_t>(cur)]) {
                used[static_cast<size_t>(cur)] = true;
                loop.push_back(cur);
                PLUMB_CHECK(next[static_cast<size_t>(cur)] >= 0) << "open marching-cubes loop";
            }
            for (size_t i = 1; i + 1 < loop.size(); ++i) {
                t.triangles[static_cast<size_t>(mask)].push_back({loop[0], loop[i], loop[i + 1]});
            }
        }
    }
    // Orientation: with only corner 0 inside, the triangle must face away from corner 0.
    auto mid = [&](int e) {
        const CubeEdge& ce = t.edges[static_cast<size_t>(e)];
        return Eigen::Vector3f(0.5f * (cornerOffset(ce.a) + cornerOffset(ce.b)));
    };
    const auto& tri = t.triangles[1].at(0);
    const Eigen::Vector3f normal = (mid(tri[1]) - mid(tri[0])).cross(mid(tri[2]) - mid(tri[0]));
    if (normal.dot(Eigen::Vector3f::Ones()) < 0.0f) {
        for (auto& list : t.triangles) {
            for (auto& tr : list) std::swap(tr[1], tr[2]);
        }
    }
    return t;
}

const McTables& mcTables() {
    static const McTables tables = buildTables();
    return tables;
}

/// The blocks around one block, for reads at local coordinates in [0, 8] along each axis.
class Neighbourhood {
  public:
    Neighbourhood(const TsdfVolume& volume, const BlockKey& key) {
        for (int i = 0; i < 8; ++i) {
            const BlockKey k = key + BlockKey(i & 1, (i >> 1) & 1, (i >> 2) & 1);
            const int32_t b = volume.findBlock(k);
            blocks_[static_cast<size_t>(i)] =
                b == BlockHashMap::kNotFound ? nullptr : volume.blockVoxels(b);
            colours_[static_cast<size_t>(i)] =
                b == BlockHashMap::kNotFound ? nullptr : volume.blockColours(b);
        }
    }
    /// Colour of the voxel at local (x, y, z), or nullptr (block missing, volume without colour).
    const VoxelColour* colourAt(int x, int y, int z) const {
        const int i = (x >> 3) | ((y >> 3) << 1) | ((z >> 3) << 2);
        const VoxelColour* b = colours_[static_cast<size_t>(i)];
        if (b == nullptr) return nullptr;
        return b + (x & 7) + 8 * (y & 7) + 64 * (z & 7);
    }
    /// Voxel at local coordinates (x, y, z) in [0, 8]^3, or nullptr if its block is missing.
    const Voxel* at(int x, int y, int z) const {
        const int i = (x >> 3) | ((y >> 3) << 1) | ((z >> 3) << 2);
        const Voxel* b = blocks_[static_cast<size_t>(i)];
        if (b == nullptr) return nullptr;
        return b + (x & 7) + 8 * (y & 7) + 64 * (z & 7);
    }

  private:
    std::array<const Voxel*, 8> blocks_{};
    std::array<const VoxelColour*, 8> colours_{};
};

/// Colour at fraction `frac` of the edge from voxel colour a to b (either may be unobserved);
/// mid grey when neither holds colour.
Color3u8 edgeColour(const VoxelColour* a, const VoxelColour* b, float frac) {
    const bool ha = a != nullptr && a->weight > 0, hb = b != nullptr && b->weight > 0;
    if (!ha && !hb) return Color3u8(128, 128, 128);
    if (!hb) return Color3u8(a->r, a->g, a->b);
    if (!ha) return Color3u8(b->r, b->g, b->b);
    auto lerp = [frac](uint8_t x, uint8_t y) {
        return static_cast<uint8_t>(std::lround(x + frac * (static_cast<float>(y) - x)));
    };
    return Color3u8(lerp(a->r, b->r), lerp(a->g, b->g), lerp(a->b, b->b));
}

struct BlockSurface {
    std::vector<Eigen::Vector3f> points;
    std::vector<Eigen::Vector3f> normals;
    std::vector<Color3u8> colours;     ///< one per point when the volume has colour
    std::vector<int32_t> edge_vertex;  ///< per voxel and axis: local vertex index or -1
};

std::vector<BlockSurface> computeEdgeVertices(const TsdfVolume& volume, const SurfaceConfig& config,
                                              bool keep_edge_ids) {
    const std::vector<BlockKey>& keys = volume.blockKeys();
    std::vector<BlockSurface> out(keys.size());
    const float vs = volume.voxelSize();
    const float w_min = config.min_weight;
    parallelFor(config.num_threads, static_cast<int>(keys.size()), [&](int bi) {
        const BlockKey& key = keys[static_cast<size_t>(bi)];
        BlockSurface& s = out[static_cast<size_t>(bi)];
        if (keep_edge_ids) s.edge_vertex.assign(kBlockVoxels * 3, -1);
        const Neighbourhood nb(volume, key);
        const Eigen::Vector3i g0 = key * kBlockSide;
        for (int z = 0; z < kBlockSide; ++z) {
            for (int y = 0; y < kBlockSide; ++y) {
                for (int x = 0; x < kBlockSide; ++x) {
                    const Voxel* v0 = nb.at(x, y, z);
                    if (!(v0->weight >= w_min)) continue;
                    for (int axis = 0; axis < 3; ++axis) {
                        const Voxel* v1 = nb.at(x + (axis == 0), y + (axis == 1), z + (axis == 2));
                        if (v1 == nullptr || !(v1->weight >= w_min)) continue;
                        const float f0 = v0->tsdf, f1 = v1->tsdf;
                        if ((f0 < 0.0f) == (f1 < 0.0f)) continue;
                        if (std::abs(f0 - f1) > config.max_tsdf_jump) continue;
                        const float frac = f0 / (f0 - f1);
                        Eigen::Vector3f q = (g0 + Eigen::Vector3i(x, y, z)).cast<float>();
                        q[axis] += frac;
                        const Eigen::Vector3f p = q * vs;
                        Eigen::Vector3f grad;
                        if (!volume.gradient(p, w_min, &grad) || !(grad.squaredNorm() > 0.0f)) {
                            continue;
                        }
                        if (keep_edge_ids) {
                            s.edge_vertex[static_cast<size_t>((x + 8 * y + 64 * z) * 3 + axis)] =
                                static_cast<int32_t>(s.points.size());
                        }
                        s.points.push_back(p);
                        s.normals.push_back(grad.normalized());
                        if (volume.hasColour()) {
                            s.colours.push_back(edgeColour(
                                nb.colourAt(x, y, z),
                                nb.colourAt(x + (axis == 0), y + (axis == 1), z + (axis == 2)),
                                frac));
                        }
                    }
                }
            }
        }
    });
    return out;
}

}  // namespace

PointCloud extractSurfacePoints(const TsdfVolume& volume, const SurfaceConfig& config) {
    const std::vector<BlockSurface> blocks = computeEdgeVertices(volume, config, false);
    PointCloud cloud;
    size_t n = 0;
    for (const auto& b : blocks) n += b.points.size();
    cloud.reserve(n, true, volume.hasColour());
    for (const auto& b : blocks) {
        cloud.points.insert(cloud.points.end(), b.points.begin(), b.points.end());
        cloud.normals.insert(cloud.normals.end(), b.normals.begin(), b.normals.end());
        cloud.colors.insert(cloud.colors.end(), b.colours.begin(), b.colours.end());
    }
    return cloud;
}

TriangleMesh extractMesh(const TsdfVolume& volume, const SurfaceConfig& config) {
    const McTables& tables = mcTables();
    const std::vector<BlockSurface> blocks = computeEdgeVertices(volume, config, true);
    std::vector<int32_t> offset(blocks.size() + 1, 0);
    for (size_t i = 0; i < blocks.size(); ++i) {
        offset[i + 1] = offset[i] + static_cast<int32_t>(blocks[i].points.size());
    }
    const std::vector<BlockKey>& keys = volume.blockKeys();
    std::vector<std::vector<Eigen::Vector3i>> block_triangles(blocks.size());
    const float w_min = config.min_weight;
    parallelFor(config.num_threads, static_cast<int>(keys.size()), [&](int bi) {
        const BlockKey& key = keys[static_cast<size_t>(bi)];
        const Neighbourhood nb(volume, key);
        // Global vertex index of the edge starting at local voxel (x, y, z) along `axis`.
        std::array<int32_t, 8> nb_index{};
        for (int i = 0; i < 8; ++i) {
            nb_index[static_cast<size_t>(i)] =
                volume.findBlock(key + BlockKey(i & 1, (i >> 1) & 1, (i >> 2) & 1));
        }
        auto edgeVertex = [&](int x, int y, int z, int axis) -> int32_t {
            const int i = (x >> 3) | ((y >> 3) << 1) | ((z >> 3) << 2);
            const int32_t b = nb_index[static_cast<size_t>(i)];
            if (b < 0) return -1;
            const int32_t local = blocks[static_cast<size_t>(b)].edge_vertex[static_cast<size_t>(
                ((x & 7) + 8 * (y & 7) + 64 * (z & 7)) * 3 + axis)];
            return local < 0 ? -1 : offset[static_cast<size_t>(b)] + local;
        };
        std::vector<Eigen::Vector3i>& tris = block_triangles[static_cast<size_t>(bi)];
        for (int z = 0; z < kBlockSide; ++z) {
            for (int y = 0; y < kBlockSide; ++y) {
                for (int x = 0; x < kBlockSide; ++x) {
                    int mask = 0;
                    bool complete = true;
                    for (int c = 0; c < 8 && complete; ++c) {
                        const Voxel* v = nb.at(x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1));
                        if (v == nullptr || !(v->weight >= w_min)) {
                            complete = false;
                        } else if (v->tsdf < 0.0f) {
                            mask |= 1 << c;
                        }
                    }
                    if (!complete || mask == 0 || mask == 255) continue;
                    for (const auto& tri : tables.triangles[static_cast<size_t>(mask)]) {
                        Eigen::Vector3i idx;
                        bool ok = true;
                        for (int k = 0; k < 3 && ok; ++k) {
                            const CubeEdge& e = tables.edges[static_cast<size_t>(tri[k])];
                            idx[k] = edgeVertex(x + (e.a & 1), y + ((e.a >> 1) & 1),
                                                z + ((e.a >> 2) & 1), e.axis);
                            ok = idx[k] >= 0;
                        }
                        if (ok) tris.push_back(idx);
                    }
                }
            }
        }
    });
    TriangleMesh mesh;
    mesh.vertices.reserve(static_cast<size_t>(offset.back()));
    mesh.normals.reserve(static_cast<size_t>(offset.back()));
    for (const auto& b : blocks) {
        mesh.vertices.insert(mesh.vertices.end(), b.points.begin(), b.points.end());
        mesh.normals.insert(mesh.normals.end(), b.normals.begin(), b.normals.end());
        mesh.colors.insert(mesh.colors.end(), b.colours.begin(), b.colours.end());
    }
    for (const auto& t : block_triangles)
        mesh.triangles.insert(mesh.triangles.end(), t.begin(), t.end());
    return mesh;
}

}  // namespace plumb::tsdf
