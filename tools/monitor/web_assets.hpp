// SPDX-License-Identifier: Apache-2.0
#pragma once

// The monitor's web page (tools/monitor/web/*), compiled into the binary by embed_web.cmake so
// that the page works without an install tree and loads nothing from elsewhere.

#include <string_view>
#include <vector>

namespace plumb::monitor {

struct WebAsset {
    const char* path;          ///< URL path, "/" + file name (e.g. "/index.html")
    const char* content_type;  ///< HTTP Content-Type
    std::string_view bytes;    ///< the file's content
};

/// Every embedded file, sorted by path.
const std::vector<WebAsset>& webAssets();

/// The asset served at `path` ("/" means "/index.html"), nullptr when there is none.
const WebAsset* findWebAsset(std::string_view path);

}  // namespace plumb::monitor
