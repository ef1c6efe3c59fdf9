"""``ParamModule``: how torchgrade layers hold their controls.

A control given as an ``nn.Parameter`` is registered as a parameter (learnable), a tensor as a
buffer (moves with ``.to()``), and a number or tuple stays a plain attribute. ``config()`` returns
the controls as plain Python values, so a layer can be written to JSON and built again.
"""

from __future__ import annotations

import torch
from torch import nn


class ParamModule(nn.Module):
    """Base class of the layers: named controls stored as parameters, buffers or plain values."""

    def __init__(self):
        super().__init__()
        self._control_names: list[str] = []

    def set_param(self, name: str, value) -> None:
        """Store control ``name``: ``nn.Parameter`` -> parameter, tensor -> buffer, else attribute."""
        if isinstance(value, nn.Parameter):
            self.register_parameter(name, value)
        elif isinstance(value, torch.Tensor):
            self.register_buffer(name, value)
        else:
            setattr(self, name, value)
        if name not in self._control_names:
            self._control_names.append(name)

    def params(self) -> dict:
        """The controls as stored (numbers, tensors or parameters), by name."""
        return {name: getattr(self, name) for name in self._control_names}

    def to_config(self) -> dict:
        """The layer's ``config()``, under the name every stage answers to."""
        return self.config()

    def plain_params(self) -> dict:
        """The controls as plain Python values (tensors become nested lists), by name."""
        return {name: _plain(value) for name, value in self.params().items()}


def _plain(value):
    if isinstance(value, torch.Tensor):
        return value.detach().cpu().tolist()
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value
