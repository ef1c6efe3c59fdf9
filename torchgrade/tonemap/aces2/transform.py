"""The ACES 2.0 Output Transform: scene-referred ACES2065-1 or linear Rec.709 -> display.

Source: Academy aces-output (ACES 2.0 Output Transforms) and OpenColorIO's builtin
``ACES-OUTPUT - ACES2065-1_to_CIE-XYZ-D65 - <target>_2.0``: AP1 clamp to ``[0, 8 r_hit]``, CAM
(JMh), tonescale, chroma compression, gamut compression to the limiting primaries, white limiting
(clamp to ``[0, peak/100]``), then the display encoding (BT.1886 or SMPTE ST 2084).
"""

from __future__ import annotations

import functools
import threading
import weakref

import torch

from ... import color
from ...base.images import check_image, full_precision, sanitize
from ...base.planes import each_plane, matrix_on
from ...runtime import values_of
from ..aces1.rrt import REC709_TO_AP0
from .cam import (
    REFERENCE_LUMINANCE,
    a_to_y,
    aab_planes_to_jmh,
    aab_to_jmh,
    jmh_params,
    jmh_to_rgb,
    jmh_to_rgb_planes,
    rgb_to_aab,
    rgb_to_aab_planes,
    y_to_j,
)
from .gamut import FOCUS_DISTANCE, FOCUS_DISTANCE_SCALING, GamutParams, gamut_compress
from .tables import hue_and_cusp_tables, reach_m_table, upper_hull_gamma
from .tonescale import (
    chroma_compress,
    chroma_norm,
    chroma_params,
    daniele_tonescale,
    tonescale_params,
)

__all__ = ["PRIMARIES", "ENCODINGS", "Aces2Output", "Prepared", "aces2_output", "prepare_output", "peak_number"]

PRIMARIES = {
    "rec709": color.REC709_CHROMATICITIES,
    "p3_d65": color.P3_D65_CHROMATICITIES,
    "rec2020": color.REC2020_CHROMATICITIES,
}
"""Limiting and display primaries by name (all D65 white)."""

ENCODINGS = ("linear", "bt1886", "pq")


