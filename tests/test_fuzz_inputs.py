"""Issue 12: a seeded, bounded fuzz run over every input kind (the long run is
``python tools/fuzz_inputs.py --cases 10000``).

Every mutated file must end in a one-line ``InputError`` or be read soundly: no
traceback, no hang, no hostile value accepted."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

_TOOL = Path(__file__).resolve().parents[1] / "tools" / "fuzz_inputs.py"


def _fuzz_module():
    spec = importlib.util.spec_from_file_location("tunespec_fuzz_inputs", _TOOL)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


fuzz_inputs = _fuzz_module()


def _check(n_cases: int, seed: int) -> None:
    counts, bugs = fuzz_inputs.fuzz(n_cases, seed=seed, time_limit_s=10.0)
    shown = "\n".join(f"{k} case {i}: {o}: {d[:400]}" for k, i, o, d in bugs[:5])
    assert not bugs, f"{len(bugs)} bug(s) (seed {seed}):\n{shown}"
    assert sum(counts[o] for o in fuzz_inputs.OUTCOMES) == n_cases
    for kind in fuzz_inputs.KINDS:  # every kind was exercised, and read at times
        assert counts[f"{kind}:refused"] + counts[f"{kind}:accepted"] > 0


def test_fuzz_every_input_kind_seeded() -> None:
    _check(350, seed=2024)


@pytest.mark.slow
def test_fuzz_every_input_kind_longer() -> None:
    _check(3000, seed=7)


@pytest.mark.slow
def test_fuzz_whole_commands_seeded() -> None:
    """Issue 24: commands with damaged files and hostile options, in-process."""
    counts, bugs = fuzz_inputs.fuzz(120, seed=24, kinds=fuzz_inputs.COMMAND_KINDS)
    shown = "\n".join(f"{k} case {i}: {o}: {d[:400]}" for k, i, o, d in bugs[:5])
    assert not bugs, f"{len(bugs)} bug(s):\n{shown}"
    assert counts["commands:refused"] > 0 and counts["commands:accepted"] > 0
