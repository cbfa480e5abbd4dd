"""No import cycles among TuneSpec's modules (issue 26, item 2).

The graph is grimp's (import-linter's graph library), built over the same plain tree
of links as ``tests/test_import_contracts.py``. It counts every import, at the top
of a module or inside a function, ``TYPE_CHECKING`` included: a lazy import is still
a dependency. A cycle is a strongly connected set of modules; each one found is
reported with the import lines that close it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOPS = ("app", "core", "devices", "resources")

#: Cycles tolerated: none (the last, app.pipeline.folder <-> steps, went with the
#: one sequencer, issue 26 item 1).
ALLOWED: list[frozenset[str]] = []

_FIND = r"""
import json, sys
import grimp

graph = grimp.build_graph(sys.argv[1], cache_dir=None)
index, low, stack, on, found = {}, {}, [], set(), []


def visit(start):
    # iterative Tarjan: strongly connected components of the module graph
    work = [(start, iter(sorted(graph.find_modules_directly_imported_by(start))))]
    index[start] = low[start] = len(index)
    stack.append(start)
    on.add(start)
    while work:
        v, children = work[-1]
        for w in children:
            if w not in index:
                index[w] = low[w] = len(index)
                stack.append(w)
                on.add(w)
                work.append((w, iter(sorted(graph.find_modules_directly_imported_by(w)))))
                break
            if w in on:
                low[v] = min(low[v], index[w])
        else:
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                scc = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    scc.append(w)
                    if w == v:
                        break
                if len(scc) > 1:
                    found.append(sorted(scc))


for m in sorted(graph.modules):
    if m not in index:
        visit(m)
out = []
for scc in found:
    lines = []
    for a in scc:
        for b in scc:
            if a != b and graph.direct_import_exists(importer=a, imported=b):
                for d in graph.get_import_details(importer=a, imported=b):
                    lines.append(f"{a}:{d['line_number']}: {d['line_contents']}")
    out.append({"modules": scc, "imports": lines})
print(json.dumps(out))
"""


def _cycles(root: Path, package: str) -> list[dict]:
    """The cycles among ``package``'s modules, found on ``sys.path = [root]``."""
    out = subprocess.run(
        [sys.executable, "-c", _FIND, package],
        cwd=root,
        env={**os.environ, "PYTHONPATH": str(root)},
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_the_finder_sees_a_cycle_inside_a_function(tmp_path) -> None:
    pytest.importorskip("grimp")
    pkg = tmp_path / "cyclic"
    (pkg / "io").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "io" / "__init__.py").write_text("")
    (pkg / "data.py").write_text("def read():\n    from cyclic.io.reader import r\n")
    (pkg / "io" / "reader.py").write_text("from cyclic.data import read\n")
    (pkg / "leaf.py").write_text("import cyclic.data\n")
    (cycle,) = _cycles(tmp_path, "cyclic")
    assert cycle["modules"] == ["cyclic.data", "cyclic.io.reader"]
    assert "cyclic.data:2: from cyclic.io.reader import r" in cycle["imports"]


def test_no_import_cycles(tmp_path) -> None:
    pytest.importorskip("grimp")
    tree = tmp_path / "tunespec"
    tree.mkdir()
    for top in TOPS:
        (tree / top).symlink_to(ROOT / top, target_is_directory=True)
    cycles = _cycles(tmp_path, "tunespec")
    bad = [c for c in cycles if frozenset(c["modules"]) not in ALLOWED]
    assert not bad, "import cycles:\n" + "\n".join(
        " <-> ".join(c["modules"]) + "\n    " + "\n    ".join(c["imports"]) for c in bad
    )
