"""The ACES 2.0 colour appearance model: Hellwig 2022 CAM (CAM16 structure) with the ACES changes.

Source: Academy aces-core ``Lib.Academy.OutputTransform.ctl`` and OpenColorIO
``ops/fixedfunction/ACES2`` (same constants): viewing conditions ``L_A = 100``, ``Y_b = 20``, dim
surround (``c = 0.59``, ``N_c = 0.9``), the "modified CAM16" primaries below instead of the CAT16
matrix, a cone compression with offset ``0.2713 * 100`` and scale ``4 * 100``, full adaptation to
the white of the RGB space, and no eccentricity term. ``J`` and ``M`` are on the 0-100 scale, ``h``
in degrees ``[0, 360)``.

Everything here is vectorised over ``(..., 3, H, W)`` or ``(..., 3)`` with the channel axis given,
and every power and square root is guarded so that gradients stay finite at 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from ...base.planes import apply_matrix, matrix_on_planes, rows_on_planes
from ...color import rgb_to_xyz_matrix, safe_pow, safe_sqrt
from ...runtime import affine, constant, values_of, where

__all__ = ["CAM16_PRIMARIES", "JMhParams", "jmh_params", "rgb_to_aab", "rgb_to_aab_planes", "aab_to_jmh",
           "aab_planes_to_jmh", "jmh_to_rgb", "jmh_to_rgb_planes", "y_to_j", "a_to_y"]

CAM16_PRIMARIES = ((0.8336, 0.1735), (2.3854, -1.4659), (0.087, -0.125), (0.333, 0.333))
"""The ACES 2.0 "modified CAM16" cone primaries and white (xy), replacing CAT16."""

REFERENCE_LUMINANCE = 100.0
L_A, Y_B = 100.0, 20.0
SURROUND_C, SURROUND_NC = 0.59, 0.9
J_SCALE = 100.0
NL_OFFSET = 0.2713 * 100.0
NL_SCALE = 4.0 * 100.0
RA_LIMIT = 0.99
"""Inverse cone compression saturates its argument here: the forward curve approaches 1 only at infinity."""

_BASE_CONE_TO_AAB = ((2.0, 1.0, 1.0 / 20.0), (1.0, -12.0 / 11.0, 1.0 / 11.0), (1.0 / 9.0, 1.0 / 9.0, -2.0 / 9.0))


def model_gamma() -> float:
    """``c z`` of the CAM: ``0.59 (1.48 + sqrt(Y_b / 100))``.

    Examples:
        >>> round(model_gamma(), 4)
        1.1371
    """
    return SURROUND_C * (1.48 + math.sqrt(Y_B / REFERENCE_LUMINANCE))


def cone_compress(v: torch.Tensor) -> torch.Tensor:
    """Signed post-adaptation compression ``sign(v) |v|^0.42 / (27.13 + |v|^0.42)``.

    Examples:
        >>> [round(v, 4) for v in cone_compress(torch.tensor([-1.0, 0.0, 1.0, 1e4])).tolist()]
        [-0.0355, 0.0, 0.0355, 0.6382]
    """
    p = safe_pow(v.abs(), 0.42)
    return _signed_as(p / (NL_OFFSET + p), v)


def cone_expand(v: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`cone_compress`, with ``|v|`` limited to 0.99 as in the reference.

    Examples:
        >>> [round(v, 4) for v in cone_expand(cone_compress(torch.tensor([0.5, 100.0]))).tolist()]
        [0.5, 100.0]
    """
    return _signed_as(_expanded(v.abs().clamp(max=RA_LIMIT)), v)


def _expanded(r: torch.Tensor, divisor: float = 1.0) -> torch.Tensor:
    """The magnitude of :func:`cone_expand` at a response ``r`` in ``[0, 0.99]``, over ``divisor``:
    ``(NL r / (1 - r))^(1/0.42) / divisor``, with ``divisor^0.42`` inside the power (one product and sum, a division)."""
    scale = divisor**0.42 / NL_OFFSET
    return safe_pow(r / affine(r, -scale, scale), 1.0 / 0.42)


