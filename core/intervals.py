"""The coverage factor of the 95 % intervals TuneSpec prints, plots and writes.

Every uncertainty TuneSpec keeps is a standard uncertainty u (k = 1); a 95 % interval
is value +- k u with k the normal distribution's 97.5 % quantile (GUM, JCGM 100:2008,
G.2-G.3). Written once here so the report, the GUI's bands and the files agree.
"""

from __future__ import annotations

__all__ = ["COVERAGE_FACTOR_95"]

#: k of a two-sided 95 % interval of a normal distribution (scipy.stats.norm.ppf(0.975)
#: = 1.95996...; 1.96 as the GUM tabulates it).
COVERAGE_FACTOR_95: float = 1.96
