"""The display-referred stages: ``LookLUT`` (a creative LUT after tone mapping), ``Dither`` and ``Display``."""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from ..base.params import Param, check_range, is_constant
from ..base.controls import Control, in_state_check, plain
from ..base.stage import Stage
from ..lut import LUT3D, identity_table
from ..runtime.strips import pixelwise
from .display import DISPLAY_ENCODINGS, DISPLAY_PRIMARIES, HLG_PEAK_RANGE, encode_display
from .dither import DEFAULT_AMPLITUDE, DITHER_CONTROLS, dither_pattern, dithered
from .look_lut import LOOK_ENCODINGS, look_lut, read_lut_file

__all__ = ["Display", "Dither", "LookLUT", "LookLUTForm", "lut_settings"]


class LookLUT(Stage):
    """A creative LUT after tone mapping: ``LookLUT(lut, contribution=1.0, encoding="srgb", interpolation=None)``.

    Args:
        lut: a :class:`~torchgrade.LUT3D`; the path of a ``.cube`` or CLF file; a ``(S, S, S, 3)`` table (indexed
            ``[b, g, r]``, entries on [0, 1] inputs); an int ``S``, the identity ``S³`` table (to be learned); or a
            dict of a LUT's settings (:func:`lut_settings`) with its ``table`` (nested lists) or without it (the
            identity, for ``load_state_dict`` to fill).
        contribution: the blend in [0, 1] (Unity's Contribution, Unreal's intensity); a number, ``(B,)`` tensor
            or ``nn.Parameter``; 0 makes the stage an identity (not computed, not exported).
        encoding: ``"srgb"`` or ``"linear"`` (:data:`LOOK_ENCODINGS`).
        interpolation: the LUT's interpolation (``"tetrahedral"`` or ``"trilinear"``); a file's or the LUT's own by default.

    ``to_config()`` names the file a LUT was read from (``{"lut": "show.cube", ...}``), or holds the table as
    nested lists.

    Examples:
        >>> from torchgrade.lut import identity_table
        >>> LookLUT(identity_table(3), contribution=0.25).to_config()["contribution"]
        0.25
        >>> LookLUT(5, contribution=0.0).is_identity
        True
    """

    controls = {
        "contribution": Control(1.0, (0.0, 1.0)),
        "encoding": Control("srgb", LOOK_ENCODINGS),
    }
    display_referred = True
    per_pixel = True
    contribution: Param
    encoding: str

    def __init__(self, lut, contribution: Param = 1.0, encoding: str = "srgb", interpolation=None):
        super().__init__()
        self.source = str(lut) if isinstance(lut, (str, Path)) else None
        self.lut = _as_lut(lut).looked_up_with(interpolation)  # a LUT3D given keeps its own interpolation
        self.init_controls(contribution=contribution, encoding=encoding)

    @property
    def is_identity(self) -> bool:
        """True at contribution 0 (a LUT table is not checked for being the identity)."""
        return is_constant(self.contribution, 0.0)

    @pixelwise
    def forward(self, image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
        return look_lut(image, self.lut, self.contribution, self.encoding, nan_free=nan_free)

    def export_form(self, backend: str = "slices") -> nn.Module:
        """The module an ONNX export traces: the blend around the LUT's own export form in ``backend``'s graph form."""
        return LookLUTForm(self, self.lut.export_form(backend=backend))

    def to_config(self) -> dict:
        """The file the LUT was read from, or its settings and table (nested lists), and the controls off their defaults."""
        lut = self.source if self.source is not None else {**lut_settings(self.lut), "table": plain(self.lut.table)}
        interpolation = {} if self.lut.interpolation == "tetrahedral" or isinstance(lut, dict) else {"interpolation": self.lut.interpolation}
        return {"lut": lut, **super().to_config(), **interpolation}

    def state_config(self) -> dict:
        """What a saved look's state records of this stage: the LUT's settings without its table, which the state
        dict holds (so loading needs neither the file nor a second copy of the table)."""
        return {**super().to_config(), "lut": lut_settings(self.lut)}

    def extra_repr(self) -> str:
        source = repr(self.source) if self.source is not None else f"table of size {self.lut.size}"
        return f"lut={source}, " + ", ".join(f"{k}={v!r}" for k, v in super().to_config().items())


class LookLUTForm(nn.Module):
    """What an ONNX export traces for a :class:`LookLUT`: :func:`look_lut` around the LUT's export form."""

    per_pixel = True
    takes_nan_free = True  # as the stage (Stage.takes_nan_free)

    def __init__(self, stage: LookLUT, lookup: nn.Module):
        super().__init__()
        self.stage, self.lookup = stage, lookup

    def forward(self, image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
        return look_lut(image, self.lookup, self.stage.contribution, self.stage.encoding, nan_free=nan_free)


def lut_settings(lut: LUT3D) -> dict:
    """A LUT's size, shaper, domain, curve and output settings as plain values: everything but its table.

    Examples:
        >>> lut_settings(LUT3D(identity_table(3), interpolation="trilinear"))["interpolation"]
        'trilinear'
    """
    return {"size": lut.size, "shaper": lut.shaper, "domain": [plain(lut.domain_min), plain(lut.domain_max)],
            "output_range": plain(lut.output_range), "curve": plain(lut.curve), "curve_range": plain(lut.curve_range),
            "output_encoding": lut.output_encoding, "interpolation": lut.interpolation}


def _lut_from_settings(settings: dict) -> LUT3D:
    """The LUT :func:`lut_settings` describes, with ``settings["table"]`` as its table or else the identity."""
    known = {"size", "shaper", "domain", "output_range", "curve", "curve_range", "output_encoding", "interpolation", "table"}
    unknown = sorted(set(settings) - known)
    if unknown or "size" not in settings:
        raise ValueError(f"a look LUT's settings take size and {', '.join(sorted(known - {'size'}))}; got {sorted(settings)}")
    size = settings["size"]
    if isinstance(size, bool) or not isinstance(size, int):
        raise ValueError(f"lut.size must be an integer, got {size!r}")
    table = settings.get("table")
    table = identity_table(size) if table is None else torch.tensor(table, dtype=torch.float32)
    if table.shape[:3] != (size, size, size):
        raise ValueError(f"lut.table must have shape ({size}, {size}, {size}, 3), got {tuple(table.shape)}")
    curve = settings.get("curve")
    domain = settings.get("domain")
    return LUT3D(table, settings.get("shaper", "linear"), None if domain is None else tuple(torch.tensor(d) for d in domain),
                 settings.get("output_range"), None if curve is None else torch.tensor(curve, dtype=torch.float32),
                 settings.get("curve_range", (0.0, 1.0)), output_encoding=settings.get("output_encoding", "linear"),
                 interpolation=settings.get("interpolation", "tetrahedral"))


def _as_lut(lut) -> LUT3D:
    """A :class:`LookLUT`'s ``lut`` argument as a ``LUT3D``."""
    if isinstance(lut, LUT3D):
        return lut
    if isinstance(lut, dict):
        return _lut_from_settings(lut)
    if isinstance(lut, (str, Path)):
        return read_lut_file(lut)
    if isinstance(lut, int) and not isinstance(lut, bool):
        return LUT3D(identity_table(lut))
    if isinstance(lut, (list, tuple)):
        lut = torch.tensor(lut, dtype=torch.float32)
    if isinstance(lut, torch.Tensor):
        return LUT3D(lut.float())
    raise ValueError(f"lut must be a LUT3D, a .cube/.clf path, an (S, S, S, 3) table, a size or a dict of settings, got {type(lut).__name__}")


class Dither(Stage):
    """Deband dithering layer, after tone mapping: ``Dither(amplitude=1/255, seed=0, size=64)``.

    ``amplitude`` (number, ``(B,)`` tensor or ``nn.Parameter``, 0..16/255) is the half-width of the
    triangular noise in sRGB values (1/255: one 8-bit code); 0 makes the layer an identity. ``seed``
    (an int) draws the noise tile of ``size x size`` pixels, so the same seed gives the same noise;
    the functional :func:`~torchgrade.output.dither.dither` takes any tile, for instance from :func:`dither_pattern` with a
    ``torch.Generator``.

    Examples:
        >>> layer = Dither(seed=3, size=16)
        >>> layer.to_config()
        {'amplitude': 0.00392156862745098, 'seed': 3, 'size': 16}
        >>> Dither(amplitude=0.0).is_identity
        True
    """

    controls = DITHER_CONTROLS
    always_in_config = ("amplitude", "seed", "size")
    amplitude: Param
    seed: int
    size: int
    pattern: torch.Tensor

    def __init__(self, amplitude: Param = DEFAULT_AMPLITUDE, seed: int = 0, size: int = 64):
        super().__init__()
        self.init_controls(amplitude=amplitude, seed=seed, size=size)
        self.draw_pattern()

    def draw_pattern(self) -> None:
        """Draw the noise tile from ``seed`` (a buffer, so it follows ``.to()``; not saved: the seed rebuilds it).

        A tile redrawn after ``.to()`` takes the device and dtype of the one it replaces.
        """
        pattern = dither_pattern(self.size, torch.Generator().manual_seed(self.seed))
        previous = self._buffers.get("pattern")
        self.register_buffer("pattern", pattern if previous is None else pattern.to(previous), persistent=False)

    def set_param(self, name: str, value) -> None:
        super().set_param(name, value)
        if name in ("seed", "size"):
            self.draw_pattern()

    def check_state(self) -> None:
        """Also draw the tile again from the checked ``seed`` and ``size``: a loaded file's tile is not trusted (a tile
        of NaN made every pixel NaN), and the seed alone defines it."""
        super().check_state()
        self.draw_pattern()

    @property
    def is_identity(self) -> bool:
        """True at amplitude 0 (then skipped by ``PostFX`` and not exported)."""
        return is_constant(self.amplitude, 0.0)

    def forward(self, image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
        return dithered(image, self.pattern, self.amplitude, nan_free=nan_free)


class Display(Stage):
    """Display encoding layer, after tone mapping (and dither): ``Display(encoding="srgb", primaries="rec709",
    peak_luminance=100, input_primaries="rec709")``; see :func:`encode_display`.

    In a :class:`~torchgrade.PostFX` after an HDR tone mapper, ``peak_luminance`` and
    ``input_primaries`` default to the tone mapper's (``PostFX(tonemap={"mode": "neutral_hdr"},
    display={"encoding": "pq", "primaries": "rec2020"})``).

    Examples:
        >>> layer = Display("pq", "rec2020", peak_luminance=1000.0, input_primaries="rec2020")
        >>> round(float(layer(torch.full((1, 3, 1, 1), 0.1))[0, 0, 0, 0]), 4)  # 100 cd/m²
        0.5081
        >>> layer.to_config()
        {'encoding': 'pq', 'primaries': 'rec2020', 'peak_luminance': 1000.0, 'input_primaries': 'rec2020'}
    """

    controls = {
        "encoding": Control("srgb", DISPLAY_ENCODINGS),
        "primaries": Control("rec709", DISPLAY_PRIMARIES),
        "peak_luminance": Control(100.0, (1.0, 10000.0)),
        "input_primaries": Control("rec709", DISPLAY_PRIMARIES),
    }
    display_referred = True
    always_in_config = ("encoding",)
    peak_luminance: Param

    def __init__(self, encoding: str = "srgb", primaries: str = "rec709", peak_luminance: Param = 100.0, input_primaries: str = "rec709"):
        super().__init__()
        self.init_controls(encoding=encoding, primaries=primaries, peak_luminance=peak_luminance, input_primaries=input_primaries)

    def check_together(self) -> None:
        """An HLG display's peak within :data:`~torchgrade.output.display.HLG_PEAK_RANGE` (a learnable one is held
        there by the encoding)."""
        if self.encoding == "hlg" and not isinstance(self.peak_luminance, nn.Parameter) and in_state_check(self.peak_luminance):
            check_range(self.peak_luminance, "an HLG display's peak_luminance", *HLG_PEAK_RANGE)

    @property
    def is_identity(self) -> bool:
        """True for display-linear output in the input's primaries: the tone mapper already clipped it."""
        return self.encoding == "linear" and self.primaries == self.input_primaries

    def forward(self, image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
        """The display's signal of ``image``; ``nan_free`` (every stage's keyword) changes nothing: the encodings make
        no NaN pass of their own."""
        return encode_display(image, **self.params())
