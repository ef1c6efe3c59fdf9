"""Random post-processing for training: :class:`RandomPostFX` (:mod:`.layer`), the ranges it samples
(:mod:`.ranges`), and what a ``weights_only`` load of a saved one needs (:mod:`.saved`).

``RandomPostFX`` is built on kornia's augmentation base, and kornia takes longer to import than torchgrade: the
layer is imported at the first use of its name.
"""

import importlib

from . import saved  # noqa: F401  registers what torch.load(weights_only=True) of a RandomPostFX needs, without kornia

__all__ = ["RandomPostFX", "tonemap_per_sample"]


def __getattr__(name: str):
    if name in __all__:
        return getattr(importlib.import_module(".layer", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
