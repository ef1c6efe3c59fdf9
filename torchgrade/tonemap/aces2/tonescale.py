"""The ACES 2.0 tonescale (Daniele Siragusano's curve) and its chroma compression.

Source: Academy aces-core ``Lib.Academy.Tonescale.ctl`` / ``Lib.Academy.OutputTransform.ctl`` and
OpenColorIO ``ops/fixedfunction/ACES2`` (``init_ToneScaleParams``, ``chroma_compress_fwd``). The
curve is applied to luminance (cd/m², scene 1.0 -> 100) and carried to lightness ``J`` through the
achromatic axis of the CAM, so hue and the ratio ``M / J`` are what chroma compression then shapes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from ...color import safe_pow, safe_sqrt
from ...runtime import affine, constant, where

__all__ = ["ToneScale", "tonescale_params", "daniele_tonescale", "ChromaParams", "chroma_params", "chroma_compress"]


@dataclass(frozen=True)
class ToneScale:
    """Constants of the curve for one peak luminance (cd/m²).

    Examples:
        >>> tonescale_params(1000.0).peak
        1000.0
    """

    peak: float
    s_2: float
    m_2: float
    g: float
    t_1: float
    c_t: float
    forward_limit: float
    log_peak: float


def tonescale_params(peak: float) -> ToneScale:
    """Daniele curve constants: grey 0.18 -> 10.013 cd/m² at 100 nits, rising 0.14 per stop of peak.

    ``r_hit`` (the scene value that reaches peak) moves from 128 to 896 as the peak goes from 100 to
    10000 cd/m², log-linearly; ``g = 1.15``, flare ``t_1 = 0.04``.

    Examples:
        >>> t = tonescale_params(1000.0)
        >>> t.forward_limit, round(t.c_t, 4)  # 8 r_hit, grey target / 100
        (4096.0, 0.1467)
    """
    n, n_r, g, c, c_d, w_g, t_1 = peak, 100.0, 1.15, 0.18, 10.013, 0.14, 0.04
    r_hit = 128.0 + (896.0 - 128.0) * math.log(n / n_r) / math.log(10000.0 / 100.0)
    m_0 = n / n_r
    m_1 = 0.5 * (m_0 + math.sqrt(m_0 * (m_0 + 4.0 * t_1)))
    u = ((r_hit / m_1) / ((r_hit / m_1) + 1.0)) ** g
    m = m_1 / u
    c_t = c_d / n_r * (1.0 + math.log2(n / 100.0) * w_g)
    g_ip = 0.5 * (c_t + math.sqrt(c_t * (c_t + 4.0 * t_1)))
    g_ipp2 = -(m_1 * (g_ip / m) ** (1.0 / g)) / ((g_ip / m) ** (1.0 / g) - 1.0)
    w_2 = c / g_ipp2
    u_2 = ((r_hit / m_1) / ((r_hit / m_1) + w_2)) ** g
    return ToneScale(n, w_2 * m_1 * 100.0, m_1 / u_2, g, t_1, c_t, 8.0 * r_hit, math.log10(n / n_r))


def daniele_tonescale(y: torch.Tensor, t: ToneScale) -> torch.Tensor:
    """``f = m_2 (Y / (Y + s_2))^g``, ``Y_ts = 100 max(0, f² / (f + t_1))`` for ``Y >= 0`` in cd/m².

    Examples:
        >>> t = tonescale_params(1000.0)
        >>> y = torch.tensor([0.0, 18.0, 51200.0], dtype=torch.float64)  # black, grey, r_hit
        >>> [round(v, 2) for v in daniele_tonescale(y, t).tolist()]
        [0.0, 14.51, 1000.0]
    """
    y = y.clamp_min(0.0)
    p = safe_pow(y / (y + t.s_2), t.g)  # f = m_2 p, so 100 f² / (f + t_1) = p² / (p / (100 m_2) + t_1 / (100 m_2²))
    return p * p / affine(p, 1.0 / (100.0 * t.m_2), t.t_1 / (100.0 * t.m_2 * t.m_2))


@dataclass(frozen=True)
class ChromaParams:
    """Chroma compression constants for one peak luminance.

    Examples:
        >>> chroma_params(tonescale_params(100.0)).sat
        1.3
    """

    sat: float
    sat_thr: float
    compr: float
    norm_scale: float


def chroma_params(t: ToneScale) -> ChromaParams:
    """``compr = 2.4 (1 + 3.3 log10(n/100))``, ``sat = max(0.2, 1.3 (1 - 0.69 log10(n/100)))``.

    Examples:
        >>> c = chroma_params(tonescale_params(100.0))
        >>> c.sat, c.compr, round(c.norm_scale, 4)
        (1.3, 2.4, 1.0001)
    """
    return ChromaParams(
        sat=max(0.2, 1.3 - 1.3 * 0.69 * t.log_peak),
        sat_thr=0.5 / t.peak,
        compr=2.4 + 2.4 * 3.3 * t.log_peak,
        norm_scale=(0.03379 * t.peak) ** 0.30596 - 0.45135,
    )


_CHROMA_NORM_POLYNOMIAL = (77.12896 - 16.46899, 11.34072 - 3.0 * 7.88380, 2.0 * 16.46899, 4.0 * 7.88380,
                           14.66441 + 3.0 * 9.19364, 4.0 * 9.19364, 2.0 * 6.37224)
""":func:`chroma_norm`'s series as a polynomial in ``c = cos h`` and ``s = sin h``: the coefficients ``(k, c1, c2, c3, s1,
s3, cs)`` of ``k + c1 c + c2 c² + c3 c³ + s1 s - s3 s³ - cs c s``."""


def chroma_norm(cos_h: torch.Tensor, sin_h: torch.Tensor, c: ChromaParams) -> torch.Tensor:
    """Hue-dependent normaliser of M: a third-order Fourier series in ``h`` fitted by the Academy.

    Examples:
        >>> c = chroma_params(tonescale_params(100.0))
        >>> round(float(chroma_norm(torch.tensor(1.0), torch.tensor(0.0), c)), 2)  # h = 0
        112.83
    """
    # With cos 2h = 2c² - 1, sin 2h = 2cs, cos 3h = 4c³ - 3c and sin 3h = 3s - 4s³ the series is the polynomial
    # k + c (c1 + c (c2 + c3 c)) + s (s1 - s3 s² - cs c) of _CHROMA_NORM_POLYNOMIAL: 8 operations where the
    # harmonics took 20.
    k, c1, c2, c3, s1, s3, cs = _CHROMA_NORM_POLYNOMIAL
    cosine_part = cos_h * torch.addcmul(constant(c1, cos_h), cos_h, affine(cos_h, c3, c2))
    sine_part = torch.add(affine(sin_h * sin_h, -s3, s1), cos_h, alpha=-cs)
    return affine(torch.addcmul(cosine_part, sin_h, sine_part), c.norm_scale, k * c.norm_scale)


def toe(x: torch.Tensor, limit, k1: torch.Tensor, k2: torch.Tensor) -> torch.Tensor:
    """Quadratic toe that leaves ``x > limit`` unchanged: root of ``y² + (k1 - k3 x) y - k2 k3 x = 0``.

    ``k2 >= 0.001`` and ``k1 <- sqrt(k1² + k2²)``, ``k3 = (limit + k1) / (limit + k2)`` (aces-core ``toe``).

    Examples:
        >>> [round(v, 4) for v in toe(torch.tensor([0.05, 2.0]), 1.0, torch.tensor(0.5), torch.tensor(0.5)).tolist()]
        [0.0412, 2.0]
    """
    k2 = k2.clamp_min(0.001)
    k1 = torch.sqrt(torch.addcmul(k1 * k1, k2, k2))  # hypot, which ONNX lacks
    k3 = (limit + k1) / (limit + k2)
    minus_b = k3 * x - k1
    y = 0.5 * (minus_b + safe_sqrt(torch.addcmul(minus_b * minus_b, k2 * k3, x, value=4.0)))
    return torch.where(x > limit, x, y)


def chroma_compress(j, m, j_ts, norm, reach_m, limit_j_max: float, cz: float, c: ChromaParams):
    """Tone-mapped colourfulness: ``M (J_ts / J)^(1/cz)``, then an expansion toe near white and a
    compression toe towards ``limit = (J_ts / J_max)^(1/cz) reach_M``, all in units of ``norm``.

    Examples:
        >>> c = chroma_params(tonescale_params(100.0))
        >>> one = torch.tensor(1.0)
        >>> # grey stays grey
        >>> float(chroma_compress(one * 50, one * 0, one * 40, one * 100, one * 150, 100.0, 1.1371, c))
        0.0
    """
    inv_cz = 1.0 / cz
    nj = j_ts / limit_j_max
    snj = (1.0 - nj).clamp_min(0.0)
    limit = safe_pow(nj, inv_cz) * reach_m / norm
    lit = j > 0
    ratio = j_ts / where(lit, j, 1.0)
    mc = m * safe_pow(ratio, inv_cz) / norm
    mc = limit - toe(limit - mc, limit - 0.001, snj * c.sat, torch.sqrt(nj * nj + c.sat_thr))
    mc = toe(mc, limit, nj * c.compr, snj)
    return where(lit & (m != 0), mc * norm, 0.0)
