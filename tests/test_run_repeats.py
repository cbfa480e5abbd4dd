"""``[capture] repeats`` and ``darks`` of a run configuration."""

from __future__ import annotations

import pytest

from tunespec.app.pipeline.plan import plan_from_config
from tunespec.core.errors import InputError


def _config(tmp_path, capture: str):
    path = tmp_path / "run.toml"
    path.write_text(f'out = "r"\n[capture]\n{capture}\n', encoding="utf-8")
    return path


def test_repeats_and_darks_reach_the_plan(tmp_path) -> None:
    plan = plan_from_config(_config(tmp_path, "repeats = 4\ndarks = 3"))
    assert (plan.repeats, plan.n_darks) == (4, 3)
    default = plan_from_config(_config(tmp_path, "iso = 100"))
    assert (default.repeats, default.n_darks) == (1, 1)


@pytest.mark.parametrize(
    ("capture", "message"),
    [
        ("repeats = 0", r"capture.repeats: expected an integer in \[1, 16\], got 0"),
        (
            "brackets = [1.0, 0.125]\nrepeats = 9",
            r"capture.repeats: expected an integer in \[1, 8\], got 9",
        ),
        ("darks = 2.5", r"capture.darks: expected an integer"),
    ],
)
def test_bad_values_name_the_key(tmp_path, capture, message) -> None:
    with pytest.raises(InputError, match=message):
        plan_from_config(_config(tmp_path, capture))
