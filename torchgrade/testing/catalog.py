"""Every stage the library ships, in each of its modes: one listing for what must hold of all of them.

:data:`STAGE_KINDS` names each stage in each mode (``"tonemap-aces"``, ``"grade-aces"``,
``"bloom-scattering"``, ``"lut-tetrahedral"``) and says how to build it: ``build(**controls)`` with
any of the stage's controls (the others at their defaults), and ``example()`` with a strong setting
that runs every step (a grade that moves every control, a bloom down the whole pyramid, a LUT baked
from such a grade). The extremes and control-range checks and ``benchmarks/robustness.py`` run
over this listing, so a stage listed here is checked everywhere.

Examples:
    >>> import torch
    >>> kind = STAGE_KINDS["grade-aces"]
    >>> kind.build(contrast=20).aces, kind.example().is_identity
    (True, False)
    >>> STAGE_KINDS["lut-trilinear"].example()(torch.rand(1, 3, 2, 2)).shape
    torch.Size([1, 3, 2, 2])
"""

from __future__ import annotations

import copy
import functools
import warnings
from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import torch
from torch import nn

from ..base.stage import Stage
from ..bloom import BLOOM_MODES, Bloom, ConvolutionBloom
from ..exposure import AutoExposure
from ..grading.layer import ColorGrade, PrimaryGrade
from ..grading.primary import STYLES
from ..look.postfx import PostFX
from ..lut import INTERPOLATIONS, LUT3D, LUTAccuracyWarning, bake_lut, identity_table
from ..lut.bake import is_display_referred
from ..output.layer import Dither, LookLUT
from ..tonemap import TONEMAP_MODES, ToneMap

__all__ = ["STRONG_GRADE", "StageKind", "STAGE_KINDS", "learnable"]

STRONG_GRADE = dict(
    post_exposure=0.7, temperature=25, tint=-10, contrast=35, color_filter=(1.0, 0.9, 0.8),
    split_shadows=(0.3, 0.4, 0.7), split_highlights=(0.8, 0.6, 0.4), split_balance=15,
    channel_mixer=((1.1, -0.1, 0.0), (0.05, 0.9, 0.05), (0.0, 0.2, 0.8)), shadows=(0.9, 0.95, 1.1),
    midtones=(1.05, 1.0, 0.95), highlights=(1.1, 1.0, 0.9), hue_shift=25, saturation=30,
)
"""A ``ColorGrade`` setting that moves every control away from identity."""


@dataclass(frozen=True)
class StageKind:
    """One stage in one mode: ``build(**controls)`` makes it, ``example()`` makes it with a strong setting."""

    build: Callable[..., nn.Module]
    example_controls: dict = field(default_factory=dict)

    def example(self) -> nn.Module:
        """The stage built with :attr:`example_controls`."""
        return self.build(**self.example_controls)

    @property
    def display_referred(self) -> bool:
        """Whether the stage's output is display-referred (inside [0, 1]): it ends in a tone mapper or a display LUT."""
        return is_display_referred(self.example())


@functools.lru_cache(maxsize=1)
def _strong_lut() -> LUT3D:
    # baking measures the LUT's error (seconds): once, then copies. A 9³ table of this look misses it
    # by far (its report says so); the example is there to be extreme, not faithful.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LUTAccuracyWarning)
        return bake_lut(nn.Sequential(ColorGrade(aces=True, **STRONG_GRADE), ToneMap("aces")), size=9)


def _lookup(interpolation: str) -> LUT3D:
    """A 9³ LUT of the strong grade in ACES followed by the ACES tone mapper, looked up with ``interpolation``."""
    lut = copy.deepcopy(_strong_lut())
    lut.interpolation = interpolation
    return lut


def _warm_table() -> torch.Tensor:
    """A 9³ creative table: warmer, with more contrast in sRGB codes (a smoothstep on each channel)."""
    codes = identity_table(9)
    return (codes * codes * (3.0 - 2.0 * codes) * torch.tensor([1.0, 0.95, 0.85])).clamp(0.0, 1.0)


