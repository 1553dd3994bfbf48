// SPDX-License-Identifier: Apache-2.0
#include "backend/layout/tlinkage.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <queue>
#include <tuple>

namespace plumb::layout {

PreferenceVector preferencesFromResiduals(int num_hypotheses,
                                          const std::function<double(int)>& residual, double tau,
                                          double cutoff_factor) {
    PreferenceVector pf;
    const double cutoff = cutoff_factor * tau;
    for (int l = 0; l < num_hypotheses; ++l) {
        const double c = residual(l);
        if (c < 0.0 || c >= cutoff) continue;
        pf.emplace_back(l, static_cast<float>(std::exp(-c / tau)));
    }
    return pf;
}

namespace {

double squaredNorm(const PreferenceVector& a) {
    double s = 0.0;
    for (const auto& [l, v] : a) s += static_cast<double>(v) * v;
    return s;
}

double dot(const PreferenceVector& a, const PreferenceVector& b) {
    double s = 0.0;
    size_t i = 0, j = 0;
    while (i < a.size() && j < b.size()) {
        if (a[i].first < b[j].first) {
            ++i;
        } else if (b[j].first < a[i].first) {
            ++j;
        } else {
            s += static_cast<double>(a[i].second) * b[j].second;
            ++i;
            ++j;
        }
    }
    return s;
}

PreferenceVector elementwiseMin(const PreferenceVector& a, const PreferenceVector& b) {
    PreferenceVector out;
    size_t i = 0, j = 0;
    while (i < a.size() && j < b.size()) {
        if (a[i].first < b[j].first) {
            ++i;
        } else if (b[j].first < a[i].first) {
            ++j;
        } else {
            out.emplace_back(a[i].first, std::min(a[i].second, b[j].second));
            ++i;
            ++j;
        }
    }
    return out;
}

double tanimoto(const PreferenceVector& a, double na, const PreferenceVector& b, double nb) {
    if (a.empty() || b.empty()) return 1.0;
    const double ab = dot(a, b);
    if (ab <= 0.0) return 1.0;
    return 1.0 - ab / (na + nb - ab);
}

}  // namespace

double tanimotoDistance(const PreferenceVector& a, const PreferenceVector& b) {
    return tanimoto(a, squaredNorm(a), b, squaredNorm(b));
}

TLinkageResult tLinkage(const std::vector<PreferenceVector>& preferences,
                        const std::vector<std::vector<int>>& adjacency) {
    const int n = static_cast<int>(preferences.size());
    const bool use_adjacency = !adjacency.empty();
    std::vector<PreferenceVector> pf = preferences;
    std::vector<double> norm2(n);
    for (int i = 0; i < n; ++i) norm2[i] = squaredNorm(pf[i]);
    std::vector<int> parent(n);
    for (int i = 0; i < n; ++i) parent[i] = i;
    std::vector<uint8_t> alive(n, 1);
    std::vector<int> version(n, 0);
    std::vector<std::vector<int>> neighbours;
    if (use_adjacency) {
        neighbours.resize(n);
        for (int i = 0; i < n && i < static_cast<int>(adjacency.size()); ++i) {
            for (int j : adjacency[i]) {
                if (j >= 0 && j < n && j != i) neighbours[i].push_back(j);
            }
        }
        for (auto& nb : neighbours) {
            std::sort(nb.begin(), nb.end());
            nb.erase(std::unique(nb.begin(), nb.end()), nb.end());
        }
    }
    // Inverted index: hypothesis -> items preferring it (cluster ids are their smallest item, and
    // a merged preference is a subset of each part's, so the lists never need new entries).
    int num_hyp = 0;
    for (const auto& p : pf) {
        for (const auto& [l, v] : p) num_hyp = std::max(num_hyp, l + 1);
    }
    std::vector<std::vector<int>> by_hypothesis(num_hyp);
    if (!use_adjacency) {
        for (int i = 0; i < n; ++i) {
            for (const auto& [l, v] : pf[i]) by_hypothesis[l].push_back(i);
        }
    }

    using Entry = std::tuple<double, int, int, int, int>;  // d, a, b, version a, version b
    std::priority_queue<Entry, std::vector<Entry>, std::greater<>> heap;
    std::vector<int> stamp(n, -1);
    int stamp_counter = 0;
    auto candidates = [&](int a, std::vector<int>* out) {
        out->clear();
        ++stamp_counter;
        stamp[a] = stamp_counter;
        if (use_adjacency) {
            for (int b : neighbours[a]) {
                if (alive[b] && stamp[b] != stamp_counter) {
                    stamp[b] = stamp_counter;
                    out->push_back(b);
                }
            }
        } else {
            for (const auto& [l, v] : pf[a]) {
                for (int b : by_hypothesis[l]) {
                    if (alive[b] && stamp[b] != stamp_counter) {
                        stamp[b] = stamp_counter;
                        out->push_back(b);
                    }
                }
            }
        }
    };
    auto push = [&](int a, int b) {
        const double d = tanimoto(pf[a], norm2[a], pf[b], norm2[b]);
        if (d >= 1.0 - 1e-12) return;
        const int lo = std::min(a, b), hi = std::max(a, b);
        heap.emplace(d, lo, hi, version[lo], version[hi]);
    };
    std::vector<int> cand;
    for (int a = 0; a < n; ++a) {
        candidates(a, &cand);
        for (int b : cand) {
            if (b > a) push(a, b);
        }
    }

    TLinkageResult result;
    while (!heap.empty()) {
        const auto [d, a, b, va, vb] = heap.top();
        heap.pop();
        if (!alive[a] || !alive[b] || version[a] != va || version[b] != vb) continue;
        // Merge b into a (a < b keeps cluster ids = smallest member).
        pf[a] = elementwiseMin(pf[a], pf[b]);
        norm2[a] = squaredNorm(pf[a]);
        alive[b] = 0;
        parent[b] = a;
        ++version[a];
        ++result.num_merges;
        if (use_adjacency) {
            std::vector<int> merged;
            std::set_union(neighbours[a].begin(), neighbours[a].end(), neighbours[b].begin(),
                           neighbours[b].end(), std::back_inserter(merged));
            merged.erase(std::remove_if(merged.begin(), merged.end(),
                                        [&](int c) { return c == a || c == b || !alive[c]; }),
                         merged.end());
            for (int c : merged) {
                auto& nc = neighbours[c];
                nc.erase(std::remove(nc.begin(), nc.end(), b), nc.end());
                if (!std::binary_search(nc.begin(), nc.end(), a)) {
                    nc.insert(std::lower_bound(nc.begin(), nc.end(), a), a);
                }
            }
            neighbours[a] = std::move(merged);
            neighbours[b].clear();
        }
        candidates(a, &cand);
        for (int c : cand) push(a, c);
    }

    // Resolve roots; number clusters by their smallest item (root = smallest, by construction).
    std::vector<int> root(n);
    for (int i = 0; i < n; ++i) {
        int r = i;
        while (parent[r] != r) r = parent[r];
        root[i] = r;
    }
    std::vector<int> index(n, -1);
    result.cluster_of_item.resize(n);
    for (int i = 0; i < n; ++i) {
        if (index[root[i]] < 0) {
            index[root[i]] = result.num_clusters++;
            result.members.emplace_back();
        }
        result.cluster_of_item[i] = index[root[i]];
        result.members[index[root[i]]].push_back(i);
    }
    return result;
}

}  // namespace plumb::layout
