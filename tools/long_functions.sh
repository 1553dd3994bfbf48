#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Lists the functions longer than a limit (default 150 lines, first to last line) in the library
# folders, longest first: `bash tools/long_functions.sh [LIMIT] [FOLDER...]`. Lambdas count
# towards the function around them. Needs Universal Ctags.
set -euo pipefail
cd "$(dirname "$0")/.."
limit=${1:-150}
shift || true
folders=("$@")
[[ ${#folders[@]} -gt 0 ]] || folders=(common device drivers messages backend)
git ls-files -- "${folders[@]}" | grep -E '\.(cpp|hpp|h|cc)$' |
    ctags -L - --language-force=C++ --c++-kinds=f --fields=+ne -o - 2>/dev/null |
    awk -F'\t' -v limit="$limit" '
        $1 !~ /^__anon/ {
            line = 0; end = 0
            for (i = 4; i <= NF; ++i) {
                if ($i ~ /^line:/) line = substr($i, 6)
                if ($i ~ /^end:/) end = substr($i, 5)
            }
            n = end - line + 1
            if (line > 0 && end > 0 && n > limit) printf "%5d %s:%d %s\n", n, $2, line, $1
        }' |
    sort -rn