def _kinds() -> dict[str, StageKind]:
    """Every stage in each of its modes, with its example setting (see :data:`STAGE_KINDS`)."""
    kinds = {f"tonemap-{mode}": StageKind(partial(ToneMap, mode)) for mode in TONEMAP_MODES}
    kinds["grade-linear"] = StageKind(ColorGrade, STRONG_GRADE)
    kinds["grade-aces"] = StageKind(partial(ColorGrade, aces=True), STRONG_GRADE)
    kinds.update({f"primary-{style}": StageKind(partial(PrimaryGrade, style), dict(contrast=(1.3, 1.2, 1.1), saturation=1.4)) for style in STYLES})
    kinds["autoexposure-log"] = StageKind(partial(AutoExposure, metering="log"))
    kinds["autoexposure-reinhard"] = StageKind(partial(AutoExposure, metering="mean", operator="reinhard"))
    kinds["autoexposure-histogram"] = StageKind(partial(AutoExposure, metering="histogram", metering_mask="center"),
                                                dict(min_ev=-4.0, max_ev=4.0, compensation=0.5, compensation_curve=((-8.0, -3.0), (-1.0, 0.0))))
    kinds["autoexposure-mask"] = StageKind(partial(AutoExposure, metering="log", metering_mask=torch.tensor([[0.0, 1.0, 0.0], [1.0, 2.0, 1.0]])),
                                           dict(compensation=-0.5))
    kinds.update({f"bloom-{mode}": StageKind(partial(Bloom, mode=mode), dict(intensity=0.8, threshold=0.8, downscale_limit=1,
                                                                               bicubic_upsampling=mode == "scattering"))
                  for mode in BLOOM_MODES})
    kinds["convolution-bloom"] = StageKind(partial(ConvolutionBloom, torch.ones(1, 3, 3)), dict(intensity=0.8, threshold=0.8))
    kinds["dither"] = StageKind(Dither)
    kinds["look-lut"] = StageKind(partial(LookLUT, _warm_table()), dict(contribution=0.7))
    kinds.update({f"lut-{interpolation}": StageKind(partial(_lookup, interpolation)) for interpolation in INTERPOLATIONS})
    kinds["postfx"] = StageKind(PostFX, dict(exposure={}, bloom={"mode": "scattering", "intensity": 0.5},
                                             grade={"aces": True, **STRONG_GRADE}, tonemap="aces"))
    return kinds


STAGE_KINDS: dict[str, StageKind] = _kinds()
"""``{name: StageKind}``: every tone mapper, the grade in Rec.709 and in ACES, both primary grade styles, both
eye-adaptation operators, histogram metering with its limits and curve, a user's metering mask, every bloom
composite, convolution bloom, dither, the LUT with each interpolation, a creative look LUT, and a whole ``PostFX`` look."""


def learnable(module: nn.Module) -> dict:
    """Make every continuous control of every stage in ``module`` an ``nn.Parameter`` holding its value: number
    controls, tensor-valued ones (a convolution bloom's kernel) and a LUT's table. A control the stage takes only as a
    number is left as it is (ACES 2.0's peak luminance, whose tables are cached per value: the stage refuses a
    parameter with ``TypeError``). Returns the parameters by ``"Stage.control"``.

    Examples:
        >>> sorted(learnable(STAGE_KINDS["tonemap-neutral_hdr"].example()))
        ['ToneMap.hue_shift', 'ToneMap.min_luminance', 'ToneMap.paper_white', 'ToneMap.peak_luminance']
        >>> learnable(STAGE_KINDS["tonemap-aces2_hdr"].example())
        {}
    """
    made = {}
    for stage in module.modules():
        if not isinstance(stage, Stage):
            continue
        values = {name: getattr(stage, name) for name, control in stage.control_table().items()
                  if control.kind == "number" or isinstance(getattr(stage, name), torch.Tensor)}
        if isinstance(stage, LUT3D):
            stage.table = nn.Parameter(stage.table.detach().clone())
            made[f"{type(stage).__name__}.table"] = stage.table
        for name, value in values.items():
            if value is None or (isinstance(value, torch.Tensor) and not value.is_floating_point()):
                continue
            parameter = nn.Parameter(torch.as_tensor(value, dtype=torch.float32).detach().clone())
            try:
                setattr(stage, name, parameter)
            except TypeError:  # refused by the stage's rules between controls, after it was stored
                setattr(stage, name, value)
                continue
            made[f"{type(stage).__name__}.{name}"] = parameter
    return made
