// SPDX-License-Identifier: Apache-2.0
#include "common/config/registry.hpp"

#include <algorithm>
#include <mutex>

namespace plumb::config {
namespace {

struct Registry {
    std::mutex mutex;
    std::vector<ProgramConfig> configs;
};

Registry& registry() {
    static Registry r;
    return r;
}

}  // namespace

bool registerProgramConfig(ProgramConfig config) {
    Registry& r = registry();
    std::lock_guard<std::mutex> lock(r.mutex);
    for (const ProgramConfig& p : r.configs) {
        if (p.name == config.name) return false;
    }
    r.configs.push_back(std::move(config));
    return true;
}

std::vector<ProgramConfig> programConfigs() {
    Registry& r = registry();
    std::vector<ProgramConfig> out;
    {
        std::lock_guard<std::mutex> lock(r.mutex);
        out = r.configs;
    }
    std::sort(out.begin(), out.end(),
              [](const ProgramConfig& a, const ProgramConfig& b) { return a.name < b.name; });
    return out;
}

Result<ProgramConfig> findProgramConfig(std::string_view name) {
    std::string known;
    for (const ProgramConfig& p : programConfigs()) {
        if (p.name == name) return p;
        known += (known.empty() ? "" : ", ") + p.name;
    }
    return notFound("no configuration schema named '" + std::string(name) +
                    "' (registered: " + (known.empty() ? std::string("none") : known) + ")");
}

}  // namespace plumb::config