class Aces2Output:
    """Float64 constants and hue tables for one (peak luminance, limiting primaries); see :func:`aces2_output`.

    Examples:
        >>> output = Aces2Output(100.0, "rec709")
        >>> output.peak, output.limiting
        (100.0, 'rec709')
    """

    def __init__(self, peak_luminance: float, limiting_primaries: str):
        peak = float(peak_luminance)
        self.peak, self.limiting = peak, limiting_primaries
        self.aces = jmh_params(color.AP0_CHROMATICITIES)
        self.limit = jmh_params(PRIMARIES[limiting_primaries])
        reach = jmh_params(color.AP1_CHROMATICITIES)
        # AP0 and AP1 share a white, so the CAM of AP1 is AP0's after the AP1 -> AP0 matrix: only its matrices differ
        self.inputs = {"ap0": self.aces, "ap1": reach}
        self.tone = tonescale_params(peak)
        self.chroma = chroma_params(self.tone)
        limit_j_max = float(y_to_j(torch.tensor(peak, dtype=torch.float64), self.aces))
        mid_j = float(y_to_j(torch.tensor(self.tone.c_t * 100.0, dtype=torch.float64), self.aces))
        focus_dist = FOCUS_DISTANCE * (1.0 + FOCUS_DISTANCE_SCALING * self.tone.log_peak)
        lower_inv = 1.0 / (1.14 + 0.07 * self.tone.log_peak)
        hues, cusps = hue_and_cusp_tables(reach, self.limit, peak, limit_j_max, self.tone.forward_limit)
        top = upper_hull_gamma(hues, cusps, self.limit, peak, limit_j_max, mid_j, focus_dist, lower_inv)
        self.gamut = GamutParams(limit_j_max, mid_j, focus_dist, lower_inv, 1.0 / self.aces.cz, hues,
                                 torch.cat((cusps, top[:, None]), -1), reach_m_table(reach, limit_j_max))

    def render(self, aces: torch.Tensor, primaries: str = "ap0") -> torch.Tensor:
        """ACES2065-1 ``(..., 3, H, W)`` (or AP1, ``primaries="ap1"``: the AP1 -> AP0 matrix folded into the CAM's
        first) -> linear RGB in the limiting primaries, 1.0 = 100 cd/m², in ``[0, peak/100]``.

        Examples:
            >>> out = _output(100.0, "rec709").render(torch.full((1, 3, 1, 1), 1e4))
            >>> [round(v, 4) for v in out.flatten().tolist()]  # white limited to peak
            [1.0, 1.0, 1.0]
        """
        aab = rgb_to_aab(aces, self.inputs[primaries])
        j, m, h, cos_h, sin_h = aab_to_jmh(aab, self.aces)
        j_out, m_out = self._compressed(aab.select(-3, 0), j, m, h, cos_h, sin_h)
        rgb = jmh_to_rgb(j_out, m_out, cos_h, sin_h, self.limit)
        return rgb.clamp(0.0, self.peak / REFERENCE_LUMINANCE)

    def render_planes(self, planes, primaries: str = "ap0") -> tuple:
        """:meth:`render` on an image's three planes, returned as planes: the form a compiler fuses into one loop
        (:func:`~torchgrade.runtime.strips.pixelwise`).

        Examples:
            >>> output, aces = _output(100.0, "rec709"), torch.rand(1, 3, 2, 2) * 4
            >>> torch.allclose(torch.stack(output.render_planes(aces.unbind(-3)), dim=-3), output.render(aces), atol=1e-6)
            True
        """
        a_, a, b = rgb_to_aab_planes(planes, self.inputs[primaries])
        j, m, h, cos_h, sin_h = aab_planes_to_jmh(a_, a, b, self.aces)
        j_out, m_out = self._compressed(a_, j, m, h, cos_h, sin_h, planes=True)
        rgb = jmh_to_rgb_planes(j_out, m_out, cos_h, sin_h, self.limit)
        return tuple(plane.clamp(0.0, self.peak / REFERENCE_LUMINANCE) for plane in rgb)

    def _compressed(self, a_, j, m, h, cos_h, sin_h, planes: bool = False) -> tuple:
        """The tone scale, chroma compression and gamut compression of ``(J, M, h)``: ``(J, M)`` of the display
        (``planes``: the hue tables gathered a row at a time, :meth:`~.gamut.GamutParams.cusp`)."""
        j_ts = y_to_j(daniele_tonescale(a_to_y(a_, self.aces), self.tone), self.aces)
        reach_m = self.gamut.reach_m(h, planes)
        norm = chroma_norm(cos_h, sin_h, self.chroma)
        m_ts = chroma_compress(j, m, j_ts, norm, reach_m, self.gamut.limit_j_max, self.aces.cz, self.chroma)
        return gamut_compress(j_ts, m_ts, h, reach_m, self.gamut, planes)


class Prepared:
    """What a stage keeps of the tables it prepared (:func:`prepare_output`): while it lives, the shared cache keeps
    them, so the stage's compiled or traced forward finds them however many other tables were built since.

    Examples:
        >>> prepare_output(100.0, "rec709").output.peak
        100.0
    """

    def __init__(self, key: tuple, output: Aces2Output):
        self.key, self.output = key, output


_BUILT: dict = {}
"""Built tables by ``(peak, limiting)``, oldest first: the :data:`MAX_BUILT` built last, and any a stage holds."""

MAX_BUILT = 8
"""Tables kept beyond those a stage holds (each is a few hundred kilobytes); ``_BUILT`` is read without the lock, by
forwards (a compiled one reads it as a constant), and only ever loses a key no stage holds."""

_HELD: weakref.WeakSet[Prepared] = weakref.WeakSet()
"""The :class:`Prepared` objects alive (held by stages)."""

_LOCK = threading.Lock()


def _output(peak: float, limiting: str) -> Aces2Output:
    """The tables of ``(peak, limiting)``, built once. A stage builds them when its controls are set
    (:func:`prepare_output`), so a compiled or traced forward finds them here as constants of its graph."""
    built = _BUILT.get((peak, limiting))
    return built if built is not None else prepare_output(peak, limiting).output


