#!/usr/bin/env bash
# import-linter (grimp) cannot follow setuptools' editable finder for the mapped
# namespace, so give it a plain tree of symlinks: build/lint/tunespec/{app,core,...}.
set -euo pipefail
cd "$(dirname "$0")/.."
rm -rf build/lint && mkdir -p build/lint/tunespec
for d in app core devices resources; do ln -s "$PWD/$d" "build/lint/tunespec/$d"; done
PYTHONPATH="$PWD/build/lint" "${LINT_IMPORTS:-lint-imports}" "$@"
