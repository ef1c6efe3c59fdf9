"""torchgrade: differentiable HDR post-processing for PyTorch (bloom, grading, tone mapping, LUTs).

Examples:
    >>> import torch
    >>> import torchgrade as tg
    >>> look = tg.PostFX(grade={"contrast": 20}, tonemap="neutral")
    >>> look(torch.rand(1, 3, 8, 8) * 4).shape
    torch.Size([1, 3, 8, 8])
"""

import importlib

from . import _moved

_moved.install()  # old import paths (torchgrade.pipeline, ...) keep working for a release, with a warning

from . import augment, color, functional, runtime, scene  # noqa: E402
from .bloom import Bloom, ConvolutionBloom  # noqa: E402
from .exposure import AutoExposure  # noqa: E402
from .grading import ColorGrade, PrimaryGrade  # noqa: E402
from .look import PostFX  # noqa: E402
from .lut import LUT3D, bake_lut  # noqa: E402
from .match import match_look  # noqa: E402
from .output import Display, Dither, LookLUT  # noqa: E402
from .runtime import compile  # noqa: E402
from .tonemap import TONEMAP_MODES, ToneMap  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "augment",
    "bloom",
    "color",
    "exposure",
    "functional",
    "grading",
    "io",
    "look",
    "lut",
    "match",
    "onnx",
    "output",
    "runtime",
    "scene",
    "tonemap",
    "compile",
    "RandomPostFX",
    "Bloom",
    "ConvolutionBloom",
    "Dither",
    "Display",
    "AutoExposure",
    "ColorGrade",
    "LUT3D",
    "LookLUT",
    "bake_lut",
    "match_look",
    "PostFX",
    "PrimaryGrade",
    "TONEMAP_MODES",
    "ToneMap",
]


_LAZY_MODULES = ("io", "onnx", "testing", "integrations")
"""Subpackages imported at their first use, so that ``import torchgrade`` loads none of the onnx, OpenEXR and numpy
packages behind them (``benchmarks/results/import.md``: what the import loads, and its time)."""


def __getattr__(name: str):
    if name in _LAZY_MODULES or f"{__name__}.{name}" in _moved.MOVED:  # a moved module warns as it is imported
        return importlib.import_module(f".{name}", __name__)
    if name == "RandomPostFX":  # built on kornia, which takes longer to import than torchgrade: imported at first use
        return augment.RandomPostFX
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