def prepare_output(peak: float, limiting: str) -> Prepared:
    """Build (once) the tables of ``(peak, limiting)`` and keep them while the returned :class:`Prepared` lives (and
    while they are among the :data:`MAX_BUILT` built last). A stage prepares its tables when its controls are set, so
    that an ONNX trace or a compiler finds them built (a graph keeps their values as constants, not their search).

    Examples:
        >>> prepare_output(100.0, "rec709").output is prepare_output(100.0, "rec709").output
        True
    """
    key = (float(peak), limiting)
    with _LOCK:
        built = _BUILT.get(key)
        if built is None:
            built = _BUILT[key] = Aces2Output(*key)
            held = {prepared.key for prepared in _HELD}
            for old in [old for old in _BUILT if old not in held and old != key][:max(len(_BUILT) - MAX_BUILT, 0)]:
                del _BUILT[old]
        prepared = Prepared(key, built)
        _HELD.add(prepared)
    return prepared


def _rgb_to_rgb(source, target) -> torch.Tensor:
    """Linear RGB -> RGB through XYZ without adaptation (OpenColorIO's ``ADAPTATION_NONE``), float64."""
    return torch.linalg.inv(color.rgb_to_xyz_matrix(target)) @ color.rgb_to_xyz_matrix(source)


_AP0_TO_AP1 = _rgb_to_rgb(color.AP0_CHROMATICITIES, color.AP1_CHROMATICITIES)
_MATRIX_VALUES = {
    "ap0_to_ap1": values_of(_AP0_TO_AP1),
    "rec709_to_ap1": values_of(_AP0_TO_AP1 @ REC709_TO_AP0),
    **{f"{source}_to_{target}": values_of(_rgb_to_rgb(PRIMARIES[source], PRIMARIES[target])) for source in PRIMARIES for target in PRIMARIES},
}
"""The transform's matrices as tuples of floats (device constants, :func:`~torchgrade.runtime.constant`)."""


def peak_number(peak_luminance) -> float:
    """The peak as a float: a number or a 0-d tensor without gradient (the tables are searched per value)."""
    if isinstance(peak_luminance, torch.Tensor) and peak_luminance.numel() == 1 and not peak_luminance.requires_grad:
        return float(peak_luminance)
    if isinstance(peak_luminance, bool) or not isinstance(peak_luminance, (int, float)):
        kind = type(peak_luminance).__name__
        raise TypeError(f"peak_luminance must be a number of cd/m² (tables are cached per value), got {kind}")
    return float(peak_luminance)


def _check(peak_luminance: float, limiting_primaries, display_primaries, encoding, input_space) -> None:
    if not (100.0 <= peak_luminance <= 10000.0):
        raise ValueError(f"peak_luminance must be in [100, 10000] cd/m², got {peak_luminance}")
    for name, value, choices in (("limiting_primaries", limiting_primaries, tuple(PRIMARIES)),
                                 ("display_primaries", display_primaries, tuple(PRIMARIES)),
                                 ("encoding", encoding, ENCODINGS), ("input_space", input_space, ("rec709", "aces"))):
        if value not in choices:
            raise ValueError(f"{name} must be one of {choices}, got {value!r}")


