"""Named test tolerances, one place (colour-science style)."""

#: Exact arithmetic paths (reshapes, einsum vs. matrix products).
ATOL_EXACT = 1e-12
#: Values that went through a float text round trip with repr().
ATOL_ROUNDTRIP = 0.0
#: Agreement with colour-science's implementation of the same formula.
ATOL_COLOUR = 1e-6
