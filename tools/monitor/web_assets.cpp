// SPDX-License-Identifier: Apache-2.0
#include "tools/monitor/web_assets.hpp"

namespace plumb::monitor {

const WebAsset* findWebAsset(std::string_view path) {
    if (path == "/") path = "/index.html";
    for (const WebAsset& a : webAssets()) {
        if (path == a.path) return &a;
    }
    return nullptr;
}

}  // namespace plumb::monitor