def aces2_output(image: torch.Tensor, peak_luminance: float = 100.0, limiting_primaries: str = "rec709",
                 display_primaries: str | None = None, encoding: str = "linear",
                 input_space: str = "rec709", *, nan_free: bool = False, planes: bool = False) -> torch.Tensor:
    r"""ACES 2.0 Output Transform of a scene-referred ``(..., 3, H, W)`` image.

    ``input_space`` is ``"rec709"`` (linear Rec.709, Bradford-adapted to AP0) or ``"aces"``
    (ACES2065-1). The image is sanitised (NaN -> 0, ±Inf -> ±65504; only bounded when the caller says it is
    ``nan_free``: :func:`~torchgrade.base.images.sanitize`), AP1-clamped to
    ``[0, 8 r_hit]`` and rendered for a display of ``peak_luminance`` cd/m² whose gamut is limited
    to ``limiting_primaries``; the result is expressed in ``display_primaries`` (default: the
    limiting ones) and encoded:

    * ``"linear"``: display-linear, ``1.0`` = peak, clipped to ``[0, 1]``;
    * ``"bt1886"``: ``L^(1/2.4)`` (BT.1886 with black 0), OpenColorIO's "Rec.1886 Rec.709 - Display";
    * ``"pq"``: SMPTE ST 2084 of ``L * peak`` cd/m², OpenColorIO's "Rec.2100-PQ - Display".

    Matches OpenColorIO's "ACES 2.0 - SDR 100 nits (Rec.709)" and "ACES 2.0 - HDR 1000 nits
    (Rec.2020)" / "(P3 D65)" views (Academy ACES 2.0; see ``tests/tonemap/test_aces2.py`` for the measured
    distance). ``planes``: computed on the image's three planes, the form a compiler fuses into one loop
    (:meth:`Aces2Output.render_planes`). Differentiable with respect to the image. ``peak_luminance`` is a number (or a
    0-d tensor without gradient) in ``[100, 10000]`` cd/m², not a learnable parameter: the gamut
    tables are searched for it, once per ``(peak_luminance, limiting_primaries)``, then cached.

    Examples:
        >>> grey = torch.full((1, 3, 1, 1), 0.18)
        >>> sdr = aces2_output(grey, encoding="bt1886")  # OpenColorIO: 0.3831
        >>> round(float(sdr[0, 0, 0, 0]), 3)
        0.383
        >>> hdr = aces2_output(grey, 1000.0, "p3_d65", "rec2020", encoding="linear")
        >>> round(float(hdr[0, 1, 0, 0]) * 1000.0, 1)  # cd/m²
        14.5
    """
    check_image(image)
    display_primaries = display_primaries or limiting_primaries
    peak = peak_number(peak_luminance)
    _check(peak, limiting_primaries, display_primaries, encoding, input_space)
    if image.dtype in (torch.float16, torch.bfloat16):
        raise TypeError(f"aces2_output needs float32 or float64 input (its CAM overflows {image.dtype})")
    # The CAM's powers and the table lookups need float32 or better, whatever autocast is active.
    with full_precision():
        image = sanitize(image, nan_free=nan_free)
        linear = _display_linear(image.unbind(-3) if planes else image, peak, limiting_primaries, display_primaries, input_space)
        encoded = each_plane(lambda plane: _encoded(plane, encoding, peak), linear)
        return torch.stack(encoded, dim=-3) if isinstance(encoded, tuple) else encoded


def _encoded(linear: torch.Tensor, encoding: str, peak: float) -> torch.Tensor:
    """Display-linear values in the display's ``encoding`` (see :func:`aces2_output`)."""
    if encoding == "bt1886":
        return color.safe_pow(linear, 1.0 / 2.4)
    if encoding == "pq":
        return color.linear_to_pq(linear, reference=peak)
    return linear


def _display_linear(x, peak: float, limiting: str, display: str, input_space: str):
    """The Output Transform to display-linear RGB, 1.0 = peak: each run of matrices folded into one (into AP1, the AP1
    -> AP0 matrix and the CAM's first, the display's and the scaling to the peak). ``x`` is an image, or its three
    planes as a tuple, and the result takes its form."""
    output = _output(peak, limiting)
    into_ap1 = matrix_on(_MATRIX_VALUES["rec709_to_ap1" if input_space == "rec709" else "ap0_to_ap1"], x)
    ap1 = each_plane(lambda v: v.clamp(0.0, output.tone.forward_limit), into_ap1)
    rgb = output.render_planes(ap1, "ap1") if isinstance(ap1, tuple) else output.render(ap1, "ap1")
    scale = REFERENCE_LUMINANCE / peak
    if limiting != display:
        rgb = matrix_on(_display_matrix(limiting, display, scale), rgb)
    elif scale != 1.0:
        rgb = each_plane(lambda v: v * scale, rgb)
    # Display values below 0 do not exist: clip where a limiting gamut pokes out of the container
    # (P3's red lies just outside Rec.2020), rather than mirror them through the encoding as OpenColorIO does.
    return each_plane(lambda v: v.clamp(0.0, 1.0), rgb)


@functools.lru_cache(maxsize=64)
def _display_matrix(limiting: str, display: str, scale: float) -> tuple:
    """The limiting primaries' matrix to the display's (:data:`_MATRIX_VALUES`) times ``scale``, made once a peak."""
    return tuple(tuple(value * scale for value in row) for row in _MATRIX_VALUES[f"{limiting}_to_{display}"])
