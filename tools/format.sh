#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# clang-format every C++ source in the tree (`--check`: only report, exit 1 if any differ).
set -euo pipefail
cd "$(dirname "$0")/.."
fmt=${CLANG_FORMAT:-clang-format}
mapfile -t files < <(git ls-files -co --exclude-standard -- '*.cpp' '*.hpp' '*.h' '*.cc' 2>/dev/null ||
                     find common drivers messages device backend tools tests -name '*.[ch]pp')
[ ${#files[@]} -gt 0 ] || exit 0
if [ "${1:-}" = "--check" ]; then
    bad=0
    for f in "${files[@]}"; do
        [ -f "$f" ] || continue
        if ! "$fmt" --dry-run --Werror "$f" >/dev/null 2>&1; then
            echo "not clang-formatted: $f (run tools/format.sh)"
            bad=1
        fi
    done
    exit $bad
fi
"$fmt" -i "${files[@]}"
