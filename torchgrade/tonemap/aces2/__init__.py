"""ACES 2.0 Output Transform (Academy, 2024) as differentiable torch: CAM, tonescale, chroma and gamut
compression with cusp tables, display encoding. The public entry point is :func:`aces2_output`."""

from .transform import ENCODINGS, PRIMARIES, Aces2Output, aces2_output

__all__ = ["ENCODINGS", "PRIMARIES", "Aces2Output", "aces2_output"]
