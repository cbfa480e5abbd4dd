"""canon package."""
