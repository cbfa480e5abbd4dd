#!/usr/bin/env bash
# Build the one-folder TuneSpec desktop app with PyInstaller and smoke-test what was built.
#
#   packaging/build_and_smoke.sh              venv + build + smoke test
#   packaging/build_and_smoke.sh --smoke-only smoke-test an existing dist/tunespec
#
# Environment:
#   PYTHON        interpreter for the build venv (default python3)
#   BUILD_CACHE   where the build venv is kept between runs (default
#                 ${XDG_CACHE_HOME:-$HOME/.cache}/tunespec-build, outside the clone)
#   VENV          build venv (default $BUILD_CACHE/venv-pyX.Y); the project is installed
#                 into it NON-editable, since PyInstaller cannot follow the editable
#                 import hook. Its dependencies are installed again only when
#                 pyproject.toml changes (stamp file); tunespec itself every run
#   PIP_ARGS      extra pip arguments (e.g. --no-index --find-links wheels/)
#   VENV_ARGS     extra `python -m venv` arguments
#   DIST          output folder (default dist); the app lands in $DIST/tunespec
#   GUI_SECONDS   how long the GUI must stay up offscreen to pass (default 15)
#
# Smoke test (no display needed; QT_QPA_PLATFORM=offscreen):
#   0. the bundle's size and its 10 largest parts;
#   1. `tunespec --help` and `tunespec-gui --help` start (Python, bundled modules), timed;
#   2. `tunespec-gui --fast-sim` starts Qt offscreen, logs "workstation ready" (the
#      start-up time is until then) and is still running after GUI_SECONDS (then it
#      is stopped) or exits 0;
#   3. `tunespec demo --out OUT` runs the whole measurement on the simulated bench with
#      the *built* CLI (bundled data sets, colour-science data, matplotlib Agg/PDF), then
#      the built `tunespec estimate-image` writes the sample's image exports (ENVI, Zarr,
#      TIFF, PNG) and the built `tunespec export-cgats` a .ti3;
#   4. every export is opened with the reader the docs name for it, told by its content
#      (packaging/check_exports.py: rawtoaces JSON against its schema with jsonschema,
#      CGATS with ArgyllCMS spec2cie when installed and TuneSpec's reader, spectral CSV
#      with colour-science, TIFF with tifffile, Zarr with xarray, ENVI with Spectral
#      Python, the report's HTML self-contained and its PDF whole; exports.json lists
#      exactly the files written).
# Exit status 0 only if every step passed; the log of a failing step is printed.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD

PYTHON=${PYTHON:-python3}
BUILD_CACHE=${BUILD_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/tunespec-build}
PYVER=$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
VENV=${VENV:-$BUILD_CACHE/venv-py$PYVER}
DIST=${DIST:-dist}
GUI_SECONDS=${GUI_SECONDS:-15}
APP="$DIST/tunespec"
SMOKE=$(mktemp -d "${TMPDIR:-/tmp}/tunespec-smoke.XXXXXX")
trap 'rm -rf "$SMOKE"' EXIT
T0=$EPOCHREALTIME

step() { printf '\n== [%5.0f s] %s\n' "$(elapsed "$T0")" "$*"; }
elapsed() {  # seconds since $1 (an $EPOCHREALTIME), to the microsecond
    local d=$(( ${EPOCHREALTIME/[.,]/} - ${1/[.,]/} ))
    printf '%d.%06d' $((d / 1000000)) $((d % 1000000))
}
fail() { printf 'FAILED: %s\n' "$*" >&2; exit 1; }

build() {
    # the dependencies change with pyproject.toml only: keep the venv while it is the same
    local stamp="$VENV/.tunespec-deps" want
    want=$(cat pyproject.toml packaging/build_and_smoke.sh | sha256sum | cut -c1-16)
    if [[ -x "$VENV/bin/python" && "$(cat "$stamp" 2>/dev/null)" == "$want" ]]; then
        step "build venv $VENV (cached): tunespec installed again, non-editable"
        # shellcheck disable=SC2086
        "$VENV/bin/python" -m pip install -q ${PIP_ARGS:-} --no-deps --force-reinstall .
    else
        step "build venv $VENV (project installed non-editable, extras gui + package)"
        mkdir -p "$(dirname "$VENV")"
        # shellcheck disable=SC2086
        "$PYTHON" -m venv ${VENV_ARGS:-} "$VENV"
        # shellcheck disable=SC2086
        "$VENV/bin/python" -m pip install -q --upgrade pip ${PIP_ARGS:-}
        # jsonschema: check_exports.py validates the rawtoaces JSON against its schema
        # shellcheck disable=SC2086
        "$VENV/bin/python" -m pip install -q ${PIP_ARGS:-} ".[gui,package]" jsonschema
        # shellcheck disable=SC2086
        "$VENV/bin/python" -m pip install -q ${PIP_ARGS:-} --no-deps --force-reinstall .
        echo "$want" >"$stamp"
    fi
    "$VENV/bin/python" -c "import PyInstaller, tunespec.app.cli; print('PyInstaller', PyInstaller.__version__)"

    step "PyInstaller build -> $APP"
    rm -rf "$APP"
    "$VENV/bin/python" -m PyInstaller --noconfirm --clean --log-level WARN \
        --distpath "$DIST" --workpath build/pyinstaller packaging/tunespec.spec

    step "desktop integration files"
    mkdir -p "$APP/share/applications" "$APP/share/icons/hicolor/scalable/apps"
    cp packaging/tunespec.desktop "$APP/share/applications/tunespec.desktop"
    cp resources/icons/tunespec.svg "$APP/share/icons/hicolor/scalable/apps/tunespec.svg"
    for n in 16 24 32 48 64 128 256 512; do
        mkdir -p "$APP/share/icons/hicolor/${n}x${n}/apps"
        cp "resources/icons/tunespec-$n.png" "$APP/share/icons/hicolor/${n}x${n}/apps/tunespec.png"
    done
    if command -v desktop-file-validate >/dev/null; then
        desktop-file-validate "$APP/share/applications/tunespec.desktop"
    fi
}

