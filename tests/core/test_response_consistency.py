"""The responses against Eq. 1 after the estimate (``core.plausibility``):
``check_response_consistency`` refuses when most patches misfit, naming the lights
where they do; ``inconsistent_patches`` names the few that misfit alone."""

from __future__ import annotations

import numpy as np
import pytest

from tunespec.core.plausibility import (
    MAX_CHI2_PER_RESPONSE,
    Checks,
    Implausible,
    check_response_consistency,
    inconsistent_patches,
)

LIGHTS = ("LED410", "LED540", "LED555", "WHITE")


def test_most_patches_misfitting_is_refused_naming_the_worst_lights() -> None:
    chi2 = np.array([150.0, 900.0, 2400.0, 0.9])
    by_light = np.array([1.1, 111.8, 124.3, 3.0])
    with pytest.raises(Implausible, match=r"median chi-square 525 per response over "
                       r"4 patch\(es\).*worst under LED555, LED540: ") as err:  # fmt: skip
        check_response_consistency(chi2, by_light, LIGHTS)
    assert err.value.check == "consistency"
    # an override accepts it and records it
    checks = Checks(force=True)
    checks(check_response_consistency, chi2, by_light, LIGHTS)
    assert len(checks.overridden) == 1


def test_a_few_misfitting_patches_are_named_not_refused() -> None:
    chi2 = np.array([0.9, 1.1, 35.0, 1.0, np.nan])
    check_response_consistency(chi2, np.ones(4), LIGHTS)  # median about 1
    line = inconsistent_patches(chi2, ("a", "b", "paper", "d", "e"))
    assert line.startswith("1 patch(es) fit no reflectance through Eq. 1 (chi-square "
                           "35-35 per response, about 1 expected): paper ")  # fmt: skip
    assert inconsistent_patches(np.full(3, MAX_CHI2_PER_RESPONSE), "abc") == ""
