"""cal1 package."""
