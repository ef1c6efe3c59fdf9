"""Tone mapping: scene-referred linear Rec.709 in, display-referred linear Rec.709 in [0, 1] out.

The engine curves clamp their input to ``[0, limit]`` first: negative (out-of-gamut) values map to
black and, as in the source documents, values above 60 are treated as 60 (beyond it every curve here is
within 1/255 of its asymptote, and half-precision evaluation stays finite). The ACES renderings
(``aces_reference``, ``aces2``, ``aces2_hdr``) take every value as their reference implementations do:
they handle out-of-gamut colours themselves. The output is clipped
to [0, 1] unless a caller asks for the unclipped display values (``clip=False``); sRGB encoding is
a separate step (:func:`torchgrade.color.linear_to_srgb`).

One file per family (Reinhard, filmic, ACES fits, ACES 1.x reference, ACES 2.0, AgX, Khronos PBR
Neutral, Unity's HDR range reduction),
the registry of modes in :mod:`~torchgrade.tonemap.registry`, the :class:`ToneMap` stage in
:mod:`~torchgrade.tonemap.layer`.

Examples:
    >>> import torch
    >>> ToneMap("reinhard")(torch.ones(1, 3, 1, 1)).flatten().tolist()
    [0.5, 0.5, 0.5]
"""

from .aces1.reference import aces_reference
from .aces2.curves import aces2_hdr, aces2_sdr
from .aces1.fits import aces, aces_fitted, aces_hill, aces_narkowicz
from .agx_curves import agx, agx_godot
from .base import TONEMAP_INPUT_LIMIT, ToneMapper, no_tonemap
from .hdr_range import bt2390_eetf, neutral_hdr
from .filmic_curves import filmic, hable, neutral, unreal_filmic
from .khronos_pbr import khronos_pbr_neutral
from .layer import ToneMap
from .registry import HDR_MODES, TONE_MAPPERS, TONEMAP_MODES, tone_mapper, tonemap
from .reinhard_curves import reinhard, reinhard_extended, reinhard_luminance

__all__ = [
    "TONEMAP_MODES",
    "TONE_MAPPERS",
    "HDR_MODES",
    "TONEMAP_INPUT_LIMIT",
    "ToneMap",
    "ToneMapper",
    "tone_mapper",
    "tonemap",
    "no_tonemap",
    "reinhard",
    "reinhard_extended",
    "reinhard_luminance",
    "neutral",
    "hable",
    "filmic",
    "unreal_filmic",
    "aces",
    "aces_fitted",
    "aces_hill",
    "aces_narkowicz",
    "aces_reference",
    "aces2_sdr",
    "aces2_hdr",
    "neutral_hdr",
    "bt2390_eetf",
    "agx",
    "agx_godot",
    "khronos_pbr_neutral",
]
