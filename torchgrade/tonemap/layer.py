"""``ToneMap``: the tone mapping stage, whose controls are its mode's."""

from __future__ import annotations

import inspect

import torch

from ..base.params import Param
from ..base.controls import Control, controls_signature
from ..base.stage import Stage
from ..runtime.strips import pixelwise
from .registry import TONE_MAPPERS, TONEMAP_MODES, check_curve_params, tone_mapped

__all__ = ["ToneMap"]


class ToneMap(Stage):
    """Tone mapping layer: ``ToneMap(mode="neutral", clip=True, **curve_params)``; see :data:`TONEMAP_MODES`.

    Each mode takes the parameters of its curve, with that curve's defaults (``white_point``: 4 for
    ``reinhard_extended`` and ``reinhard_luminance``, 11.2 for ``hable`` and ``filmic``;
    ``exposure_bias``: 2; Hable's six ``filmic`` parameters; Unreal's ``slope``, ``toe``, ``shoulder``,
    ``black_clip``, ``white_clip``) and ranges (:data:`~torchgrade.tonemap.TONE_MAPPERS`). Each accepts
    a number, a 0-d or per-sample ``(B,)`` tensor, or an ``nn.Parameter`` to learn it; ``None`` means
    the mode's default. Assigning ``mode`` resets the curve parameters to the new mode's defaults.
    ``clip=False`` leaves the display values unclipped (a LUT baked through it clips after its lookup).

    Examples:
        >>> import torch
        >>> layer = ToneMap("reinhard_extended", white_point=2.0)
        >>> layer(torch.full((1, 3, 1, 1), 1.0)).flatten().tolist()
        [0.625, 0.625, 0.625]
        >>> layer.to_config()
        {'mode': 'reinhard_extended', 'white_point': 2.0}
        >>> layer.mode = "hable"
        >>> layer.to_config()
        {'mode': 'hable', 'exposure_bias': 2.0, 'white_point': 11.2}
        >>> ToneMap("agx", slope=0.9)
        Traceback (most recent call last):
        ...
        ValueError: tone mapper 'agx' takes no 'slope'; it takes no parameters
    """

    per_pixel = True

    controls = {"mode": Control("neutral", TONEMAP_MODES), "clip": Control(True)}
    """The controls of every mode; :meth:`control_table` adds the mode's curve parameters."""

    display_referred = True
    mode: str
    clip: bool

    def __init__(
        self, mode: str = "neutral", white_point: Param | None = None, exposure_bias: Param | None = None, clip: bool = True, **curve_params: Param
    ):
        super().__init__()
        given = {"white_point": white_point, "exposure_bias": exposure_bias, **curve_params}
        self._use_mode(mode, bool(clip), {name: value for name, value in given.items() if value is not None})

    def _use_mode(self, mode: str, clip: bool, curve_params: dict) -> None:
        """Replace every control by ``mode``'s, from ``curve_params`` and the mode's defaults."""
        check_curve_params(mode, curve_params)
        for name in self._control_names:
            delattr(self, name)
        self._control_names = []
        self.mode = mode  # the table depends on it
        self.init_controls(mode=mode, clip=clip, **curve_params)

    def control_table(self) -> dict:
        return {**type(self).controls, **TONE_MAPPERS[self.mode].controls}

    def check_together(self) -> None:
        """Prepare what the mode builds per control value (ACES 2.0's gamut tables), outside any forward, and keep it:
        a shared cache drops tables no stage holds, and a compiled forward cannot build them."""
        entry = TONE_MAPPERS[self.mode]
        if all(hasattr(self, name) for name in entry.controls):
            self._prepared = None if entry.prepare is None else entry.prepare(**{name: getattr(self, name) for name in entry.controls})

    def __getstate__(self):
        """A saved or copied tone map leaves its prepared tables behind; loading prepares them again (:meth:`check_together`)."""
        state = super().__getstate__()
        state.pop("_prepared", None)
        return state

    @classmethod
    def config_table(cls, config: dict) -> dict:
        """The controls of every mode, and the curve parameters of the config's mode (when it names a known one)."""
        mode = config.get("mode", cls.controls["mode"].default)
        return {**cls.controls, **(TONE_MAPPERS[mode].controls if isinstance(mode, str) and mode in TONE_MAPPERS else {})}

    def set_param(self, name: str, value) -> None:
        if name == "mode" and value != self.mode:
            self._use_mode(value, self.clip, {})
        else:
            super().set_param(name, value)

    @property
    def always_in_config(self) -> tuple:
        """The mode and every curve parameter: a tone mapper's config names its whole curve."""
        return ("mode", *TONE_MAPPERS[self.mode].controls)

    @property
    def is_identity(self) -> bool:
        """Tone mapping is never skipped: even ``"none"`` clips to the display range."""
        return False

    @property
    def expects_hdr(self) -> bool:
        """True when a curve maps scene-referred input (any mode but ``"none"``): a LUT baked through it needs an HDR shaper."""
        return self.mode != "none"

    @pixelwise(planes=True)
    def forward(self, image: torch.Tensor, *, nan_free: bool = False, planes: bool = False) -> torch.Tensor:
        return tone_mapped(image, nan_free=nan_free, planes=planes, **self.params())


def _signature() -> inspect.Signature:
    """``(mode, white_point, exposure_bias, clip, *, <every other curve parameter of any mode>)``, ``None`` meaning the mode's default."""
    positional = inspect.Parameter.POSITIONAL_OR_KEYWORD
    leading = [
        inspect.Parameter("mode", positional, default="neutral"),
        inspect.Parameter("white_point", positional, default=None),
        inspect.Parameter("exposure_bias", positional, default=None),
        inspect.Parameter("clip", positional, default=True),
    ]
    named = {parameter.name for parameter in leading}
    others = {name: Control(None) for entry in TONE_MAPPERS.values() for name in entry.controls if name not in named}
    return controls_signature(others, leading=tuple(leading))


ToneMap.__signature__ = _signature()
