"""The continuum model shared by every solver: pure numpy reference functions (SI units)."""