sizes() {  # the bundle's size and its 10 largest parts (folders under _internal, files)
    step "0. bundle size"
    printf 'bundle %s: %s MB in %s files\n' "$APP" \
        "$(du -sm "$APP" | cut -f1)" "$(find "$APP" -type f | wc -l)"
    echo "10 largest parts (MB):"
    # sed reads to the end: head would exit after 10 lines and, under pipefail,
    # sort's next write would end the script with SIGPIPE (141)
    (cd "$APP" && du -sm _internal/* tunespec tunespec-gui share 2>/dev/null) \
        | sort -rn | sed -n '1,10s/^/  /p'
}

timed_start() {  # timed_start NAME CMD... : seconds to run CMD (e.g. --help), logged
    local name=$1; shift
    local t=$EPOCHREALTIME
    run_logged "$name" "$@"
    printf '%s start-up (%s): %.2f s\n' "$name" "$*" "$(elapsed "$t")"
}

run_logged() {  # run_logged NAME CMD... : run, keep the log, print it on failure
    local name=$1; shift
    if ! "$@" >"$SMOKE/$name.log" 2>&1; then
        cat "$SMOKE/$name.log" >&2
        fail "$name: $*"
    fi
}

smoke() {
    [[ -x "$APP/tunespec" && -x "$APP/tunespec-gui" ]] || fail "no built app in $APP"
    export QT_QPA_PLATFORM=offscreen
    local cli="$ROOT/$APP/tunespec" gui="$ROOT/$APP/tunespec-gui"

    step "1. programs start"
    timed_start cli-help "$cli" --help
    timed_start cli-help-again "$cli" --help
    timed_start gui-help "$gui" --help
    grep -q "export-cgats" "$SMOKE/cli-help.log" || fail "export-cgats missing from tunespec --help"

    step "2. GUI starts offscreen (${GUI_SECONDS}s)"
    local t=$EPOCHREALTIME ready="" pid rc
    "$gui" --fast-sim >"$SMOKE/gui.log" 2>&1 &
    pid=$!
    while kill -0 "$pid" 2>/dev/null; do
        if [[ -z "$ready" ]] && grep -q "workstation ready" "$SMOKE/gui.log"; then
            ready=$(elapsed "$t")
        fi
        [[ $(elapsed "$t" | cut -d. -f1) -ge $GUI_SECONDS ]] && break
        sleep 0.1
    done
    if kill -0 "$pid" 2>/dev/null; then
        kill -TERM "$pid"
        for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
        kill -KILL "$pid" 2>/dev/null || true
        wait "$pid" 2>/dev/null || true
        rc=124
    else
        set +e; wait "$pid"; rc=$?; set -e
    fi
    if [[ $rc -ne 0 && $rc -ne 124 ]]; then
        cat "$SMOKE/gui.log" >&2
        fail "tunespec-gui exited with $rc"
    fi
    grep -q "Traceback" "$SMOKE/gui.log" && { cat "$SMOKE/gui.log" >&2; fail "tunespec-gui logged an error"; }
    [[ -n "$ready" ]] || { cat "$SMOKE/gui.log" >&2; fail "tunespec-gui never logged 'workstation ready'"; }
    printf 'GUI start-up (launch to "workstation ready"): %.2f s\n' "$ready"
    echo "GUI ok (exit $rc: $([[ $rc -eq 124 ]] && echo 'still running, stopped' || echo 'closed'))"

    step "3. demo, image estimation and CGATS export with the built CLI"
    local out="$SMOKE/demo" t3=$EPOCHREALTIME
    run_logged demo "$cli" demo --out "$out"
    tail -n 3 "$SMOKE/demo.log"
    printf 'demo: %.1f s\n' "$(elapsed "$t3")"
    local export="$out/export" images="$SMOKE/images" cgats="$SMOKE/cgats"
    [[ -d "$export" ]] || fail "the demo wrote no $export"
    run_logged estimate-image "$cli" estimate-image "$out/sample" \
        --sensitivities "$export/sensitivities.csv" -o "$images"
    tail -n 1 "$SMOKE/estimate-image.log"
    mkdir -p "$cgats"
    run_logged export-cgats "$cli" export-cgats --reflectances "$export/reflectances.csv" \
        -o "$cgats/cli.ti3"

    step "4. every export opened with its reader (packaging/check_exports.py)"
    command -v spec2cie >/dev/null \
        || echo "ArgyllCMS not installed: .ti3 files read by TuneSpec's CGATS reader only"
    "$VENV_PY" packaging/check_exports.py "$export" "$images" "$cgats" \
        || fail "exports: see the lines above"
    step "smoke test passed: $APP ($(printf '%.0f' "$(elapsed "$T0")") s in all)"
}

VENV_PY="$VENV/bin/python"
[[ -x "$VENV_PY" ]] || VENV_PY=$PYTHON
case "${1:-}" in
    --smoke-only) sizes; smoke ;;
    "") build; VENV_PY="$VENV/bin/python"; sizes; smoke ;;
    *) echo "usage: $0 [--smoke-only]" >&2; exit 2 ;;
esac
