"""ACES 1.x: the RRT's first modules and constants (``rrt.py``), the fits games ship (Unity's, Hill's, Narkowicz's:
``fits.py``) and the reference RRT + ODT that OpenColorIO's ACES 1.0 views apply (``reference.py``)."""

from .fits import aces, aces_fitted, aces_hill, aces_narkowicz
from .reference import aces_reference

__all__ = ["aces", "aces_fitted", "aces_hill", "aces_narkowicz", "aces_reference"]
