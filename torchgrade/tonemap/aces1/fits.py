"""Fits of ACES 1.x as games ship them: Unity's (``AcesTonemap``), Stephen Hill's and Krzysztof Narkowicz's."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ...base.planes import each_plane, joined, matrix_on, rows_into
from ...color import AP1_LUMINANCE, MATRICES, MATRIX_VALUES
from ...runtime import affine, constant, values_of
from .rrt import (
    AP1_TO_REC709,
    DIM_SURROUND_GAMMA,
    ODT_SAT_FACTOR,
    RRT_SAT_FACTOR,
    rrt_glow_and_red_modifier_planes,
    smoothstep_hue_weight,
)
from ..base import apply_rows, display, limited

__all__ = ["aces_fitted", "aces", "aces_hill", "aces_narkowicz"]

_ACES_FIT = dict(a=2.785085, b=0.107772, c=2.936045, d=0.887122, e=0.806889)
"""Luminance fit of RRT 1.0.3 + ODT RGBmonitor_100nits_dim (Unity AcesTonemap; RMSE 0.0013)."""


def _lerp_to_luminance(factor: float) -> torch.Tensor:
    """``lerp(Y, rgb, factor) = factor rgb + (1 - factor) Y`` with Unity's AP1 luminance, as a float64 matrix
    (Unity's RRT/ODT desaturation)."""
    weights = torch.tensor(AP1_LUMINANCE, dtype=torch.float64)
    return factor * torch.eye(3, dtype=torch.float64) + (1.0 - factor) * weights.expand(3, 3)


_RRT_DESATURATE = _lerp_to_luminance(RRT_SAT_FACTOR)
_ODT_TAIL = AP1_TO_REC709 @ _lerp_to_luminance(ODT_SAT_FACTOR) @ MATRICES["xyz_to_ap1"]
_RRT_DESATURATE_VALUES, _ODT_TAIL_VALUES = values_of(_RRT_DESATURATE), values_of(_ODT_TAIL)
"""After the dim surround: XYZ → AP1, the ODT's desaturation and AP1 → Rec.709, folded into one matrix."""


def _fit(x: torch.Tensor) -> torch.Tensor:
    """The luminance fit :data:`_ACES_FIT`: ``x (a x + b) / (x (c x + d) + e)``, in five operations."""
    k = _ACES_FIT
    return x * affine(x, k["a"], k["b"]) / torch.addcmul(constant(k["e"], x), x, affine(x, k["c"], k["d"]))


def _dim_surround_planes(big_x: torch.Tensor, big_y: torch.Tensor, big_z: torch.Tensor) -> tuple:
    """Unity's ``darkSurround_to_dimSurround`` on the planes of XYZ: ``Y → Y^0.9811`` in xyY, chromaticity kept, with 1e-4
    floors (the power of ``Y`` clamped to [0, 65504] by ``hardtanh``, whose gradient is 0 at its bounds: finite at 0, as
    :func:`~torchgrade.color.safe_pow`'s)."""
    total = (big_x + big_y + big_z).clamp_min(1e-4)
    x, y = big_x / total, big_y / total
    new_y = F.hardtanh(big_y, 0.0, 65504.0) ** DIM_SURROUND_GAMMA
    m = new_y / y.clamp_min(1e-4)
    return x * m, new_y, (1.0 - x - y) * m


def aces_fitted(aces):
    """Unity ``AcesTonemap`` on ACES2065-1 input: RRT glow and red modifier, desaturation, the luminance
    fit ``x (a x + b) / (x (c x + d) + e)`` of RRT+ODT (RGB monitor, 100 nits, dim), dim surround,
    ODT desaturation, then AP1 → XYZ → D60→D65 → Rec.709; not clipped.

    ``aces`` is an image or its three planes (a tuple), and the result takes its form. The RRT runs on the image's
    planes (:func:`~torchgrade.tonemap.aces1.rrt.rrt_glow_and_red_modifier_planes`), which go into the next matrix as
    they are; on planes, every matrix gives planes (:func:`~torchgrade.base.planes.rows_into`), so that a compiler
    keeps the chain in one loop.

    Examples:
        >>> round(float(aces_fitted(torch.zeros(3, 1, 1)).max()), 6)
        0.0
        >>> image = torch.rand(3, 2, 2) * 4
        >>> bool(torch.allclose(torch.cat(aces_fitted(image.split(1, dim=-3)), dim=-3), aces_fitted(image), atol=1e-6))
        True
    """
    on_planes = isinstance(aces, tuple)
    planes = rrt_glow_and_red_modifier_planes(aces if on_planes else aces.split(1, dim=-3), smoothstep_hue_weight)
    ap1 = rows_into(MATRIX_VALUES["ap0_to_ap1"], planes, on_planes)
    acescg = matrix_on(_RRT_DESATURATE_VALUES, each_plane(lambda plane: plane.clamp_min(0.0), ap1))
    xyz = matrix_on(MATRIX_VALUES["ap1_to_xyz"], each_plane(_fit, acescg))
    return rows_into(_ODT_TAIL_VALUES, _dim_surround_planes(*(xyz if on_planes else xyz.split(1, dim=-3))), on_planes)


def aces(image: torch.Tensor, clip: bool = True, *, planes: bool = False) -> torch.Tensor:
    """ACES filmic tone mapping as Unity does it: ``AcesTonemap(unity_to_ACES(min(x, 60)))`` (HDR §3.5).

    ``planes``: computed on the image's three planes (:func:`aces_fitted`), the form a compiler fuses into one loop.

    Examples:
        >>> [round(v, 3) for v in aces(torch.tensor([0.18, 1.0, 100.0]).expand(3, 1, 3))[0, 0].tolist()]
        [0.108, 0.63, 0.945]
    """
    scene = limited(image)
    linear = aces_fitted(matrix_on(MATRIX_VALUES["srgb_to_ap0"], scene.split(1, dim=-3) if planes else scene))
    return joined(each_plane(lambda plane: display(plane, clip), linear))


_HILL_INPUT = ((0.59719, 0.35458, 0.04823), (0.07600, 0.90834, 0.01566), (0.02840, 0.13383, 0.83777))
_HILL_OUTPUT = ((1.60475, -0.53108, -0.07367), (-0.10208, 1.10813, -0.00605), (-0.00327, -0.07276, 1.07602))


def aces_hill(image: torch.Tensor, clip: bool = True) -> torch.Tensor:
    """Stephen Hill's ACES fit (BakingLab ``ACES.hlsl``, ``ACESFitted``): sRGB → RRT-saturation/AP1
    input matrix, ``RRTAndODTFit(v) = (v (v + 0.0245786) - 0.000090537) / (v (0.983729 v + 0.432951) + 0.238081)``,
    output matrix back to linear Rec.709 (ODT sRGB, 100 nits).

    Examples:
        >>> [round(v, 3) for v in aces_hill(torch.tensor([0.18, 1.0, 5.0]).expand(3, 1, 3))[0, 0].tolist()]
        [0.106, 0.619, 0.931]
    """
    v = apply_rows(_HILL_INPUT, limited(image))
    fitted = (v * (v + 0.0245786) - 0.000090537) / (v * (0.983729 * v + 0.4329510) + 0.238081)
    return display(apply_rows(_HILL_OUTPUT, fitted), clip)


_NARKOWICZ_EXPOSURE = 0.6
"""Narkowicz's input scale: his curve was fitted to ACES with the input exposed by 0.6 (the blog's ``x *= 0.6``)."""


def aces_narkowicz(image: torch.Tensor, clip: bool = True) -> torch.Tensor:
    """Krzysztof Narkowicz's ACES luminance fit ("ACES Filmic Tone Mapping Curve", 2016), per channel:
    ``x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)`` with ``x = 0.6 · c``.

    Examples:
        >>> [round(v, 3) for v in aces_narkowicz(torch.tensor([0.18, 1.0, 5.0]).expand(3, 1, 3))[0, 0].tolist()]
        [0.14, 0.673, 0.954]
    """
    x = limited(image) * _NARKOWICZ_EXPOSURE
    return display(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), clip)
