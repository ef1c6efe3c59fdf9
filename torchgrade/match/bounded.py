"""Controls an optimiser moves but cannot push outside their documented ranges.

Each fitted control is stored as an unconstrained tensor ``raw`` and read as
``low + (high - low) * sigmoid(raw)``, with ``low, high`` taken from the stage's control table, so
every step of an optimiser lands inside the range the stage promises to handle. Ranges spanning
more than three decades above zero (a tone mapper's white point, 0.001..10000) are mapped in log
space instead, so the optimiser moves them by ratios rather than by steps of thousands.

Examples:
    >>> import torch
    >>> from torchgrade import ColorGrade
    >>> bounded = BoundedControls(ColorGrade.controls, ("contrast", "lift"))
    >>> bounded.values()["contrast"].item()
    0.0
    >>> with torch.no_grad():
    ...     _ = bounded.raw["contrast"].fill_(1e6)
    >>> bounded.values()["contrast"].item()   # as far as the range allows, never beyond
    100.0
"""

from __future__ import annotations

import math

import torch
from torch import nn

__all__ = ["BoundedControls", "LOG_SPAN"]

LOG_SPAN = 1000.0
"""A range whose ``high / low`` exceeds this (with ``low > 0``) is mapped through the sigmoid in log space."""

_EDGE = 1e-6  # a default on a range's edge starts this far inside it: the sigmoid never reaches its ends


class BoundedControls(nn.Module):
    """The controls ``names`` of a control ``table``, as unconstrained parameters starting at ``initial`` or the defaults.

    ``values()`` gives each control in its own units and shape (a colour ``(3,)``, a trackball
    ``(4,)``), inside its range, differentiable with respect to :attr:`raw`.

    Examples:
        >>> from torchgrade.tonemap import TONE_MAPPERS
        >>> bounded = BoundedControls(TONE_MAPPERS["hable"].controls, ("white_point",), {"white_point": 6.0})
        >>> round(bounded.values()["white_point"].item(), 6)
        6.0
    """

    def __init__(self, table: dict, names, initial: dict | None = None, dtype=torch.float64):
        super().__init__()
        initial = initial or {}
        self.raw = nn.ParameterDict()
        self.ranges = {}
        for name in names:
            control = table[name]
            if getattr(control, "kind", None) != "number" or control.range is None:
                raise ValueError(f"{name} is not a numeric control with a range; fittable: {fittable_names(table)}")
            low, high = (float(bound) for bound in control.range)
            start = torch.as_tensor(initial.get(name, control.default), dtype=dtype)
            self.ranges[name] = (low, high, low > 0 and high / low > LOG_SPAN)
            self.raw[name] = nn.Parameter(self._raw_of(start, name))

    def _unit(self, value: torch.Tensor, name: str) -> torch.Tensor:
        low, high, logarithmic = self.ranges[name]
        if logarithmic:
            return (value.log() - math.log(low)) / (math.log(high) - math.log(low))
        return (value - low) / (high - low)

    def _raw_of(self, value: torch.Tensor, name: str) -> torch.Tensor:
        return torch.logit(self._unit(value, name).clamp(_EDGE, 1.0 - _EDGE))

    def values(self) -> dict:
        """Every fitted control, in its units and inside its range."""
        out = {}
        for name, raw in self.raw.items():
            low, high, logarithmic = self.ranges[name]
            unit = torch.sigmoid(raw)
            # exp(log(high)) can round a hair above high; the clamp keeps the promise at the very edge.
            out[name] = (math.log(low) + unit * (math.log(high) - math.log(low))).exp().clamp(low, high) if logarithmic else low + unit * (high - low)
        return out

    def plain_values(self, digits: int = 5) -> dict:
        """The fitted controls as rounded plain numbers and lists, the form a config holds."""
        return {name: _rounded(value.detach().cpu().tolist(), digits) for name, value in self.values().items()}


def fittable_names(table: dict) -> list:
    """The controls of ``table`` that can be fitted: numbers with a range.

    Examples:
        >>> from torchgrade.tonemap import TONE_MAPPERS
        >>> fittable_names(TONE_MAPPERS["reinhard_extended"].controls)
        ['white_point']
    """
    return [name for name, control in table.items() if getattr(control, "kind", None) == "number" and control.range is not None]


def _rounded(value, digits: int):
    if isinstance(value, list):
        return [_rounded(v, digits) for v in value]
    return round(float(value), digits)
