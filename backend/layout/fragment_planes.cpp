// SPDX-License-Identifier: Apache-2.0
#include "backend/layout/fragment_planes.hpp"

#include <fmt/format.h>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/segmentation/supervoxel_clustering.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <unordered_map>

#include "backend/layout/alpha_expansion.hpp"
#include "backend/layout/plane_fit.hpp"
#include "backend/layout/tlinkage.hpp"
#include "common/config/config.hpp"
#include "common/config/schema.hpp"
#include "common/core/timing.hpp"

namespace plumb::layout {

void describe(config::Schema& s, FragmentPlaneConfig& c) {
    s.field("sample_voxel_m", c.sample_voxel_m, "working sample spacing (voxel-grid average)", "m")
        .positive()
        .max(0.5);
    s.field("supervoxel_voxel_m", c.supervoxel_voxel_m, "VCCS voxel resolution", "m")
        .positive()
        .max(0.5);
    s.field("supervoxel_seed_m", c.supervoxel_seed_m, "VCCS seed resolution", "m")
        .positive()
        .max(2.0);
    s.field("spatial_importance", c.spatial_importance, "VCCS weight of the spatial distance")
        .min(0.0);
    s.field("normal_importance", c.normal_importance, "VCCS weight of the normal distance")
        .min(0.0);
    s.field("max_supervoxel_curvature", c.max_supervoxel_curvature,
            "supervoxels curvier than this (lambda_min / sum) generate no hypotheses")
        .range(0.0, 1.0 / 3.0);
    s.field("min_triangle_sine", c.min_triangle_sine,
            "hypothesis triangles with a smaller sine are near collinear and dropped")
        .range(0.0, 1.0);
    s.field("max_hypothesis_normal_angle_deg", c.max_hypothesis_normal_angle_deg,
            "a hypothesis must lie within this angle of all three supervoxel normals", "deg")
        .range(0.0, 90.0);
    s.field("max_hypotheses", c.max_hypotheses, "cap on hypotheses per fragment").min(1);
    s.field("tau_m", c.tau_m, "T-linkage inlier scale tau", "m").positive().max(1.0);
    s.field("cutoff_factor", c.cutoff_factor, "preferences vanish beyond cutoff_factor * tau")
        .positive();
    s.field("min_cluster_supervoxels", c.min_cluster_supervoxels,
            "T-linkage clusters with fewer supervoxels are outliers")
        .min(1);
    s.field("min_cluster_area_m2", c.min_cluster_area_m2,
            "T-linkage clusters with less area are outliers", "m^2")
        .min(0.0);
    s.field("null_cost_factor", c.null_cost_factor, "null-label cost gamma in units of tau")
        .positive();
    s.field("smoothness_factor", c.smoothness_factor,
            "Potts weight per neighbour pair in units of tau")
        .min(0.0);
    s.field("knn", c.knn, "graph neighbours per point (k nearest)").range(1, 64);
    s.field("neighbour_radius_m", c.neighbour_radius_m, "graph neighbours must be closer", "m")
        .positive();
    s.field("max_point_normal_angle_deg", c.max_point_normal_angle_deg,
            "data-term normal gate (180 disables)", "deg")
        .range(0.0, 180.0);
    s.field("max_expansion_cycles", c.max_expansion_cycles, "alpha-expansion cycles per round")
        .min(1);
    s.field("refit_rounds", c.refit_rounds, "expansion + refit rounds").min(1);
    s.field("min_label_points", c.min_label_points, "labels with fewer points are dropped").min(1);
    s.field("min_label_area_m2", c.min_label_area_m2, "labels with less area are dropped", "m^2")
        .min(0.0);
    s.field("merge_angle_deg", c.merge_angle_deg, "coplanar-label merge: maximum angle", "deg")
        .range(0.0, 90.0);
    s.field("merge_offset_m", c.merge_offset_m, "coplanar-label merge: maximum mean offset", "m")
        .min(0.0);
}

namespace {

struct Sample {
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector3d> normals;  // unit (zero when unknown)
    int num_input = 0;
};

/// Voxel-grid average of the finite input points (and their normals when present), in order of
/// first occurrence (deterministic).
Sample voxelSample(const PointCloud& cloud, double voxel) {
    Sample s;
    std::unordered_map<uint64_t, int> index;
    index.reserve(cloud.size() / 4 + 16);
    std::vector<int> counts;
    const bool has_normals = cloud.hasNormals();
    for (size_t i = 0; i < cloud.size(); ++i) {
        const Eigen::Vector3f& pf = cloud.points[i];
        if (!pf.allFinite()) continue;
        ++s.num_input;
        const Eigen::Vector3d p = pf.cast<double>();
        const auto kx = static_cast<int64_t>(std::floor(p.x() / voxel));
        const auto ky = static_cast<int64_t>(std::floor(p.y() / voxel));
        const auto kz = static_cast<int64_t>(std::floor(p.z() / voxel));
        const uint64_t key = (static_cast<uint64_t>(kx & 0x1FFFFF) << 42) |
                             (static_cast<uint64_t>(ky & 0x1FFFFF) << 21) |
                             static_cast<uint64_t>(kz & 0x1FFFFF);
        auto [it, inserted] = index.emplace(key, static_cast<int>(s.points.size()));
        if (inserted) {
            s.points.push_back(Eigen::Vector3d::Zero());
            s.normals.push_back(Eigen::Vector3d::Zero());
            counts.push_back(0);
        }
        const int k = it->second;
        s.points[k] += p;
        if (has_normals && cloud.normals[i].allFinite())
            s.normals[k] += cloud.normals[i].cast<double>();
        ++counts[k];
    }
    for (size_t k = 0; k < s.points.size(); ++k) {
        s.points[k] /= counts[k];
        const double nn = s.normals[k].norm();
        s.normals[k] = nn > 1e-9 ? Eigen::Vector3d(s.normals[k] / nn) : Eigen::Vector3d::Zero();
    }
    return s;
}

double cosDeg(double deg) { return std::cos(deg * std::numbers::pi / 180.0); }

struct LabelPlane {
    Eigen::Vector3d n;
    double d;
};

/// Unary costs of the graph cut (Eq. 4): |n.p + d| for planes, gamma for the null label (last);
/// a point whose normal disagrees with the plane by more than the gate pays 2 gamma.
PottsProblem buildProblem(const Sample& sample, const std::vector<LabelPlane>& planes,
                          const std::vector<PottsEdge>& edges, double gamma, double cos_gate) {
    PottsProblem prob;
    prob.num_nodes = static_cast<int>(sample.points.size());
    prob.num_labels = static_cast<int>(planes.size()) + 1;
    prob.unary.resize(static_cast<size_t>(prob.num_nodes) * prob.num_labels);
    for (int p = 0; p < prob.num_nodes; ++p) {
        double* row = prob.unary.data() + static_cast<size_t>(p) * prob.num_labels;
        const Eigen::Vector3d& x = sample.points[p];
        const Eigen::Vector3d& nx = sample.normals[p];
        const bool has_normal = nx.squaredNorm() > 0.5;
        for (size_t l = 0; l < planes.size(); ++l) {
            double c = std::abs(planes[l].n.dot(x) + planes[l].d);
            if (has_normal && std::abs(planes[l].n.dot(nx)) < cos_gate) c = std::max(c, 2 * gamma);
            row[l] = c;
        }
        row[planes.size()] = gamma;
    }
    prob.edges = edges;
    return prob;
}

/// The sample as a PCL cloud (float), for the k-d tree and VCCS.
pcl::PointCloud<pcl::PointXYZ>::Ptr pclCloud(const Sample& sample) {
    const int n = static_cast<int>(sample.points.size());
    auto cloud = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
    cloud->resize(n);
    for (int i = 0; i < n; ++i) {
        const Eigen::Vector3f p = sample.points[i].cast<float>();
        (*cloud)[i] = pcl::PointXYZ(p.x(), p.y(), p.z());
    }
    cloud->width = static_cast<uint32_t>(n);
    cloud->height = 1;
    return cloud;
}

/// Each sample point's graph neighbours: its `knn` nearest other points closer than
/// neighbour_radius_m, nearest first.
std::vector<std::vector<int>> nearestNeighbours(const pcl::PointCloud<pcl::PointXYZ>::Ptr& cloud,
                                                const FragmentPlaneConfig& config) {
    const int n = static_cast<int>(cloud->size());
    pcl::KdTreeFLANN<pcl::PointXYZ> tree;
    tree.setInputCloud(cloud);
    const int k_query = std::min(n, config.knn + 1);
    std::vector<std::vector<int>> knn(n);
    std::vector<int> idx(k_query);
    std::vector<float> d2(k_query);
    const double r2 = config.neighbour_radius_m * config.neighbour_radius_m;
    for (int i = 0; i < n; ++i) {
        const int found = tree.nearestKSearch((*cloud)[i], k_query, idx, d2);
        for (int j = 0; j < found; ++j) {
            if (idx[j] != i && d2[j] <= r2) knn[i].push_back(idx[j]);
        }
    }
    return knn;
}

/// Points without a fused normal get the PCA normal of themselves and their neighbours,
/// oriented towards the fragment origin (the first camera centre).
void fillMissingNormals(const std::vector<std::vector<int>>& knn, Sample* sample) {
    for (size_t i = 0; i < sample->points.size(); ++i) {
        if (sample->normals[i].squaredNorm() > 0.5) continue;
        PlaneMoments m;
        m.add(sample->points[i]);
        for (int j : knn[i]) m.add(sample->points[j]);
        const PlaneFitResult f = m.fit();
        if (!f.valid) continue;
        sample->normals[i] = f.normal.dot(-sample->points[i]) < 0 ? -f.normal : f.normal;
    }
}

/// A supervoxel's centre, plane normal (oriented by its points' normals) and radius.
struct SvInfo {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
    double radius = 0.0;
    bool planar = false;
};

/// The supervoxels of the sample: members (sample indices), sorted adjacency lists, planes.
struct Supervoxels {
    std::vector<std::vector<int>> members;
    std::vector<std::vector<int>> adjacency;
    std::vector<SvInfo> info;
    size_t size() const { return members.size(); }
};

/// Step 2 (reference §4.2): VCCS supervoxels over the sample (colour unused), their members and
/// adjacency.
Supervoxels vccsSupervoxels(const Sample& sample, const pcl::PointCloud<pcl::PointXYZ>::Ptr& cloud,
                            const FragmentPlaneConfig& config, FragmentPlaneDiagnostics* diag) {
    const int n = static_cast<int>(sample.points.size());
    auto normals = std::make_shared<pcl::PointCloud<pcl::Normal>>();
    normals->resize(n);
    for (int i = 0; i < n; ++i) {
        const Eigen::Vector3f nf = sample.normals[i].cast<float>();
        (*normals)[i] = pcl::Normal(nf.x(), nf.y(), nf.z());
    }
    pcl::SupervoxelClustering<pcl::PointXYZ> vccs(static_cast<float>(config.supervoxel_voxel_m),
                                                  static_cast<float>(config.supervoxel_seed_m));
    vccs.setUseSingleCameraTransform(false);
    vccs.setInputCloud(cloud);
    vccs.setNormalCloud(normals);
    vccs.setColorImportance(0.0f);
    vccs.setSpatialImportance(static_cast<float>(config.spatial_importance));
    vccs.setNormalImportance(static_cast<float>(config.normal_importance));
    std::map<uint32_t, pcl::Supervoxel<pcl::PointXYZ>::Ptr> svs;
    vccs.extract(svs);
    std::multimap<uint32_t, uint32_t> sv_adj;
    vccs.getSupervoxelAdjacency(sv_adj);
    const auto labeled = vccs.getLabeledCloud();
    std::map<uint32_t, int> sv_index;
    for (const auto& [label, ptr] : svs) {
        const int k = static_cast<int>(sv_index.size());
        sv_index[label] = k;
    }
    const int num_sv = static_cast<int>(sv_index.size());
    Supervoxels sv;
    sv.members.resize(num_sv);
    if (labeled && static_cast<int>(labeled->size()) == n) {
        for (int i = 0; i < n; ++i) {
            auto it = sv_index.find((*labeled)[i].label);
            if (it == sv_index.end()) continue;
            sv.members[it->second].push_back(i);
        }
    }
    sv.adjacency.resize(num_sv);
    for (const auto& [a, b] : sv_adj) {
        auto ia = sv_index.find(a), ib = sv_index.find(b);
        if (ia == sv_index.end() || ib == sv_index.end() || ia->second == ib->second) continue;
        sv.adjacency[ia->second].push_back(ib->second);
        sv.adjacency[ib->second].push_back(ia->second);
    }
    for (auto& nb : sv.adjacency) {
        std::sort(nb.begin(), nb.end());
        nb.erase(std::unique(nb.begin(), nb.end()), nb.end());
        diag->num_adjacency_pairs += static_cast<int>(nb.size());
    }
    diag->num_adjacency_pairs /= 2;
    diag->num_supervoxels = num_sv;
    return sv;
}

/// Each supervoxel's centre, radius and least-squares plane; planar when its PCA curvature is
/// at most max_supervoxel_curvature and it has at least 3 points.
void supervoxelPlanes(const Sample& sample, const FragmentPlaneConfig& config, Supervoxels* sv,
                      FragmentPlaneDiagnostics* diag) {
    const std::vector<std::vector<int>>& members = sv->members;
    std::vector<SvInfo>& info = sv->info;
    info.assign(sv->size(), SvInfo{});
    for (size_t k = 0; k < sv->size(); ++k) {
        PlaneMoments m;
        Eigen::Vector3d nsum = Eigen::Vector3d::Zero();
        for (int i : members[k]) {
            m.add(sample.points[i]);
            nsum += sample.normals[i];
        }
        if (members[k].empty()) continue;
        const PlaneFitResult f = m.fit();
        info[k].centre = m.mean();
        for (int i : members[k]) {
            info[k].radius = std::max(info[k].radius, (sample.points[i] - info[k].centre).norm());
        }
        if (f.valid) {
            info[k].normal = f.normal.dot(nsum) < 0 ? -f.normal : f.normal;
            info[k].planar = f.curvature <= config.max_supervoxel_curvature &&
                             static_cast<int>(members[k].size()) >= 3;
        }
        if (info[k].planar) ++diag->num_planar_supervoxels;
    }
}

/// Step 3 (reference §4.3): a plane hypothesis from every triangle of mutually adjacent planar
/// supervoxel centres (not near collinear, within max_hypothesis_normal_angle_deg of all three
/// normals); with few triangles also a supervoxel with two of its neighbours; at most
/// max_hypotheses (a uniform deterministic subsample).
std::vector<LabelPlane> planeHypotheses(const Supervoxels& sv, const FragmentPlaneConfig& config,
                                        FragmentPlaneDiagnostics* diag) {
    const std::vector<SvInfo>& info = sv.info;
    const std::vector<std::vector<int>>& adjacency = sv.adjacency;
    const int num_sv = static_cast<int>(sv.size());
    const double cos_hyp = cosDeg(config.max_hypothesis_normal_angle_deg);
    std::vector<LabelPlane> hypotheses;
    auto tryTriangle = [&](int a, int b, int c) {
        const Eigen::Vector3d u = info[b].centre - info[a].centre;
        const Eigen::Vector3d v = info[c].centre - info[a].centre;
        Eigen::Vector3d nrm = u.cross(v);
        const double len = nrm.norm();
        if (!(len >= config.min_triangle_sine * u.norm() * v.norm()) || len <= 0.0) return;
        nrm /= len;
        for (int s : {a, b, c}) {
            if (std::abs(nrm.dot(info[s].normal)) < cos_hyp) return;
        }
        if (nrm.dot(info[a].normal + info[b].normal + info[c].normal) < 0) nrm = -nrm;
        hypotheses.push_back({nrm, -nrm.dot(info[a].centre)});
    };
    for (int a = 0; a < num_sv; ++a) {
        if (!info[a].planar) continue;
        const auto& na = adjacency[a];
        for (size_t x = 0; x < na.size(); ++x) {
            const int b = na[x];
            if (b <= a || !info[b].planar) continue;
            for (size_t y = x + 1; y < na.size(); ++y) {
                const int c = na[y];
                if (c <= a || !info[c].planar) continue;
                if (std::binary_search(adjacency[b].begin(), adjacency[b].end(), c)) {
                    tryTriangle(a, b, c);
                }
            }
        }
    }
    if (static_cast<int>(hypotheses.size()) < diag->num_planar_supervoxels) {
        // Sparse adjacency (few triangles): also a supervoxel with two of its neighbours.
        for (int a = 0; a < num_sv; ++a) {
            if (!info[a].planar) continue;
            const auto& na = adjacency[a];
            for (size_t x = 0; x + 1 < na.size(); ++x) {
                const int b = na[x], c = na[x + 1];
                if (!info[b].planar || !info[c].planar) continue;
                if (std::binary_search(adjacency[b].begin(), adjacency[b].end(), c)) continue;
                tryTriangle(a, b, c);
            }
        }
    }
    if (static_cast<int>(hypotheses.size()) > config.max_hypotheses) {
        std::vector<LabelPlane> kept;
        kept.reserve(config.max_hypotheses);
        const double step = static_cast<double>(hypotheses.size()) / config.max_hypotheses;
        for (int i = 0; i < config.max_hypotheses; ++i) {
            kept.push_back(hypotheses[static_cast<size_t>(i * step)]);
        }
        hypotheses.swap(kept);
    }
    diag->num_hypotheses = static_cast<int>(hypotheses.size());
    return hypotheses;
}

/// Step 4's output: the kept clusters' planes and the label of each sample point (-1: none).
struct InitialLabelling {
    std::vector<LabelPlane> planes;
    std::vector<int> labels;
};

/// Step 4 (Eq. 2-3, reference §4.4): T-linkage over the supervoxels, residual = mean |n.p + d|
/// of a supervoxel's points (pruned exactly beyond the cutoff), merges restricted to adjacent
/// clusters; clusters of at least min_cluster_supervoxels and min_cluster_area_m2 refitted by
/// least squares, kept when their RMS is at most 2 tau.
InitialLabelling tLinkageClusters(const Sample& sample, const Supervoxels& sv,
                                  const std::vector<LabelPlane>& hypotheses,
                                  const FragmentPlaneConfig& config,
                                  FragmentPlaneDiagnostics* diag) {
    const double tau = config.tau_m;
    const double cutoff = config.cutoff_factor * tau;
    const double point_area = config.sample_voxel_m * config.sample_voxel_m;
    const std::vector<std::vector<int>>& members = sv.members;
    const int num_hyp = static_cast<int>(hypotheses.size());
    std::vector<PreferenceVector> prefs(sv.size());
    for (size_t k = 0; k < sv.size(); ++k) {
        if (members[k].empty()) continue;
        prefs[k] = preferencesFromResiduals(
            num_hyp,
            [&](int l) {
                const LabelPlane& h = hypotheses[l];
                // Exact pruning: every member lies within `radius` of the centre.
                if (std::abs(h.n.dot(sv.info[k].centre) + h.d) - sv.info[k].radius >= cutoff) {
                    return -1.0;
                }
                double s = 0.0;
                for (int i : members[k]) s += std::abs(h.n.dot(sample.points[i]) + h.d);
                return s / static_cast<double>(members[k].size());
            },
            tau, config.cutoff_factor);
    }
    const TLinkageResult tl = tLinkage(prefs, sv.adjacency);
    diag->num_tlinkage_clusters = tl.num_clusters;
    InitialLabelling out;
    out.labels.assign(sample.points.size(), -1);
    for (const std::vector<int>& cl : tl.members) {
        if (static_cast<int>(cl.size()) < config.min_cluster_supervoxels) continue;
        PlaneMoments m;
        Eigen::Vector3d nsum = Eigen::Vector3d::Zero();
        for (int k : cl) {
            for (int i : members[k]) {
                m.add(sample.points[i]);
                nsum += sample.normals[i];
            }
        }
        if (static_cast<double>(m.count()) * point_area < config.min_cluster_area_m2) continue;
        const PlaneFitResult f = m.fit();
        if (!f.valid || f.rms_m > 2.0 * tau) continue;
        const Eigen::Vector3d nrm = f.normal.dot(nsum) < 0 ? -f.normal : f.normal;
        const int label = static_cast<int>(out.planes.size());
        out.planes.push_back({nrm, -nrm.dot(f.centroid)});
        for (int k : cl) {
            for (int i : members[k]) out.labels[i] = label;
        }
    }
    diag->num_clusters_kept = static_cast<int>(out.planes.size());
    return out;
}

/// The Potts pairs of the graph cut (Eq. 5): every k-NN pair once, weight lambda.
std::vector<PottsEdge> pottsEdges(const std::vector<std::vector<int>>& knn, double lambda) {
    std::vector<PottsEdge> edges;
    for (int i = 0; i < static_cast<int>(knn.size()); ++i) {
        for (int j : knn[i]) {
            if (i < j) {
                edges.push_back({i, j, lambda});
            } else if (std::find(knn[j].begin(), knn[j].end(), i) == knn[j].end()) {
                edges.push_back({j, i, lambda});  // one-sided neighbour: keep the pair once
            }
        }
    }
    return edges;
}

/// PEARL re-estimation (Isack & Boykov 2012) after an expansion round: every label refitted to
/// its points, labels with too little support dropped, coplanar labels merged (angle below
/// merge_angle_deg and each centroid within merge_offset_m of the other's plane); `labels` are
/// renumbered to the new planes, which are returned.
std::vector<LabelPlane> pearlRefit(const Sample& sample, int num_labels,
                                   const FragmentPlaneConfig& config, std::vector<int>* labels,
                                   FragmentPlaneDiagnostics* diag) {
    const int n = static_cast<int>(sample.points.size());
    const double point_area = config.sample_voxel_m * config.sample_voxel_m;
    std::vector<PlaneMoments> mom(num_labels);
    std::vector<Eigen::Vector3d> nsum(num_labels, Eigen::Vector3d::Zero());
    for (int i = 0; i < n; ++i) {
        if ((*labels)[i] < 0) continue;
        mom[(*labels)[i]].add(sample.points[i]);
        nsum[(*labels)[i]] += sample.normals[i];
    }
    std::vector<int> remap(num_labels, -1);
    std::vector<LabelPlane> refit;
    std::vector<PlaneMoments> refit_mom;
    for (int l = 0; l < num_labels; ++l) {
        const PlaneFitResult f = mom[l].fit();
        if (!f.valid || mom[l].count() < config.min_label_points ||
            static_cast<double>(mom[l].count()) * point_area < config.min_label_area_m2) {
            ++diag->labels_dropped;
            continue;
        }
        const Eigen::Vector3d nrm = f.normal.dot(nsum[l]) < 0 ? -f.normal : f.normal;
        remap[l] = static_cast<int>(refit.size());
        refit.push_back({nrm, -nrm.dot(f.centroid)});
        refit_mom.push_back(mom[l]);
    }
    const double cos_merge = cosDeg(config.merge_angle_deg);
    std::vector<int> merged_into(refit.size());
    for (size_t a = 0; a < refit.size(); ++a) merged_into[a] = static_cast<int>(a);
    for (size_t a = 0; a < refit.size(); ++a) {
        if (merged_into[a] != static_cast<int>(a)) continue;
        for (size_t b = a + 1; b < refit.size(); ++b) {
            if (merged_into[b] != static_cast<int>(b)) continue;
            if (refit[a].n.dot(refit[b].n) < cos_merge) continue;
            const double off_ab = std::abs(refit[a].n.dot(refit_mom[b].mean()) + refit[a].d);
            const double off_ba = std::abs(refit[b].n.dot(refit_mom[a].mean()) + refit[b].d);
            if (std::max(off_ab, off_ba) > config.merge_offset_m) continue;
            merged_into[b] = static_cast<int>(a);
            refit_mom[a].add(refit_mom[b]);
            const PlaneFitResult f = refit_mom[a].fit();
            if (f.valid) {
                const Eigen::Vector3d nrm = f.normal.dot(refit[a].n) < 0 ? -f.normal : f.normal;
                refit[a] = {nrm, -nrm.dot(f.centroid)};
            }
            ++diag->labels_merged;
        }
    }
    std::vector<int> compact(refit.size(), -1);
    std::vector<LabelPlane> next;
    for (size_t a = 0; a < refit.size(); ++a) {
        if (merged_into[a] == static_cast<int>(a)) {
            compact[a] = static_cast<int>(next.size());
            next.push_back(refit[a]);
        }
    }
    for (int i = 0; i < n; ++i) {
        if ((*labels)[i] < 0) continue;
        const int r = remap[(*labels)[i]];
        (*labels)[i] = r < 0 ? -1 : compact[merged_into[r]];
    }
    return next;
}

/// Step 5 (Eq. 4-5, reference §4.5): graph-cut multi-model fitting of every sample point, from
/// the T-linkage labelling: data term |n.p + d| (Eq. 4, buildProblem), null label gamma, Potts
/// term over the k-NN pairs (Eq. 5), minimised by alpha-expansion, then PEARL refits, for
/// refit_rounds rounds. Updates `planes` and `labels`.
Status graphCutFit(const Sample& sample, const std::vector<std::vector<int>>& knn,
                   const FragmentPlaneConfig& config, std::vector<LabelPlane>* planes,
                   std::vector<int>* labels, FragmentPlaneDiagnostics* diag) {
    const int n = static_cast<int>(sample.points.size());
    const double tau = config.tau_m;
    const std::vector<PottsEdge> edges = pottsEdges(knn, config.smoothness_factor * tau);
    const double gamma = config.null_cost_factor * tau;
    const double cos_gate = config.max_point_normal_angle_deg >= 180.0
                                ? -2.0
                                : cosDeg(config.max_point_normal_angle_deg);
    ExpansionConfig ecfg;
    ecfg.max_cycles = config.max_expansion_cycles;
    bool first_round = true;
    for (int round = 0; round < config.refit_rounds && !planes->empty(); ++round) {
        const int null_label = static_cast<int>(planes->size());
        const PottsProblem prob = buildProblem(sample, *planes, edges, gamma, cos_gate);
        std::vector<int> init(n);
        for (int i = 0; i < n; ++i) init[i] = (*labels)[i] < 0 ? null_label : (*labels)[i];
        auto res = alphaExpansion(prob, std::move(init), ecfg);
        if (!res.isOk()) return res.status();
        if (first_round) diag->initial_energy = res->initial_energy;
        first_round = false;
        diag->final_energy = res->energy;
        diag->expansion_cycles += res->cycles;
        diag->max_flow_calls += res->max_flow_calls;
        for (int i = 0; i < n; ++i) {
            (*labels)[i] = res->labels[i] == null_label ? -1 : res->labels[i];
        }
        *planes = pearlRefit(sample, static_cast<int>(planes->size()), config, labels, diag);
    }
    return Status::ok();
}

/// The output planes from the final labels (the last refit already holds their parameters):
/// centroid, support, area and RMS of each.
std::vector<FragmentPlane> finalPlanes(const Sample& sample, const std::vector<LabelPlane>& planes,
                                       const std::vector<int>& labels, double point_area) {
    std::vector<PlaneMoments> mom(planes.size());
    for (size_t i = 0; i < labels.size(); ++i) {
        if (labels[i] >= 0) mom[labels[i]].add(sample.points[i]);
    }
    std::vector<FragmentPlane> out;
    for (size_t l = 0; l < planes.size(); ++l) {
        FragmentPlane fp;
        fp.normal_F = planes[l].n;
        fp.d_F = planes[l].d;
        fp.centroid_F = mom[l].mean();
        fp.num_points = static_cast<int>(mom[l].count());
        fp.area_m2 = fp.num_points * point_area;
        const PlaneFitResult f = mom[l].fit();
        fp.rms_m = f.valid ? f.rms_m : 0.0;
        out.push_back(fp);
    }
    return out;
}

/// Checks a fragment's points before plane extraction.
Status checkFragment(const Fragment& fragment) {
    if (fragment.points_F.empty()) {
        return invalidArgument(fmt::format("fragment {}: no points", fragment.id));
    }
    if (!fragment.points_F.isConsistent()) {
        return invalidArgument(fmt::format("fragment {}: {} points but {} normals / {} colours",
                                           fragment.id, fragment.points_F.size(),
                                           fragment.points_F.normals.size(),
                                           fragment.points_F.colors.size()));
    }
    return Status::ok();
}

}  // namespace

Result<FragmentPlanes> extractFragmentPlanes(const Fragment& fragment,
                                             const FragmentPlaneConfig& config) {
    const auto t_start = SteadyClock::now();
    PLUMB_RETURN_IF_ERROR(config::validate(config));
    PLUMB_RETURN_IF_ERROR(checkFragment(fragment));
    FragmentPlanes out;
    out.fragment_id = fragment.id;
    out.sample_spacing_m = config.sample_voxel_m;
    FragmentPlaneDiagnostics& diag = out.diagnostics;

    // 1. Working sample (reference §4.1) and its neighbour graph.
    auto t0 = SteadyClock::now();
    Sample sample = voxelSample(fragment.points_F, config.sample_voxel_m);
    diag.num_input_points = sample.num_input;
    if (sample.num_input == 0) {
        return invalidArgument(fmt::format("fragment {}: no finite points", fragment.id));
    }
    const int n = static_cast<int>(sample.points.size());
    diag.num_sample_points = n;
    const pcl::PointCloud<pcl::PointXYZ>::Ptr cloud = pclCloud(sample);
    const std::vector<std::vector<int>> knn = nearestNeighbours(cloud, config);
    fillMissingNormals(knn, &sample);
    diag.ms_sample = msSince(t0);
    out.sample_F.reserve(n, true, false);
    for (int i = 0; i < n; ++i) {
        out.sample_F.points.push_back(sample.points[i].cast<float>());
        out.sample_F.normals.push_back(sample.normals[i].cast<float>());
    }
    out.labels.assign(n, -1);
    if (n < 3) {
        diag.ms_total = msSince(t_start);
        return out;
    }

    t0 = SteadyClock::now();  // 2. Supervoxels.
    Supervoxels sv = vccsSupervoxels(sample, cloud, config, &diag);
    diag.ms_supervoxels = msSince(t0);

    t0 = SteadyClock::now();  // 3. Hypotheses.
    supervoxelPlanes(sample, config, &sv, &diag);
    const std::vector<LabelPlane> hypotheses = planeHypotheses(sv, config, &diag);
    diag.ms_hypotheses = msSince(t0);

    t0 = SteadyClock::now();  // 4. T-linkage.
    InitialLabelling initial = tLinkageClusters(sample, sv, hypotheses, config, &diag);
    diag.ms_tlinkage = msSince(t0);

    t0 = SteadyClock::now();  // 5. Graph cut with PEARL refits.
    std::vector<LabelPlane> planes = std::move(initial.planes);
    std::vector<int> labels = std::move(initial.labels);
    PLUMB_RETURN_IF_ERROR(graphCutFit(sample, knn, config, &planes, &labels, &diag));
    diag.ms_graph_cut = msSince(t0);

    const double point_area = config.sample_voxel_m * config.sample_voxel_m;
    out.planes = finalPlanes(sample, planes, labels, point_area);
    out.labels = labels;
    for (int i = 0; i < n; ++i) diag.num_null_points += labels[i] < 0 ? 1 : 0;
    diag.ms_total = msSince(t_start);
    return out;
}

nlohmann::json toJson(const FragmentPlaneDiagnostics& d) {
    return nlohmann::json{{"num_input_points", d.num_input_points},
                          {"num_sample_points", d.num_sample_points},
                          {"num_supervoxels", d.num_supervoxels},
                          {"num_planar_supervoxels", d.num_planar_supervoxels},
                          {"num_adjacency_pairs", d.num_adjacency_pairs},
                          {"num_hypotheses", d.num_hypotheses},
                          {"num_tlinkage_clusters", d.num_tlinkage_clusters},
                          {"num_clusters_kept", d.num_clusters_kept},
                          {"initial_energy", d.initial_energy},
                          {"final_energy", d.final_energy},
                          {"expansion_cycles", d.expansion_cycles},
                          {"max_flow_calls", d.max_flow_calls},
                          {"labels_dropped", d.labels_dropped},
                          {"labels_merged", d.labels_merged},
                          {"num_null_points", d.num_null_points},
                          {"ms_sample", d.ms_sample},
                          {"ms_supervoxels", d.ms_supervoxels},
                          {"ms_hypotheses", d.ms_hypotheses},
                          {"ms_tlinkage", d.ms_tlinkage},
                          {"ms_graph_cut", d.ms_graph_cut},
                          {"ms_total", d.ms_total}};
}

}  // namespace plumb::layout
