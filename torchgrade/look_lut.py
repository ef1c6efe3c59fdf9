"""``LookLUT``: a creative 3D LUT on the tone-mapped image, with a contribution, as Unity URP's Color Lookup.

A colourist's show LUT (a ``.cube`` or CLF file), a LUT made in a grading application, or any
``(S, S, S, 3)`` table, applied to display-referred light after tone mapping. Unity URP's HDR grading
path (``ApplyColorGrading`` in URP's ``Common.hlsl``) defines it: clamp the tone-mapped colour to [0, 1],
encode it as sRGB, look it up, blend with the contribution in sRGB codes and decode::

    c = sRGB(clamp(x, 0, 1))
    y = sRGB⁻¹(clamp(c + contribution · (LUT(c) - c), 0, 1))

``encoding="linear"`` looks the display-linear values up directly (a LUT authored for linear input).
Unreal's Color Grading LUT with its intensity is the same blend. The LUT is a
:class:`~torchgrade.LUT3D` stage, so its interpolation (a control of the LUT) and its ONNX forms are the
baked LUT's.

Examples:
    >>> import torch
    >>> from torchgrade.lut import LUT3D, identity_table
    >>> warm = identity_table(9) * torch.tensor([1.0, 0.9, 0.8])  # a table that cools nothing and warms everything
    >>> look = LookLUT(warm, contribution=0.5)
    >>> out = look(torch.full((1, 3, 1, 1), 0.5))
    >>> out[0, 0, 0, 0].item() > out[0, 2, 0, 0].item()
    True
"""

from __future__ import annotations

import functools
from pathlib import Path

import torch
from torch import nn

from .color import linear_to_srgb, srgb_to_linear
from .core import Param, check_image, is_constant, sanitize, scalar_param, to_input_dtype, working_dtype
from .lut import LUT3D, identity_table
from .runtime import in_strips
from .stage import Control, Stage, plain

__all__ = ["LookLUT", "LookLUTForm", "look_lut", "lut_settings", "LOOK_ENCODINGS", "read_lut_file"]

LOOK_ENCODINGS = ("srgb", "linear")
"""How the display-referred image is encoded for the LUT: sRGB codes (Unity URP, most show LUTs) or display-linear."""


def look_lut(image: torch.Tensor, lookup, contribution: Param = 1.0, encoding: str = "srgb") -> torch.Tensor:
    """Apply a creative LUT ``lookup`` (a :class:`~torchgrade.LUT3D`, or its export form) to display-referred
    ``image`` with ``contribution`` in [0, 1] (a number or per sample ``(B,)``); see the module docstring.

    Examples:
        >>> from torchgrade.lut import LUT3D, identity_table
        >>> image = torch.rand(2, 3, 4, 4)
        >>> torch.allclose(look_lut(image, LUT3D(identity_table(5))), image, atol=1e-6)  # the identity LUT
        True
        >>> torch.allclose(look_lut(image, LUT3D(identity_table(5) * 0.5), contribution=0.0), image, atol=1e-6)  # no blend
        True
    """
    check_image(image)
    x = sanitize(working_dtype(image)).clamp(0.0, 1.0)
    coded = linear_to_srgb(x) if encoding == "srgb" else x
    amount = scalar_param(contribution, coded, "contribution")
    blended = (coded + amount * (lookup(coded) - coded)).clamp(0.0, 1.0)
    return to_input_dtype(srgb_to_linear(blended) if encoding == "srgb" else blended, image)


def read_lut_file(path) -> LUT3D:
    """A ``.cube`` or CLF (``.clf``, ``.ctf``-free) file as a :class:`~torchgrade.LUT3D`, chosen by its suffix.

    Examples:
        >>> read_lut_file("look.png")
        Traceback (most recent call last):
        ...
        ValueError: a look LUT is a .cube or .clf file, got 'look.png'
    """
    suffix = Path(path).suffix.lower()
    if suffix not in (".cube", ".clf"):
        raise ValueError(f"a look LUT is a .cube or .clf file, got {str(path)!r}")
    # torchgrade.io imports OpenEXR, which takes longer to import than torchgrade: it is imported when a file is read.
    from .io import read_clf, read_cube

    return read_cube(path) if suffix == ".cube" else read_clf(path)


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

    def __init__(self, lut, contribution: Param = 1.0, encoding: str = "srgb", interpolation=None):
        super().__init__()
        self.source = str(lut) if isinstance(lut, (str, Path)) else None
        self.lut = _as_lut(lut)
        if interpolation is not None:
            self.lut.interpolation = interpolation
        self.init_controls(contribution=contribution, encoding=encoding)

    @property
    def is_identity(self) -> bool:
        """True at contribution 0 (a LUT table is not checked for being the identity)."""
        return is_constant(self.contribution, 0.0)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        call = functools.partial(look_lut, lookup=self.lut, contribution=self.contribution, encoding=self.encoding)
        return in_strips(call, image, (self.contribution, self.lut.table))

    def export_form(self, backend: str = "strip") -> nn.Module:
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

    def __init__(self, stage: LookLUT, lookup: nn.Module):
        super().__init__()
        self.stage, self.lookup = stage, lookup

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return look_lut(image, self.lookup, self.stage.contribution, self.stage.encoding)


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
