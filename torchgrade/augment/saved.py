"""A saved :class:`~torchgrade.RandomPostFX` read back by ``torch.load(path, weights_only=True)`` in a process that has
only imported torchgrade.

``weights_only`` loading makes only the classes registered with ``torch.serialization.add_safe_globals``, found by
the name the file holds (``torchgrade.augment.layer.RandomPostFX``). Registering the layer itself at ``import torchgrade``
would import kornia (its base class), which ``import torchgrade`` does not load (``benchmarks/results/import.md``); :class:`SavedRandomPostFX`
is registered under that name instead, and imports the layer only when a file holds one. The layer, once imported,
is registered under another name (:data:`LOADED_NAME`): the load then fills it (``__setstate__``, which checks it as
construction does).

Examples:
    >>> import io
    >>> import torch
    >>> import torchgrade as tg
    >>> saved = io.BytesIO()
    >>> torch.save(tg.RandomPostFX(contrast=20), saved)
    >>> _ = saved.seek(0)
    >>> torch.load(saved, weights_only=True).ranges
    {'contrast': (-20.0, 20.0)}
"""

from __future__ import annotations

import torch

__all__ = ["SavedRandomPostFX", "SAVED_NAME", "OLD_SAVED_NAME", "LOADED_NAME"]

SAVED_NAME = "torchgrade.augment.layer.RandomPostFX"
"""The name a saved layer's file holds (the class's module and name)."""

OLD_SAVED_NAME = "torchgrade.augment.RandomPostFX"
"""The name files saved before the layer moved into the ``augment`` package hold."""

LOADED_NAME = "torchgrade.augment.layer.RandomPostFX.loaded"
"""The name the layer's class is registered under once imported; one no file holds, so that a file's name always
finds :class:`SavedRandomPostFX`."""


class SavedRandomPostFX:
    """Stands for :class:`~torchgrade.RandomPostFX` in a ``weights_only`` load: makes the empty layer the file fills."""

    def __new__(cls, *args):
        from .layer import RandomPostFX

        return RandomPostFX.__new__(RandomPostFX, *args)


torch.serialization.add_safe_globals([(SavedRandomPostFX, SAVED_NAME), (SavedRandomPostFX, OLD_SAVED_NAME)])
