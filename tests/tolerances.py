"""Named test tolerances, one place (colour-science style)."""

#: Exact arithmetic paths (reshapes, einsum vs. matrix products).
ATOL_EXACT = 1e-12
#: Values that went through a float text round trip with repr().
ATOL_ROUNDTRIP = 0.0
#: Agreement with colour-science's implementation of the same formula.
ATOL_COLOUR = 1e-6
#: Vectorised (batched LAPACK) vs. per-patch loop of the same Wiener formula (Eq. 5).
ATOL_WIENER_LOOP = 1e-10
#: Published values rounded to 4 decimals (Sharma et al. 2005 CIEDE2000 test data).
ATOL_PUBLISHED_4DP = 5e-5
#: Published D50 / 2° white XYZ rounded to 3 decimals.
ATOL_PUBLISHED_3DP = 5e-4
