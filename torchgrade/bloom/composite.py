"""Bloom composite modes: how a mode joins the pyramid's levels and blends the glow into the frame.

:data:`COMPOSITES` maps each mode to a :class:`Composite`: its final blend and, where the levels are
not simply summed, its level weight. A new mode is one blend function and one line there;
:data:`BLOOM_MODES` and the ``mode`` control of :class:`~torchgrade.Bloom` follow the table.

* ``"additive"`` (Unity): levels summed, ``image + intensity * glow``.
* ``"scattering"`` (Unity): each level joins the one above as ``lerp(level, low, scatter)``, and
  ``lerp(image, glow + image - removed, min(intensity, 1))`` where ``removed`` is the light the
  prefilter took out of the image, so the pass only moves light: ``sum(output) = sum(image)``.
* ``"energy_conserving"`` (Bevy's ``BloomCompositeMode::EnergyConserving``): each level joins the one
  above with Bevy's ``compute_blend_factor`` (:func:`bevy_blend_factor`), and the frame becomes
  ``lerp(image, glow, intensity)``. Level ``k`` here is Bevy's mip ``k`` (the first blurred level),
  and the final blend (Bevy's mip 0 factor) is ``intensity``. It conserves light only when the
  prefilter passes all of it (``threshold=0``, ``fade_fireflies=False``, no ``karis_average`` or
  ``clamp``); with ``low_frequency_boost=0``, ``high_pass_frequency=1`` it is then exactly
  ``scattering`` with ``scatter = intensity``.
* Godot's glow blend modes (``tonemap.glsl`` ``apply_glow``), on the additive pyramid's glow ``g``
  (``intensity`` and ``tint`` applied): ``"screen"`` ``c + g' - c g'`` with ``g' = clamp(g, 0, 1)``
  (Godot's ``white`` = 1); ``"softlight"`` ``c + g' (D(c) - c)`` with ``D(c) = ((16c - 12)c + 4)c``
  for ``c <= 0.25``, ``sqrt(c)`` above, and ``c`` unchanged above 1 (Godot blends it after tone
  mapping; here it blends where the stage runs); ``"replace"`` ``g``; ``"mix"``
  ``lerp(c, glow, intensity)`` (``intensity`` is Godot's ``glow_mix``, at most 1).

Every blend is ``(image, glow, strength, kept) -> output`` with ``glow = strength * glow`` at full
resolution, ``strength`` the intensity (clamped to 1 in lerp modes) and ``kept`` (scattering) the share of each
pixel's light that its half-resolution block did not pass to the pyramid. The linear blends write the output into ``glow`` (a fresh
tensor): every new frame-sized buffer costs page faults, and on CPU that is a large part of bloom's time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import torch

__all__ = [
    "Composite", "COMPOSITES", "BLOOM_MODES", "LERP_MODES", "bevy_blend_factor", "scatter_weight", "bevy_weight",
    "additive_blend", "scattering_blend", "lerp_blend", "screen_blend", "softlight_blend", "replace_blend",
]


@dataclass(frozen=True)
class Composite:
    """One composite mode: its final ``blend``, its ``level_weight`` (None: levels summed) and whether
    ``intensity`` is a lerp weight (``lerp``, clamped to 1).

    ``blend(image, glow, strength, kept)`` takes ``kept``, the share of each pixel's light that stays in the image
    (``1 - strength · fraction`` at full resolution, the fraction its block passed to the pyramid), where the mode
    ``scatters`` (None otherwise). ``level_weight(param, levels, strength)`` returns ``k -> weight`` of level ``k``
    joining the one above, given ``param(name)`` (a control as a broadcastable tensor) and the number of levels taking
    part (an int, or a 0-d tensor in the fixed-depth form). ``zero_is_identity``: the blend returns the image
    unchanged when ``strength`` (and so the glow) is 0.

    Examples:
        >>> COMPOSITES["mix"].lerp, COMPOSITES["additive"].level_weight is None
        (True, True)
    """

    blend: Callable
    level_weight: Optional[Callable] = None
    lerp: bool = False
    scatters: bool = False
    zero_is_identity: bool = True


def bevy_blend_factor(mip: int, max_mip: int, intensity, boost, curvature, high_pass) -> torch.Tensor:
    """Bevy's ``compute_blend_factor`` (energy-conserving): the weight of level ``mip`` blended into the one above.

    ``x = mip / max_mip``; ``boost' = (1 - (1 - x)^(1 / (1 - curvature))) * boost * (1 - intensity)``;
    ``high = 1 - clamp((x - high_pass) / high_pass, 0, 1)``; factor ``(intensity + boost') * high``.

    Examples:
        >>> t = torch.tensor
        >>> round(float(bevy_blend_factor(2, 4, t(0.3), t(0.7), t(0.95), t(1.0))), 4)  # 0.3 + 0.49 boost
        0.79
    """
    x = mip / max_mip
    low_frequency = (1.0 - torch.pow(1.0 - x, 1.0 / (1.0 - curvature))) * boost * (1.0 - intensity)
    high_pass_weight = 1.0 - ((x - high_pass) / high_pass).clamp(0.0, 1.0)
    return (intensity + low_frequency) * high_pass_weight


def scatter_weight(param, levels, strength):
    """Unity's scattering: every level joins the one above with weight ``scatter``.

    Examples:
        >>> scatter_weight(lambda name: torch.tensor(0.7), 3, torch.tensor(1.0))(1)
        tensor(0.7000)
    """
    scatter = param("scatter")
    return lambda k: scatter


def bevy_weight(param, levels, strength):
    """Bevy's energy-conserving weights (:func:`bevy_blend_factor`) over ``levels`` levels.

    Examples:
        >>> controls = {"low_frequency_boost": 0.7, "low_frequency_boost_curvature": 0.95, "high_pass_frequency": 1.0}
        >>> bevy_weight(lambda name: torch.tensor(controls[name]), 3, torch.tensor(1.0))(1)
        tensor(1.)
    """
    boost, curvature, high_pass = (
        param(name) for name in ("low_frequency_boost", "low_frequency_boost_curvature", "high_pass_frequency")
    )
    max_mip = levels - 1 if isinstance(levels, int) else (levels - 1).clamp_min(1)
    return lambda k: bevy_blend_factor(k, max_mip, strength, boost, curvature, high_pass)


def additive_blend(image, glow, strength, kept):
    """``image + glow``.

    Examples:
        >>> additive_blend(torch.ones(1), torch.ones(1), 1.0, None)
        tensor([2.])
    """
    return glow.add_(image)


def scattering_blend(image, glow, strength, kept):
    """``glow + image * kept``: the light passed to the pyramid leaves the image.

    Examples:
        >>> scattering_blend(torch.ones(1, 1, 2, 2), torch.full((1, 1, 2, 2), 0.5), 1.0, torch.full((1, 1, 2, 2), 0.5))
        tensor([[[[1., 1.],
                  [1., 1.]]]])
    """
    return glow.addcmul_(image, kept)


def lerp_blend(image, glow, strength, kept):
    """``lerp(image, glow, strength)`` given ``strength * glow``: ``glow + image * (1 - strength)``.

    Examples:
        >>> lerp_blend(torch.ones(1), torch.full((1,), 1.5), torch.tensor(0.5), None)
        tensor([2.])
    """
    return glow.addcmul_(image, 1.0 - strength)


def screen_blend(image, glow, strength, kept):
    """Godot's screen glow (white 1): ``c + g - c g`` with ``g`` clamped to [0, 1].

    Examples:
        >>> screen_blend(torch.tensor([0.5]), torch.tensor([3.0]), 1.0, None)
        tensor([1.])
    """
    glow = glow.clamp(0.0, 1.0)
    return image + glow - image * glow


def softlight_blend(image, glow, strength, kept):
    """Godot's soft-light glow: ``c + g (D(c) - c)``, ``g`` in [0, 1]; ``D`` a cubic to 0.25, then ``sqrt``; ``c > 1`` kept.

    Godot blends display values, never below 0; here a negative (out-of-gamut) ``c`` meets the cubic's tangent at 0,
    ``D(c) = 4c`` (``((16l - 12)l + 4) c`` with ``l = max(c, 0)``): the cubic itself grows as ``16c³``, a slope of
    4.8e9 at -1e4.

    Examples:
        >>> softlight_blend(torch.tensor([-1.0, 0.25, 2.0]), torch.tensor([1.0, 1.0, 1.0]), 1.0, None)
        tensor([-4.0000,  0.5000,  2.0000])
    """
    glow = glow.clamp(0.0, 1.0)
    light = image.clamp_min(0.0)
    dark = ((16.0 * light - 12.0) * light + 4.0) * image
    target = torch.where(image <= 0.25, dark, image.clamp_min(0.25).sqrt())
    return torch.where(image > 1.0, image, image + glow * (target - image))


def replace_blend(image, glow, strength, kept):
    """Godot's replace: the glow alone.

    Examples:
        >>> replace_blend(torch.ones(1), torch.zeros(1), 1.0, None)
        tensor([0.])
    """
    return glow


COMPOSITES = {
    "additive": Composite(additive_blend),
    "scattering": Composite(scattering_blend, scatter_weight, lerp=True, scatters=True),
    "energy_conserving": Composite(lerp_blend, bevy_weight, lerp=True),
    "screen": Composite(screen_blend),
    "softlight": Composite(softlight_blend),
    "replace": Composite(replace_blend, zero_is_identity=False),
    "mix": Composite(lerp_blend, lerp=True),
}
"""Every composite mode by name, in the order the documentation lists them."""

BLOOM_MODES = tuple(COMPOSITES)
LERP_MODES = tuple(name for name, composite in COMPOSITES.items() if composite.lerp)
"""Modes whose final pass is a lerp by ``intensity``, clamped to 1 there."""
