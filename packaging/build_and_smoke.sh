#!/usr/bin/env bash
# Build the one-folder TuneSpec desktop app with PyInstaller and smoke-test what was built.
#
#   packaging/build_and_smoke.sh              venv + build + smoke test
#   packaging/build_and_smoke.sh --smoke-only smoke-test an existing dist/tunespec
#
# Environment:
#   PYTHON        interpreter for the build venv (default python3)
#   VENV          build venv (default build/pkg-venv); the project is installed into it
#                 NON-editable, since PyInstaller cannot follow the editable import hook
#   PIP_ARGS      extra pip arguments (e.g. --no-index --find-links wheels/)
#   VENV_ARGS     extra `python -m venv` arguments (e.g. --system-site-packages to reuse
#                 installed PySide6/scipy wheels; tunespec itself is still installed
#                 non-editable into the venv)
#   DIST          output folder (default dist); the app lands in $DIST/tunespec
#   GUI_SECONDS   how long the GUI must stay up offscreen to pass (default 15)
#
# Smoke test (no display needed; QT_QPA_PLATFORM=offscreen):
#   1. `tunespec --help` and `tunespec-gui --help` start (Python, bundled modules);
#   2. `tunespec-gui --fast-sim` starts Qt offscreen and is still running after
#      GUI_SECONDS (then it is stopped) or exits 0;
#   3. `tunespec demo --out OUT` runs the whole measurement on the simulated bench with
#      the *built* CLI (bundled data sets, colour-science data, matplotlib Agg/PDF);
#   4. the exports exist and are sound: report.html self-contained (inline images, no
#      external URLs), report.pdf a PDF, every .ti3 readable by ArgyllCMS spec2cie when
#      it is installed, sensitivities JSON valid; the built `tunespec export-cgats`
#      reads the demo's reflectances and writes a .ti3.
# Exit status 0 only if every step passed; the log of a failing step is printed.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD

PYTHON=${PYTHON:-python3}
VENV=${VENV:-build/pkg-venv}
DIST=${DIST:-dist}
GUI_SECONDS=${GUI_SECONDS:-15}
APP="$DIST/tunespec"
SMOKE=$(mktemp -d "${TMPDIR:-/tmp}/tunespec-smoke.XXXXXX")
trap 'rm -rf "$SMOKE"' EXIT

step() { printf '\n== %s\n' "$*"; }
fail() { printf 'FAILED: %s\n' "$*" >&2; exit 1; }

build() {
    step "build venv $VENV (project installed non-editable, extras gui + package)"
    # shellcheck disable=SC2086
    "$PYTHON" -m venv ${VENV_ARGS:-} "$VENV"
    # shellcheck disable=SC2086
    "$VENV/bin/python" -m pip install -q --upgrade pip ${PIP_ARGS:-}
    # shellcheck disable=SC2086
    "$VENV/bin/python" -m pip install -q ${PIP_ARGS:-} ".[gui,package]"
    "$VENV/bin/python" -c "import PyInstaller, tunespec.app.cli; print('PyInstaller', PyInstaller.__version__)"

    step "PyInstaller build -> $APP"
    rm -rf "$APP"
    "$VENV/bin/pyinstaller" --noconfirm --clean --log-level WARN \
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
    du -sh "$APP"
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
    run_logged cli-help "$cli" --help
    run_logged gui-help "$gui" --help
    grep -q "export-cgats" "$SMOKE/cli-help.log" || fail "export-cgats missing from tunespec --help"

    step "2. GUI starts offscreen (${GUI_SECONDS}s)"
    set +e
    timeout --signal=TERM --kill-after=10 "$GUI_SECONDS" "$gui" --fast-sim >"$SMOKE/gui.log" 2>&1
    local rc=$?
    set -e
    if [[ $rc -ne 0 && $rc -ne 124 ]]; then
        cat "$SMOKE/gui.log" >&2
        fail "tunespec-gui exited with $rc"
    fi
    grep -q "Traceback" "$SMOKE/gui.log" && { cat "$SMOKE/gui.log" >&2; fail "tunespec-gui logged an error"; }
    echo "GUI ok (exit $rc: $([[ $rc -eq 124 ]] && echo 'still running, stopped' || echo 'closed'))"

    step "3. demo with the built CLI"
    local out="$SMOKE/demo"
    run_logged demo "$cli" demo --out "$out"
    tail -n 5 "$SMOKE/demo.log"

    step "4. exports"
    local html pdf
    html=$(find "$out" -name '*.html' | head -n 1)
    pdf=$(find "$out" -name '*.pdf' | head -n 1)
    [[ -n "$html" ]] || fail "no HTML report in $out"
    [[ -n "$pdf" ]] || fail "no PDF report in $out"
    head -c 5 "$pdf" | grep -q '%PDF-' || fail "$pdf is not a PDF"
    grep -q 'data:image/png;base64,' "$html" || fail "$html has no embedded plots"
    if grep -qE '(src|href)="https?://|<script src=|<link ' "$html"; then
        fail "$html refers to external assets"
    fi
    local n_ti3=0 ti3
    while IFS= read -r -d '' ti3; do
        n_ti3=$((n_ti3 + 1))
        head -n 1 "$ti3" | grep -q '^CTI3' || fail "$ti3: not a CTI3 file"
        if command -v spec2cie >/dev/null && grep -q 'SPECTRAL_BANDS' "$ti3"; then
            run_logged "spec2cie-$n_ti3" spec2cie -n -i D50 -o 1931_2 "$ti3" "$SMOKE/argyll-$n_ti3.ti3"
        fi
    done < <(find "$out" -name '*.ti3' -print0)
    [[ $n_ti3 -gt 0 ]] || fail "no .ti3 export in $out"
    command -v spec2cie >/dev/null && echo "ArgyllCMS spec2cie read $n_ti3 .ti3 file(s)" \
        || echo "ArgyllCMS not installed: .ti3 files checked for the CTI3 header only"
    local json
    json=$(find "$out" -name 'sensitivities*.json' | head -n 1)
    if [[ -n "$json" ]]; then
        "$VENV_PY" -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['spectral_data']['index']['main']==['R','G','B']" "$json" \
            || fail "$json is not rawtoaces JSON"
    fi
    local refl
    refl=$(find "$out" -name 'reflectances.csv' | head -n 1)
    if [[ -n "$refl" ]]; then
        run_logged export-cgats "$cli" export-cgats --reflectances "$refl" -o "$SMOKE/cli.ti3"
        head -n 1 "$SMOKE/cli.ti3" | grep -q '^CTI3' || fail "built export-cgats wrote no CTI3"
    fi
    find "$out" -maxdepth 2 -type f | sed "s|$out/|  |" | sort
    step "smoke test passed: $APP"
}

VENV_PY="$VENV/bin/python"
[[ -x "$VENV_PY" ]] || VENV_PY=$PYTHON
case "${1:-}" in
    --smoke-only) smoke ;;
    "") build; VENV_PY="$VENV/bin/python"; smoke ;;
    *) echo "usage: $0 [--smoke-only]" >&2; exit 2 ;;
esac
