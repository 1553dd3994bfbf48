#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Checks the include rules of DESIGN.md ("Top-level layout") over the source tree:
#   - the device side (common/, drivers/, messages/, device/) includes no PCL, Ceres or Open3D
#     header: it must cross-build for a small ARM box;
#   - dependencies point one way, common <- drivers, messages <- device and common, messages <-
#     backend: common/ includes none of drivers/ messages/ device/ backend/; drivers/ none of
#     messages/ device/ backend/; messages/ none of drivers/ device/ backend/; device/ none of
#     backend/; backend/ none of drivers/ or device/; no library folder includes tools/ or tests/.
# Prints one line per violation (file:line: the include and the rule) and exits 1 when there is
# any, 0 otherwise.
#
#   tools/check_link_rules.sh [ROOT]   check the tree at ROOT (default: this repository)
#   tools/check_link_rules.sh --self-test
#                                      check that a tree with violations fails, naming each
set -euo pipefail

# folder | regular expression of the forbidden includes (what follows `#include <` or `#include "`)
# | the rule, for the message
rules=(
    "common|(pcl|ceres|open3d)/|the device side includes no PCL, Ceres or Open3D"
    "drivers|(pcl|ceres|open3d)/|the device side includes no PCL, Ceres or Open3D"
    "messages|(pcl|ceres|open3d)/|the device side includes no PCL, Ceres or Open3D"
    "device|(pcl|ceres|open3d)/|the device side includes no PCL, Ceres or Open3D"
    "common|(drivers|messages|device|backend|tools|tests)/|common/ depends on nothing of ours"
    "drivers|(messages|device|backend|tools|tests)/|drivers/ depends on common/ only"
    "messages|(drivers|device|backend|tools|tests)/|messages/ depends on common/ only"
    "device|(backend|tools|tests)/|device/ depends on common/, drivers/ and messages/ only"
    "backend|(drivers|device|tools|tests)/|backend/ depends on common/ and messages/ only"
)

check_tree() {
    local root=$1 violations=0 rule folder pattern why file hit line include
    for rule in "${rules[@]}"; do
        # The pattern holds '|' itself: the folder is before the first '|', the reason after the
        # last one, the pattern in between.
        folder=${rule%%|*}
        why=${rule##*|}
        pattern=${rule#*|}
        pattern=${pattern%|*}
        [ -d "$root/$folder" ] || continue
        while IFS= read -r hit; do
            [ -n "$hit" ] || continue
            file=${hit%%:*}
            file=${file#"$root"/}
            line=${hit#*:}
            line=${line%%:*}
            include=$(sed -nE 's/^[[:space:]]*#[[:space:]]*include[[:space:]]*[<"]([^>"]*)[>"].*/\1/p' \
                <<<"${hit#*:*:}")
            echo "$file:$line: #include \"$include\": $why"
            violations=$((violations + 1))
        done < <(grep -rinE --include='*.cpp' --include='*.hpp' --include='*.h' --include='*.cc' \
                     "^[[:space:]]*#[[:space:]]*include[[:space:]]*[<\"]$pattern" "$root/$folder" ||
                     true)
    done
    if [ "$violations" -gt 0 ]; then
        echo "$violations include(s) break the link rules of DESIGN.md"
        return 1
    fi
    return 0
}

self_test() {
    local tmp out status=0
    tmp=$(mktemp -d)
    trap 'rm -rf "$tmp"' RETURN
    mkdir -p "$tmp/common/core" "$tmp/device/fusion" "$tmp/backend/layout" "$tmp/backend/calibration"
    printf '#include <Eigen/Core>\n' >"$tmp/common/core/fine.hpp"
    printf '#include <pcl/point_types.h>\n' >"$tmp/common/core/bad_pcl.hpp"
    printf '#include "common/core/fine.hpp"\n  #  include <ceres/ceres.h>\n' \
        >"$tmp/device/fusion/bad_ceres.cpp"
    printf '#include <open3d/Open3D.h>\n' >"$tmp/device/fusion/bad_open3d.cpp"
    printf '#include <pcl/point_types.h>\n#include "drivers/source.hpp"\n' \
        >"$tmp/backend/layout/bad_drivers.cpp"
    printf '#include "drivers/sim/noise.hpp"\n' >"$tmp/backend/calibration/self_calibration.hpp"
    printf '#include "drivers/source.hpp"\n' >"$tmp/backend/calibration/self_calibration.cpp"
    out=$(check_tree "$tmp") && status=1
    for expected in "common/core/bad_pcl.hpp:1:" "device/fusion/bad_ceres.cpp:2:" \
        "device/fusion/bad_open3d.cpp:1:" "backend/layout/bad_drivers.cpp:2:" \
        "backend/calibration/self_calibration.hpp:1:" "backend/calibration/self_calibration.cpp:1:" \
        "6 include(s)"; do
        grep -qF "$expected" <<<"$out" || { echo "self-test: missing \"$expected\""; status=1; }
    done
    for unexpected in "fine.hpp" "bad_drivers.cpp:1:"; do
        if grep -qF "$unexpected" <<<"$out"; then
            echo "self-test: wrongly reported \"$unexpected\""
            status=1
        fi
    done
    [ "$status" -eq 0 ] && echo "self-test: every injected violation reported, nothing else" ||
        printf '%s\n' "$out"
    return $status
}

if [ "${1:-}" = "--self-test" ]; then
    self_test
else
    check_tree "${1:-$(cd "$(dirname "$0")/.." && pwd)}"
fi
