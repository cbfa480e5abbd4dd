"""wizard package."""