def _signed_as(magnitude: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """``sign(v) magnitude`` for a magnitude that is 0 where ``v`` is (ONNX has no ``copysign``).

    Examples:
        >>> _signed_as(torch.tensor([2.0, 0.0]), torch.tensor([-1.0, 0.0])).tolist()
        [-2.0, 0.0]
    """
    return torch.sign(v) * magnitude


@dataclass(frozen=True)
class JMhParams:
    """float64 constants of the CAM for one RGB space (see :func:`jmh_params`).

    Examples:
        >>> from torchgrade.color import AP1_CHROMATICITIES
        >>> tuple(jmh_params(AP1_CHROMATICITIES).rgb_to_cone.shape)
        (3, 3)
    """

    rgb_to_cone: torch.Tensor
    cone_to_rgb: torch.Tensor
    cone_to_aab: torch.Tensor
    aab_to_cone: torch.Tensor
    f_l_n: float
    cz: float
    a_w_j: float
    values: dict = field(init=False, repr=False, compare=False)
    """The four matrices as tuples of floats by field name: what images are multiplied by (device constants)."""

    def __post_init__(self):
        names = ("rgb_to_cone", "cone_to_rgb", "cone_to_aab", "aab_to_cone")
        object.__setattr__(self, "values", {name: values_of(getattr(self, name)) for name in names})


def jmh_params(chromaticities) -> JMhParams:
    """CAM constants for RGB with the given primaries and white, adapted fully to that white.

    Examples:
        >>> from torchgrade.color import AP0_CHROMATICITIES
        >>> p = jmh_params(AP0_CHROMATICITIES)
        >>> round(p.cz, 4), round(p.f_l_n, 6)
        (1.1371, 0.007937)
    """
    k = 1.0 / (5.0 * L_A + 1.0)
    k4 = k**4
    f_l = 0.2 * k4 * (5.0 * L_A) + 0.1 * (1.0 - k4) ** 2 * (5.0 * L_A) ** (1.0 / 3.0)
    to_xyz = rgb_to_xyz_matrix(chromaticities)
    to_cam = torch.linalg.inv(rgb_to_xyz_matrix(CAM16_PRIMARIES)) @ to_xyz * REFERENCE_LUMINANCE
    white = to_cam @ torch.ones(3, dtype=torch.float64)
    y_w = (to_xyz @ torch.ones(3, dtype=torch.float64))[1] * REFERENCE_LUMINANCE
    d_rgb = (f_l / REFERENCE_LUMINANCE) * y_w / white
    rgb_to_cone = torch.diag(d_rgb) @ to_cam
    a_w_j = float(cone_compress(torch.tensor(f_l, dtype=torch.float64)))
    base = NL_SCALE * torch.tensor(_BASE_CONE_TO_AAB, dtype=torch.float64)
    a_w = float(base[0].sum()) * a_w_j
    cone_to_aab = torch.cat((base[:1] / a_w, base[1:] * 43.0 * SURROUND_NC))
    return JMhParams(
        rgb_to_cone, torch.linalg.inv(rgb_to_cone), cone_to_aab, torch.linalg.inv(cone_to_aab),
        f_l / REFERENCE_LUMINANCE, model_gamma(), a_w_j,
    )


def _apply(p: JMhParams, name: str, v: torch.Tensor, dim: int) -> torch.Tensor:
    """Matrix ``name`` of ``p`` applied along ``dim``: to an image as per-channel products (no matrix-library call)."""
    if dim == -3 and v.dim() >= 3:
        return apply_matrix(constant(p.values[name], v), v)
    m = getattr(p, name).to(dtype=v.dtype, device=v.device)
    return torch.movedim(torch.movedim(v, dim, -1) @ m.T, -1, dim)


def rgb_to_aab(rgb: torch.Tensor, p: JMhParams, dim: int = -3) -> torch.Tensor:
    """RGB -> ``(A, a, b)``: cone matrix, signed compression, opponent matrix (A normalised to white = 1).

    Examples:
        >>> from torchgrade.color import AP0_CHROMATICITIES
        >>> p = jmh_params(AP0_CHROMATICITIES)
        >>> round(float(rgb_to_aab(torch.ones(1, 3, 1, 1, dtype=torch.float64), p)[0, 0]), 6)  # white: A = 1
        1.0
    """
    return _apply(p, "cone_to_aab", cone_compress(_apply(p, "rgb_to_cone", rgb, dim)), dim)


def rgb_to_aab_planes(planes, p: JMhParams) -> tuple:
    """:func:`rgb_to_aab` on an image's three planes, returned as the planes ``(A, a, b)``: the form a compiler fuses
    (:func:`~torchgrade.runtime.strips.pixelwise`).

    Examples:
        >>> from torchgrade.color import AP0_CHROMATICITIES
        >>> p, rgb = jmh_params(AP0_CHROMATICITIES), torch.rand(3, 2, 2, dtype=torch.float64)
        >>> torch.allclose(torch.stack(rgb_to_aab_planes(rgb.unbind(-3), p), dim=-3), rgb_to_aab(rgb, p))
        True
    """
    cone = [cone_compress(plane) for plane in rows_on_planes(p.values["rgb_to_cone"], planes)]
    return rows_on_planes(p.values["cone_to_aab"], cone)


def _polar(a: torch.Tensor, b: torch.Tensor) -> tuple:
    """``(M, h, cos h, sin h)`` of ``(a, b)``: ``M = sqrt(a² + b²)``, ``h = atan2(b, a)``, and the hue's cosine and sine as
    ``(a / M, b / M)``, with finite gradients at the origin, where the hue is 0 (cosine 1, sine 0).

    Below the smallest normal number ``a² + b²`` counts as the origin: atan2's gradient divides by ``a² + b²``, which a
    denormal turns into 0/0 (a grey pixel of 1e-38 in float32 did). There ``a`` is taken as 1 for the hue and ``M`` as
    1 for the division (values within a denormal of the origin's), and the square root's gradient is selected away at
    0 (:func:`~torchgrade.color.safe_sqrt`): no select over the frame.

    Examples:
        >>> [[round(v, 6) for v in t.tolist()] for t in _polar(torch.tensor([3.0, 0.0]), torch.tensor([4.0, 0.0]))]
        [[5.0, 0.0], [0.927295, 0.0], [0.6, 1.0], [0.8, 0.0]]
    """
    squared = torch.addcmul(a * a, b, b)
    origin = squared <= torch.finfo(squared.dtype).tiny
    m = safe_sqrt(squared)
    unit_a = a + origin
    unit_m = m + origin
    return m, torch.atan2(b, unit_a), unit_a / unit_m, b / unit_m


def aab_to_jmh(aab: torch.Tensor, p: JMhParams, dim: int = -3):
    """``J = 100 A^cz``, ``M = |(a, b)|``, ``h = atan2(b, a)`` in degrees; ``A <= 0`` is black (0, 0, 0).

    Returns ``(J, M, h, cos h, sin h)``, the trigonometry from ``(a, b)`` directly (:func:`_polar`).

    Examples:
        >>> from torchgrade.color import AP0_CHROMATICITIES
        >>> p = jmh_params(AP0_CHROMATICITIES)
        >>> rgb = torch.tensor([0.5, 0.2, 0.1], dtype=torch.float64).reshape(1, 3, 1, 1)
        >>> j, m, h, _, _ = aab_to_jmh(rgb_to_aab(rgb, p), p)
        >>> [round(float(v), 2) for v in (j, m, h)]
        [58.62, 52.42, 26.24]
    """
    a_, a, b = aab.unbind(dim)
    return aab_planes_to_jmh(a_, a, b, p)


def aab_planes_to_jmh(a_: torch.Tensor, a: torch.Tensor, b: torch.Tensor, p: JMhParams):
    """:func:`aab_to_jmh` of the planes ``A``, ``a`` and ``b``."""
    lit = a_ > 0
    j = J_SCALE * safe_pow(a_, p.cz)
    m, hue, cos_h, sin_h = _polar(a, b)
    h = where(lit, torch.remainder(torch.rad2deg(hue), 360.0), 0.0)
    return j, where(lit, m, 0.0), h, cos_h, sin_h


def jmh_to_rgb(j, m, cos_h, sin_h, p: JMhParams, dim: int = -3) -> torch.Tensor:
    """Inverse model: ``A = (J / 100)^(1/cz)``, ``(a, b) = M (cos h, sin h)``, then the matrices back to RGB.

    Examples:
        >>> from torchgrade.color import AP0_CHROMATICITIES
        >>> p = jmh_params(AP0_CHROMATICITIES)
        >>> rgb = torch.tensor([0.5, 0.2, 0.1], dtype=torch.float64).reshape(1, 3, 1, 1)
        >>> j, m, _, cos_h, sin_h = aab_to_jmh(rgb_to_aab(rgb, p), p)
        >>> [round(v, 6) for v in jmh_to_rgb(j, m, cos_h, sin_h, p).flatten().tolist()]
        [0.5, 0.2, 0.1]
    """
    planes = _aab_planes(j, m, cos_h, sin_h, p)
    if dim == -3 and j.dim() >= 2:  # an image's planes go into the matrix as they are, without a concatenation
        cone = matrix_on_planes(constant(p.values["aab_to_cone"], j), [plane.unsqueeze(-3) for plane in planes])
    else:
        cone = _apply(p, "aab_to_cone", torch.stack(planes, dim), dim)
    return _apply(p, "cone_to_rgb", cone_expand(cone), dim)


def jmh_to_rgb_planes(j, m, cos_h, sin_h, p: JMhParams) -> tuple:
    """:func:`jmh_to_rgb` returned as the three planes of RGB: the form a compiler fuses
    (:func:`~torchgrade.runtime.strips.pixelwise`).

    Examples:
        >>> from torchgrade.color import AP0_CHROMATICITIES
        >>> p = jmh_params(AP0_CHROMATICITIES)
        >>> j, m, _, cos_h, sin_h = aab_to_jmh(rgb_to_aab(torch.rand(3, 2, 2, dtype=torch.float64), p), p)
        >>> torch.allclose(torch.stack(jmh_to_rgb_planes(j, m, cos_h, sin_h, p), dim=-3), jmh_to_rgb(j, m, cos_h, sin_h, p))
        True
    """
    cone = [cone_expand(plane) for plane in rows_on_planes(p.values["aab_to_cone"], _aab_planes(j, m, cos_h, sin_h, p))]
    return rows_on_planes(p.values["cone_to_rgb"], cone)


def _aab_planes(j, m, cos_h, sin_h, p: JMhParams) -> tuple:
    """``(A, a, b)`` of ``(J, M, h)``: ``A = (J / 100)^(1/cz)``, ``(a, b) = M (cos h, sin h)``."""
    return safe_pow(j / J_SCALE, 1.0 / p.cz), m * cos_h, m * sin_h


def a_to_y(a: torch.Tensor, p: JMhParams) -> torch.Tensor:
    """Luminance in cd/m² (RGB 1.0 -> 100) of an achromatic colour with response ``A >= 0``: ``ra^-1(A_w A) / F_L_n``.

    Examples:
        >>> from torchgrade.color import AP0_CHROMATICITIES
        >>> p = jmh_params(AP0_CHROMATICITIES)
        >>> round(float(a_to_y(torch.tensor(1.0, dtype=torch.float64), p)), 6)  # scene white
        100.0
    """
    return _expanded((p.a_w_j * a).clamp(0.0, RA_LIMIT), p.f_l_n)  # cone_expand of a response >= 0, over F_L_n


def y_to_j(y: torch.Tensor, p: JMhParams) -> torch.Tensor:
    """Lightness ``J = 100 (ra(|y| F_L_n) / A_w)^cz`` of an achromatic colour of luminance ``y`` cd/m², odd in ``y``.

    Examples:
        >>> from torchgrade.color import AP0_CHROMATICITIES
        >>> p = jmh_params(AP0_CHROMATICITIES)
        >>> [round(v, 6) for v in y_to_j(torch.tensor([100.0, -100.0], dtype=torch.float64), p).tolist()]
        [100.0, -100.0]
    """
    # ra = q / (NL + q) with q = (|y| F_L_n)^0.42, and J = 100 (ra / A_w)^cz = (q / ((NL + q) k))^cz with
    # k = A_w / 100^(1/cz): the constants folded into one product and sum
    q = safe_pow(y.abs(), 0.42)
    k = p.a_w_j / J_SCALE ** (1.0 / p.cz)
    return _signed_as(safe_pow(q / affine(q, k, k * NL_OFFSET / p.f_l_n**0.42), p.cz), y)
