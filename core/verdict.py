"""The calibration's verdict, one rule for the report, ``summary.json``, the CLI and
the GUI: PASS needs more than Table 1.

Table 1 is a fit to the calibration chart itself. ``PASS`` needs Table 1's RGB mean
error *and* the prediction of the patches a second calibration left out
(:mod:`tunespec.core.selfcheck`) within the threshold, *and* no finding of the
self-check (residuals against the error model, the systematic errors fitted, the
LED corrections, the light's reading noise). A Table 1 or a prediction over the threshold fails; a finding, or no
self-check at all, gives ``PASS with warnings``, naming each check.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = [
    "VERDICTS",
    "calibration_verdict",
    "checked_self_check",
    "self_check_findings",
]

#: The verdict's three outcomes.
VERDICTS = ("PASS", "PASS with warnings", "FAIL")


def self_check_findings(checked: Mapping[str, Any]) -> list[str]:
    """Each check that flagged, in a few words (the warnings say more)."""

    def chi(d: Mapping[str, Any]) -> str:
        values = ", ".join(f"{c} {d['reduced'][c]:.1f}" for c in d["flagged"])
        return f"reduced chi-square {values} over {d['limit']:.1f}"

    out = []
    fitted = checked["residual_chi_square"]
    if fitted.get("flagged"):
        out.append(f"calibration residuals beyond the error model ({chi(fitted)})")
    held = checked.get("held_out")
    if held is None:
        out.append("no prediction of left-out patches was made")
    elif held["chi_square"].get("flagged"):
        out.append(
            f"left-out patches' residuals beyond the error model ({chi(held['chi_square'])})"
        )
    if checked.get("implausible_leds"):
        out.append(
            f"implausible LED corrections ({', '.join(checked['implausible_leds'])})"
        )
    if checked.get("large_systematic_terms"):
        out.append(
            f"large systematic errors ({', '.join(checked['large_systematic_terms'])})"
        )
    limit = checked.get("limits", {}).get("meter_noise_fraction")
    noise = checked.get("meter_noise_fraction", {})
    if limit is not None and noise and max(noise.values()) > limit:
        out.append(
            f"noisy light readings ({100 * max(noise.values()):.2f} % of the peak)"
        )
    named = len(out) - (held is None)  # the findings of the checks listed here
    if checked.get("warnings") and not named:
        out += [str(w) for w in checked["warnings"]]  # a check this list lacks
    return out


def checked_self_check(check: Any) -> dict[str, Any] | None:
    """A self-check as the verdict reads it: its ``as_dict()`` form (a mapping read
    back from ``calibration.json`` as it is), or ``None`` -- also for a document that
    lacks its residual check (a ``calibration.json`` edited by hand)."""
    if check is None:
        return None
    d = dict(check) if isinstance(check, Mapping) else check.as_dict()
    return d if isinstance(d.get("residual_chi_square"), Mapping) else None


def calibration_verdict(
    rgb_mean: float, threshold: float, check: Any
) -> tuple[str, str]:
    """``(outcome, why)``, ``outcome`` one of :data:`VERDICTS`.

    ``rgb_mean`` is Table 1's RGB mean error (of full scale), ``check`` the
    self-check or its ``as_dict()``; ``None``, or one without its residual check,
    counts as no self-check (:func:`checked_self_check`).
    """
    self_check = checked_self_check(check)
    limit, mean = float(threshold), float(rgb_mean)
    ok = mean <= limit
    if self_check is None:
        why = (
            f"Table 1 RGB mean error {mean:.4f} of full scale is "
            f"{'within' if ok else 'over'} the threshold {limit:.4f}"
        )
        if not ok:
            return "FAIL", why
        return "PASS with warnings", (
            f"{why}; but: no self-check of the calibration (no left-out patches "
            "predicted, no residual check against the error model)"
        )
    over = [] if ok else [f"Table 1 RGB mean error {mean:.4f}"]
    within = [f"Table 1 RGB mean error {mean:.4f}"] if ok else []
    findings = self_check_findings(self_check)
    held = self_check.get("held_out")
    if held is not None:
        held_mean = float(held["prediction"]["RGB"]["mean"])
        text = f"left-out patches' (1 in {held['every']}) RGB mean {held_mean:.4f}"
        (within if held_mean <= limit else over).append(text)
    if over:
        why = f"{' and '.join(over)} over the threshold {limit:.4f}"
        if findings:
            why += f"; self-check: {'; '.join(findings)}"
        return "FAIL", why
    why = f"{' and '.join(within)} within the threshold {limit:.4f}"
    if findings:
        return "PASS with warnings", f"{why}; but: {'; '.join(findings)}"
    chi = self_check["residual_chi_square"]["reduced"]
    why += (
        "; residuals consistent with the error model (reduced chi-square "
        + ", ".join(f"{c} {v:.2f}" for c, v in chi.items())
        + "), light-source corrections and readings plausible"
    )
    return "PASS", why
