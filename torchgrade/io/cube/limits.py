"""The .cube sizes both directions share: the shaper written, and what a file may hold."""

__all__ = ["SHAPER_SIZE", "MAX_SHAPER_SIZE"]

SHAPER_SIZE = 65536
"""Points of the 1D shaper written for LogC LUTs (Resolve's largest 1D size)."""

MAX_SHAPER_SIZE = 65536
"""Largest 1D section written or read."""
