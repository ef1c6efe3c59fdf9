"""The steps of Unity's colour grade, one pure, differentiable function each.

Each function takes and returns ``(..., 3, H, W)`` tensors; controls broadcast as the library's
conventions say (numbers, 0-d, per-sample). :func:`torchgrade.grading.grade.color_grade` chains them in
Unity's order and skips the steps left at identity; see :mod:`torchgrade.grading.grade` for the order,
units and sources.
"""

from __future__ import annotations

import math

import torch

from ..base.core import (
    HALF_MAX,
    NEGLIGIBLE_LIGHT,
    Param,
    apply_matrix,
    bounded_pow,
    channel_max,
    color_param,
    each_plane,
    is_constant,
    joined,
    like_image,
    matrix_on,
    matrix_param,
    matrix_product,
    per_channel,
    scalar_param,
    untracked,
)
from ..color import (
    ACESCC_MIDGRAY,
    AP1_LUMINANCE,
    CHANNEL,
    LOGC_A,
    LOGC_B,
    LOGC_C,
    LOGC_D,
    REC709_LUMINANCE,
    aces_to_acescc,
    acescc_to_aces,
    acescct_to_linear,
    convert,
    hsv_planes,
    linear_to_acescct,
    luminance,
    rgb_from_hsv_planes,
    rgb_planes_from_hsv,
    safe_pow,
    safe_sqrt,
    srgb_to_linear,
)
from ..color.spaces import shared_matrix
from ..runtime import affine, constant, folded, is_exporting, where
from .curves import evaluate_curve

__all__ = [
    "IDENTITY_MATRIX",
    "IDENTITY_TRACKBALL",
    "post_exposure",
    "white_balance_coefficients",
    "white_balance_matrix",
    "white_balance",
    "contrast_space",
    "log_contrast",
    "contrast",
    "color_filter",
    "soft_light",
    "split_toning",
    "channel_mixer",
    "smoothstep",
    "shadows_midtones_highlights",
    "lift_gamma_gain_coefficients",
    "lift_gamma_gain",
    "hue_shift",
    "saturation_curves",
    "saturation",
    "saturation_matrix",
    "fast_tonemap",
    "fast_tonemap_inverse",
    "yrgb_curves",
]

IDENTITY_MATRIX = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
IDENTITY_TRACKBALL = (1.0, 1.0, 1.0, 0.0)
"""A lift, gamma or gain trackball that changes nothing: white, offset 0."""


def _channels(t: torch.Tensor) -> torch.Tensor:
    """A scalar parameter (0-d or (B,1,1,1)) as a single-channel map that can be concatenated to RGB."""
    return t.reshape(t.shape[:1] + (1, 1, 1)) if t.dim() else t.reshape(1, 1, 1)


def post_exposure(image: torch.Tensor, stops: Param) -> torch.Tensor:
    """Post exposure: ``rgb · 2^stops``.

    Examples:
        >>> post_exposure(torch.full((3, 1, 1), 0.25), 2.0).flatten().tolist()
        [1.0, 1.0, 1.0]
    """
    return image * torch.exp2(scalar_param(stops, image, "post_exposure"))


def white_balance_coefficients(temperature: torch.Tensor, tint: torch.Tensor) -> torch.Tensor:
    """LMS gains of Unity's ``ColorUtils.ColorBalanceToLMSCoeffs(temperature, tint)``.

    ``x = 0.31271 - t1·(0.1 if t1 < 0 else 0.05)``, ``y = 2.87x - 3x² - 0.27509508 + t2·0.05`` with
    ``t1 = temperature/65``, ``t2 = tint/65``; the white ``(x, y)`` goes to CAT02 LMS and the gains are
    D65's LMS ``(0.949237, 1.03542, 1.08728)`` divided by it. Returns ``(..., 3, 1, 1)``.

    Examples:
        >>> gains = white_balance_coefficients(torch.tensor(0.0), torch.tensor(0.0))
        >>> bool(torch.allclose(gains, torch.ones(3, 1, 1), atol=1e-5))
        True
    """
    t1, t2 = _channels(temperature) / 65.0, _channels(tint) / 65.0
    x = 0.31271 - torch.where(t1 < 0, t1 * 0.1, t1 * 0.05)
    y = 2.87 * x - 3.0 * x * x - 0.27509508 + t2 * 0.05
    big_x, big_z = x / y, (1.0 - x - y) / y
    lms = torch.cat(
        (
            0.7328 * big_x + 0.4296 - 0.1624 * big_z,
            -0.7036 * big_x + 1.6975 + 0.0061 * big_z,
            0.0030 * big_x + 0.0136 + 0.9834 * big_z,
        ),
        dim=-3,
    )
    d65 = constant((0.949237, 1.03542, 1.08728), lms).reshape(3, 1, 1)
    return d65 / lms


def white_balance_matrix(image: torch.Tensor, temperature: Param = 0.0, tint: Param = 0.0) -> torch.Tensor:
    """White balance as one matrix on linear Rec.709: ``LMSToLinear · diag(gains) · LinearToLMS`` with the
    gains of :func:`white_balance_coefficients`; ``(3, 3)``, or ``(B, 3, 3)`` for per-sample controls.

    Examples:
        >>> m = white_balance_matrix(torch.zeros(1, 3, 1, 1), temperature=0.0)
        >>> bool(torch.allclose(m, torch.eye(3), atol=1e-4))
        True
    """
    gains = white_balance_coefficients(scalar_param(temperature, image, "temperature"), scalar_param(tint, image, "tint"))
    return matrix_product(shared_matrix("lms_to_linear", image), gains[..., 0] * shared_matrix("linear_to_lms", image))


def white_balance(image: torch.Tensor, temperature: Param = 0.0, tint: Param = 0.0) -> torch.Tensor:
    """White balance: scale in LMS by :func:`white_balance_coefficients` (Unity ``ColorGradeWhiteBalance``),
    applied as :func:`white_balance_matrix`.

    Examples:
        >>> warm = white_balance(torch.full((3, 1, 1), 0.5), temperature=50.0).flatten()
        >>> bool(warm[0] > warm[2])
        True
    """
    return apply_matrix(white_balance_matrix(image, temperature, tint), image)


def contrast_space(aces: bool = False, log_space: str = "acescc") -> tuple:
    """``(encoding, into, out of)``: the log encoding contrast is graded in, the matrix (a :data:`~torchgrade.color.MATRICES`
    name) from linear Rec.709 into its primaries and the one from them to the grade's working space (None: none).

    Examples:
        >>> contrast_space(), contrast_space(True), contrast_space(True, "acescct")
        (('logc', None, None), ('acescc', 'srgb_to_ap0', 'ap0_to_ap1'), ('acescct', 'srgb_to_ap1', None))
    """
    if not aces:
        return "logc", None, None
    if log_space == "acescct":
        return "acescct", "srgb_to_ap1", None
    return "acescc", "srgb_to_ap0", "ap0_to_ap1"


def log_contrast(image: torch.Tensor, amount: Param, encoding: str = "logc") -> torch.Tensor:
    """Contrast about mid grey in ``encoding`` (``"logc"``, ``"acescc"`` or ``"acescct"``) on linear values in
    that encoding's primaries: ``(log(x) - 0.4135884) · (1 + amount/100) + 0.4135884``, decoded back.

    In LogC, ``c log10(a x + b) + d``, the encode, the scaling and the decode fold into one power:
    ``((a x + b)^k · 10^((d - 0.4135884)(k - 1) / c) - b) / a``.

    Examples:
        >>> # in a pure log encoding x -> 0.18 (x / 0.18)^k: grey is the pivot, 1.0 goes to 0.18 (1 / 0.18)^1.5
        >>> [round(v, 3) for v in log_contrast(torch.tensor([0.18, 1.0]), 50.0, "acescc").tolist()]
        [0.18, 2.357]
    """
    k = folded(_contrast_slope, amount, like=image, host=untracked(image))  # the power's backward would copy a CPU exponent to the device
    if encoding == "acescct":
        return acescct_to_linear((linear_to_acescct(image) - ACESCC_MIDGRAY) * k + ACESCC_MIDGRAY)
    if encoding == "acescc":
        if untracked(image, k):
            return _acescc_contrast_in_place(image, k)
        if is_exporting():
            return _acescc_contrast_folded(image, k)
        return acescc_to_aces((aces_to_acescc(image) - ACESCC_MIDGRAY) * k + ACESCC_MIDGRAY)
    base = affine(image, LOGC_A, LOGC_B).clamp_min(torch.finfo(image.dtype).tiny)
    if is_exporting():
        # The power as exp(k ln(base) + ln(gain)): a Log and an Exp cost less than half a Pow (benchmarks/results/onnx_ops.md).
        log_gain = math.log(10.0) * (LOGC_D - ACESCC_MIDGRAY) / LOGC_C * (k - 1.0)
        return (torch.exp(torch.log(base) * k + log_gain) - LOGC_B) / LOGC_A
    gain = torch.pow(10.0, (LOGC_D - ACESCC_MIDGRAY) * (k - 1.0) / LOGC_C) / LOGC_A
    return affine(base**k * gain, 1.0, -LOGC_B / LOGC_A)


def _contrast_slope(amount: Param, *, like: torch.Tensor) -> torch.Tensor:
    """The slope ``k = 1 + amount / 100`` of :func:`log_contrast` (made once for a plain number, ``runtime.folded``).

    Examples:
        >>> _contrast_slope(50.0, like=torch.zeros(())).item()
        1.5
    """
    return 1.0 + scalar_param(amount, like, "contrast") * 0.01


_ACESCC_PIVOT_STOPS = ACESCC_MIDGRAY * 17.52 - 9.72
"""ACEScc's pivot as ``log2`` of linear (``log2(0.18)``): the code ``(log2(x) + 9.72) / 17.52`` at ``ACESCC_MIDGRAY``."""


def _acescc_contrast_in_place(image: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
    """ACEScc contrast with the encode, the scaling and the decode folded into one power of two, computed in place.

    ``min(2^(k log2(2u) + p - k(1 + p)), 65504)``, that is ``2^min((log2(u) - p) k + p, log2(65504))``, with ``p``
    the pivot in stops and ``2u = x + max(x, 2^-15)`` twice the encode's ``u = max(x, 2^-16 + x/2)`` on ``x`` clamped
    to [0, 65504] (its two segments, :func:`~torchgrade.color.aces_to_acescc`); the decode's low segment
    ``(v - 2^-16)·2`` is below ``v`` exactly where ``v < 2^-15``, so the decode is ``2v - max(v, 2^-15)``.

    Examples:
        >>> x = torch.tensor([0.0, 1e-5, 0.18, 1.0, 1e5])
        >>> bool(torch.allclose(_acescc_contrast_in_place(x, torch.tensor(1.3)), acescc_to_aces((aces_to_acescc(x) - ACESCC_MIDGRAY) * 1.3 + ACESCC_MIDGRAY), rtol=1e-5))
        True
    """
    x = image.clamp(0.0, HALF_MAX)
    offset = _ACESCC_PIVOT_STOPS - k * (1.0 + _ACESCC_PIVOT_STOPS)
    # bounded after the power: in float16 log2(65504) rounds to 16, whose power is infinite
    value = x.clamp_min(2.0**-15).add_(x).log2_().mul_(k).add_(offset).exp2_().clamp_max_(HALF_MAX)
    return value.clamp_min(2.0**-15).lerp_(value, 2.0)  # m + 2(v - m) = 2v - m


def _acescc_contrast_folded(image: torch.Tensor, k) -> torch.Tensor:
    """:func:`_acescc_contrast_in_place` for export, with min and max of two branches as clamps: one ``Log``, one
    ``Exp``, no comparison or ``Where`` (their costs on onnxruntime's CPU: ``benchmarks/results/onnx_ops.md``).

    ``s = x + max(x, 2^-15)`` with ``x`` clamped to [0, 65504] is twice the encode's ``max(x, 2^-16 + x/2)``, rounded
    alike; ``v = exp(min(k ln s + ((1 - k) p - k) ln 2, ln 65504))`` the scaled code decoded, with ``p`` the pivot
    in stops; the decode's ``min(v, (v - 2^-16)·2)`` is ``2v - max(v, 2^-15)``, again with the same rounding.

    Examples:
        >>> x = torch.tensor([0.0, 2.0**-16, 2.0**-15, 0.18, 1e5])
        >>> bool(torch.allclose(_acescc_contrast_folded(x, torch.tensor(1.3)), _acescc_contrast_in_place(x, torch.tensor(1.3)), rtol=1e-5))
        True
    """
    x = image.clamp(0.0, HALF_MAX)
    doubled = x + x.clamp_min(2.0**-15)
    offset = ((1.0 - k) * _ACESCC_PIVOT_STOPS - k) * math.log(2.0)
    value = torch.exp((torch.log(doubled) * k + offset).clamp_max(math.log(HALF_MAX)))
    return 2.0 * value - value.clamp_min(2.0**-15)


def contrast(image: torch.Tensor, amount: Param, aces: bool = False, log_space: str = "acescc") -> torch.Tensor:
    """Contrast about mid grey in log space (:func:`log_contrast` in the encoding of :func:`contrast_space`).

    Linear mode uses LogC and returns linear Rec.709; ``aces=True`` uses ACEScc and returns ACEScg
    (Unity ``ColorGradingContrast``); ``log_space="acescct"`` uses ACEScct (S-2016-001) on ACEScg, whose
    linear toe below 2^-7 keeps shadows from the log's steep fall.

    Examples:
        >>> out = contrast(torch.tensor([0.05, 1.0, 1.0]).reshape(3, 1, 1), 50.0).flatten()
        >>> bool(out[0] < 0.05 and out[1] > 1.0)  # shadows darker, highlights brighter
        True
    """
    encoding, into, out_of = contrast_space(aces, log_space)
    x = image if into is None else convert(image, into)
    x = log_contrast(x, amount, encoding)
    return x if out_of is None else convert(x, out_of)


def color_filter(image: torch.Tensor, color) -> torch.Tensor:
    """Colour filter: multiply by the colour, given sRGB-encoded as in Unity's picker (HDR allowed).

    Examples:
        >>> color_filter(torch.ones(3, 1, 1), (1.0, 1.0, 0.0)).flatten().tolist()
        [1.0, 1.0, 0.0]
    """
    return image * srgb_to_linear(color_param(color, image, "color_filter"))


def soft_light(base: torch.Tensor, blend: torch.Tensor) -> torch.Tensor:
    """Soft-light blend (Unity ``SoftLight``, after Adobe): below 0.5 ``2ab + a²(1 - 2b)``, else
    ``sqrt(a)(2b - 1) + 2a(1 - b)``.

    Examples:
        >>> soft_light(torch.tensor([0.3]), torch.tensor([0.5])).tolist()  # a 0.5 blend changes nothing
        [0.30000001192092896]
    """
    return torch.where(blend >= 0.5, _lighten(base, blend), _darken(base, blend))


def _darken(base: torch.Tensor, blend: torch.Tensor) -> torch.Tensor:
    """Soft light below a blend of 0.5: ``2ab + a²(1 - 2b)``."""
    return 2.0 * base * blend + base * base * (1.0 - 2.0 * blend)


def _lighten(base: torch.Tensor, blend: torch.Tensor) -> torch.Tensor:
    """Soft light from a blend of 0.5 up: ``sqrt(a)(2b - 1) + 2a(1 - b)``."""
    return safe_sqrt(base) * (2.0 * blend - 1.0) + 2.0 * base * (1.0 - blend)


def _soft_light_by_channel(gamma: torch.Tensor, weights: tuple, offsets: tuple) -> torch.Tensor:
    """Soft-light blends of ``gamma`` with tints ``0.5 + offset · weight`` given by constant per-channel ``offsets``.

    With ``weight`` in [0, 1] a channel's blend stays on the side of 0.5 its offset's sign gives, so each channel is
    blended by that branch of :func:`soft_light` alone, written with ``s = 2 blend - 1 = 2 offset weight``:
    ``a + s(√a - a)`` (:func:`_lighten`) and ``a + s·a(1 - a)`` (:func:`_darken`), one multiply-add each; an offset of
    0 blends with 0.5 exactly, where both branches return the base, and is skipped. In place where nothing records
    (:func:`untracked`), one plane at a time.

    Examples:
        >>> base, t = torch.rand(1, 3, 2, 2), torch.rand(1, 1, 2, 2)
        >>> tint = 0.5 + torch.tensor([-0.2, 0.0, 0.3]).reshape(3, 1, 1) * t
        >>> bool(torch.allclose(_soft_light_by_channel(base.clone(), (t,), ((-0.2, 0.0, 0.3),)), soft_light(base, tint), atol=1e-6))
        True
    """
    on_planes = isinstance(gamma, tuple)  # the image's planes (ExecutionPolicy.pixel_planes): returned as planes
    in_place = not on_planes and untracked(gamma, *weights)
    exporting = is_exporting()
    planes = []
    for c, plane in enumerate(gamma if on_planes else gamma.split(1, dim=-3)):
        for weight, offset in zip(weights, (channel_offsets[c] for channel_offsets in offsets)):
            if offset == 0.0:
                continue
            if offset < 0.0:  # a(1 - a), as a - a² in one pass where not exported
                shift = plane * (1.0 - plane) if exporting else torch.addcmul(plane, plane, plane, value=-1.0)
            else:  # the planes are finite and at least 0 (gamma of a bounded frame; each blend keeps them so)
                shift = (plane.sqrt() if in_place else safe_sqrt(plane)) - plane
            if exporting:  # the expression's nodes: an addcmul exports its value as a float32 Constant, whatever the graph's dtype
                plane = plane + 2.0 * offset * weight * shift
            elif in_place:
                plane = plane.addcmul_(weight, shift, value=2.0 * offset)
            else:
                plane = torch.addcmul(plane, weight, shift, value=2.0 * offset)
        planes.append(plane)
    if on_planes:
        return tuple(planes)
    return gamma if in_place else torch.cat(planes, dim=-3)


def _soft_light_masked(base: torch.Tensor, weight: torch.Tensor, offset: torch.Tensor) -> torch.Tensor:
    """:func:`soft_light` with the tint ``0.5 + offset · weight`` for export, with offsets that are graph inputs.

    With ``weight`` in [0, 1] the blend's side of 0.5 is the offset's sign, so the branch is picked per channel by
    ``m = [offset > 0]`` instead of per pixel: ``a + s(m √a + a((1 - 2m) - (1 - m) a))`` with ``s = 2 offset weight``
    is :func:`_lighten` for ``m = 1`` and :func:`_darken` for ``m = 0``, exactly (a 0/1 factor of a finite value).

    Examples:
        >>> base, t, offset = torch.rand(2, 3, 2, 2), torch.rand(2, 1, 2, 2), torch.tensor([[-0.2, 0.0, 0.3], [0.1, -0.4, 0.0]])
        >>> offset = offset.reshape(2, 3, 1, 1)
        >>> bool(torch.allclose(_soft_light_masked(base, t, offset), soft_light(base, 0.5 + offset * t), atol=1e-6))
        True
    """
    lighter = (offset > 0.0).to(base.dtype)
    shift = lighter * safe_sqrt(base) + base * ((1.0 - 2.0 * lighter) - (1.0 - lighter) * base)
    return base + 2.0 * offset * weight * shift


def split_toning(
    image: torch.Tensor, shadows=(0.5, 0.5, 0.5), highlights=(0.5, 0.5, 0.5), balance: Param = 0.0, luminance_weights="rec709"
) -> torch.Tensor:
    """Split toning in gamma 2.2 space (Unity ``ColorGradeSplitToning``).

    ``t = saturate(Y(saturate(c)) + balance/100)``; the shadow tint ``lerp(0.5, shadows, 1 - t)`` and the
    highlight tint ``lerp(0.5, highlights, t)`` are soft-light blended in turn. Grey 0.5 tints are neutral. An image
    given as its three planes (a tuple, :attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`) is toned as planes
    where the tints are numbers, and joined into one image where they are tensors.

    Examples:
        >>> image = torch.rand(3, 2, 2)
        >>> bool(torch.allclose(split_toning(image), image, atol=1e-5))  # grey tints: neutral
        True
    """
    plain = _plain_offsets(shadows), _plain_offsets(highlights)
    if None in plain:
        image = joined(image)  # tensor colours blend the frame
    gamma = each_plane(lambda plane: safe_pow(plane, 1.0 / 2.2), image)
    t = luminance(each_plane(lambda plane: plane.clamp(0.0, 1.0), gamma), luminance_weights)
    if not is_constant(balance, 0.0):
        t = t + scalar_param(balance, t, "split_balance") * 0.01
    t = t.clamp(0.0, 1.0)
    if None not in plain:
        return each_plane(lambda plane: safe_pow(plane, 2.2), _soft_light_by_channel(gamma, (1.0 - t, t), plain))
    offsets = (color_param(shadows, image, "split_shadows") - 0.5, color_param(highlights, image, "split_highlights") - 0.5)
    if is_exporting():
        return safe_pow(_soft_light_masked(_soft_light_masked(gamma, 1.0 - t, offsets[0]), t, offsets[1]), 2.2)
    shadow_tint = 0.5 + offsets[0] * (1.0 - t)
    highlight_tint = 0.5 + offsets[1] * t
    return safe_pow(soft_light(soft_light(gamma, shadow_tint), highlight_tint), 2.2)


def _plain_offsets(color):
    """A split-toning colour given as three numbers, as its offsets from neutral grey ``c - 0.5`` in Python (the branch
    each channel's blend takes is then known without reading the device); ``None`` for a tensor.

    Examples:
        >>> _plain_offsets((0.45, 0.5, 0.56)), _plain_offsets(torch.tensor([0.5, 0.5, 0.5]))
        ((-0.04999999999999999, 0.0, 0.06000000000000005), None)
    """
    if isinstance(color, torch.Tensor) or len(color) != 3 or not all(isinstance(c, (int, float)) for c in color):
        return None
    return tuple(float(c) - 0.5 for c in color)


def channel_mixer(image: torch.Tensor, mixer=IDENTITY_MATRIX) -> torch.Tensor:
    """Channel mixer: ``rgb' = M · rgb``, rows are the output channels (1.0 = Unity's 100%). An image given as its three
    planes (a tuple, :attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`) is returned as planes.

    Examples:
        >>> swap = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
        >>> channel_mixer(torch.tensor([1.0, 2.0, 3.0]).reshape(3, 1, 1), swap).flatten().tolist()
        [2.0, 1.0, 3.0]
    """
    return matrix_on(matrix_param(mixer, like_image(image), "channel_mixer"), image)


def smoothstep(edge0, edge1, x: torch.Tensor) -> torch.Tensor:
    """HLSL ``smoothstep``: ``t²(3 - 2t)`` with ``t = saturate((x - edge0) / (edge1 - edge0))``.

    Examples:
        >>> smoothstep(0.0, 1.0, torch.tensor([-1.0, 0.5, 2.0])).tolist()
        [0.0, 0.5, 1.0]
    """
    t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def shadows_midtones_highlights(
    image: torch.Tensor,
    shadows=(1.0, 1.0, 1.0),
    midtones=(1.0, 1.0, 1.0),
    highlights=(1.0, 1.0, 1.0),
    shadows_start: Param = 0.0,
    shadows_end: Param = 0.3,
    highlights_start: Param = 0.55,
    highlights_end: Param = 1.0,
    luminance_weights="rec709",
) -> torch.Tensor:
    """Zone tints (Unity ``ColorGradingShadowsMidtonesHighlights``), colours sRGB-encoded as in Unity.

    ``ws = 1 - smoothstep(s0, s1, Y)``, ``wh = smoothstep(h0, h1, Y)``, ``wm = 1 - ws - wh``;
    ``rgb' = rgb · (S ws + M wm + H wh)``. An image given as its three planes (a tuple,
    :attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`) is returned as planes.

    Examples:
        >>> image = torch.rand(3, 2, 2)
        >>> bool(torch.equal(shadows_midtones_highlights(image), image))  # white tints change nothing
        True
    """
    lum = luminance(image, luminance_weights)
    shadow_weight = 1.0 - smoothstep(
        scalar_param(shadows_start, lum, "shadows_start"), scalar_param(shadows_end, lum, "shadows_end"), lum
    )
    highlight_weight = smoothstep(
        scalar_param(highlights_start, lum, "highlights_start"), scalar_param(highlights_end, lum, "highlights_end"), lum
    )
    midtone_weight = 1.0 - shadow_weight - highlight_weight
    tints = (srgb_to_linear(color_param(color, lum, name)) for color, name in zip((shadows, midtones, highlights), ("shadows", "midtones", "highlights")))
    return per_channel(lambda x, s, m, h: x * (s * shadow_weight + m * midtone_weight + h * highlight_weight), image, *tints)


def _trackball(value, image: torch.Tensor, name: str) -> tuple:
    """A trackball ``(r, g, b, w)``, or per sample ``(B, 4)``, as its colour and its offset ``w``."""
    t = value if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=image.dtype, device=image.device)
    if t.dim() not in (1, 2) or t.shape[-1] != 4:
        raise ValueError(f"parameter {name!r} must be a trackball (r, g, b, w) or per-sample (B, 4), got shape {tuple(t.shape)}")
    return color_param(t[..., :3], image, name), scalar_param(t[..., 3], image, name)


def _minus_luminance(rgb: torch.Tensor) -> torch.Tensor:
    """``rgb - Y(rgb)`` for colours ``(..., 3, 1, 1)``, as ``sum_j w_j (rgb_i - rgb_j)`` with the Rec.709
    weights normalised to sum 1 (Unity's sum to 1.0000001), so a grey colour gives exactly 0."""
    weights = constant(REC709_LUMINANCE, rgb)
    weights = (weights / weights.sum()).reshape(3, 1, 1)
    return ((rgb.unsqueeze(-3) - rgb.unsqueeze(-4)) * weights).sum(dim=-3)


def _balanced(value, image: torch.Tensor, name: str, scale: float) -> tuple:
    """A trackball's colour decoded and scaled, minus its luminance (so it leaves luminance alone), and its ``w``."""
    rgb, offset = _trackball(value, image, name)
    return _minus_luminance(srgb_to_linear(rgb) * scale), offset


def lift_gamma_gain_coefficients(lift, gamma, gain, image: torch.Tensor) -> tuple:
    """Unity ``ColorUtils.PrepareLiftGammaGain``: ``(lift, 1 / gamma, gain)`` as ``(..., 3, 1, 1)``.

    With ``dec`` the sRGB decode and ``Y`` Rec.709 luminance, for each trackball ``(rgb, w)``:
    ``lift = l - Y(l) + w`` with ``l = dec(rgb) · 0.15``; ``1 / max(g - Y(g) + w + 1, 1e-3)`` with
    ``g = dec(rgb) · 0.8``; ``gain = k - Y(k) + w + 1`` with ``k = dec(rgb) · 0.8``. ``Y`` uses
    weights summing to exactly 1 (see :func:`_minus_luminance`), so identity trackballs give exactly
    ``(0, 1, 1)`` where Unity's are off by 1e-7.

    Examples:
        >>> lift, inverse_gamma, gain = lift_gamma_gain_coefficients(IDENTITY_TRACKBALL, IDENTITY_TRACKBALL, IDENTITY_TRACKBALL, torch.ones(3, 1, 1))
        >>> lift.flatten().tolist(), inverse_gamma.flatten().tolist(), gain.flatten().tolist()
        ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0])
    """
    lift_rgb, lift_offset = _balanced(lift, image, "lift", 0.15)
    gamma_rgb, gamma_offset = _balanced(gamma, image, "gamma", 0.8)
    gain_rgb, gain_offset = _balanced(gain, image, "gain", 0.8)
    inverse_gamma = 1.0 / (gamma_rgb + gamma_offset + 1.0).clamp_min(1e-3)
    return lift_rgb + lift_offset, inverse_gamma, gain_rgb + gain_offset + 1.0


def lift_gamma_gain(image: torch.Tensor, lift=IDENTITY_TRACKBALL, gamma=IDENTITY_TRACKBALL, gain=IDENTITY_TRACKBALL) -> torch.Tensor:
    """Lift, gamma, gain (Unity ``LiftGammaGainHDR``): ``c = rgb · gain + lift``, ``sign(c) |c|^(1/gamma)``.

    The trackballs are prepared by :func:`lift_gamma_gain_coefficients`; the power is mirrored for
    negative values (ACEScg can be negative) and saturates at ±65504 (:func:`~torchgrade.base.core.bounded_pow`):
    Unity's own minimum gamma is a power of 1000, which overflows float32 from 1.1 up.

    An image given as its three planes (a tuple, :attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`) is returned
    as planes.

    Examples:
        >>> lift_gamma_gain(torch.full((3, 1, 1), 0.5), gain=(1.0, 1.0, 1.0, 1.0)).flatten().tolist()  # offset 1: double
        [1.0, 1.0, 1.0]
    """
    return per_channel(_lift_gamma_gain_of, image, *lift_gamma_gain_coefficients(lift, gamma, gain, like_image(image)))


def _lift_gamma_gain_of(x: torch.Tensor, lift: torch.Tensor, inverse_gamma: torch.Tensor, gain: torch.Tensor) -> torch.Tensor:
    """``sign(c) |c|^(1/gamma)`` of ``c = x · gain + lift``, for coefficients that broadcast against ``x``."""
    c = x * gain + lift
    return torch.sign(c) * bounded_pow(c.abs(), inverse_gamma)


def _hsv(image: torch.Tensor) -> tuple:
    """:func:`~torchgrade.color.hsv_planes` of ``image`` (or of its three planes, a tuple), negligible light taken as black."""
    # Hue divides by the chroma (max - min): ACEScg turns a grey 1e-38 into a tinted one, whose hue's gradient overflows.
    lit = channel_max(image) > NEGLIGIBLE_LIGHT
    return hsv_planes(each_plane(lambda plane: where(lit, plane, 0.0), image))


def hue_shift(image: torch.Tensor, degrees: Param, hue_vs_hue=None) -> torch.Tensor:
    """Hue shift in HSV, wrapping around the colour wheel (Unity ``ColorGradingHueShift``); RGB ≥ 0.

    With a ``hue_vs_hue`` curve the shifted hue ``h`` moves on by ``curve(h) - 0.5`` turns (URP ``LutBuilderHdr``).
    An image given as its three planes (a tuple, :attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`) is returned
    as planes.

    Examples:
        >>> red = torch.tensor([1.0, 0.0, 0.0]).reshape(3, 1, 1)
        >>> [round(v, 4) for v in hue_shift(red, 120.0).flatten().tolist()]
        [0.0, 1.0, 0.0]
    """
    hue, sat, value = _hsv(image)
    hue = torch.remainder(hue + scalar_param(degrees, hue, "hue_shift") / 360.0, 1.0)
    if hue_vs_hue is not None:
        hue = torch.remainder(hue + evaluate_curve(hue_vs_hue, hue, periodic=True, name="hue_vs_hue") - 0.5, 1.0)
    return (rgb_planes_from_hsv if isinstance(image, tuple) else rgb_from_hsv_planes)(hue, sat, value)


def saturation_curves(image: torch.Tensor, hue_vs_sat=None, sat_vs_sat=None, lum_vs_sat=None, luminance_weights="rec709") -> torch.Tensor:
    """The saturation factor of the curves (URP ``LutBuilderHdr``), ``(..., 1, H, W)``; RGB ≥ 0, an image or its three
    planes (a tuple, :attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`).

    ``2 HueVsSat(h) · 2 SatVsSat(s) · 2 LumVsSat(Y)`` of the pixel's HSV hue, HSV saturation and
    luminance; curves not given count as 1.

    Examples:
        >>> flat = ((0.0, 0.5), (0.5, 0.5))
        >>> saturation_curves(torch.rand(3, 2, 2), hue_vs_sat=flat).unique().tolist()
        [1.0]
    """
    hue, sat, _ = _hsv(image)
    axes = {"hue_vs_sat": (hue_vs_sat, hue, True), "sat_vs_sat": (sat_vs_sat, sat, False)}
    if lum_vs_sat is not None:
        axes["lum_vs_sat"] = (lum_vs_sat, luminance(image, luminance_weights), False)
    factor = torch.ones_like(hue)
    for name, (points, value, periodic) in axes.items():
        if points is not None:
            factor = factor * (2.0 * evaluate_curve(points, value, periodic, name))
    return factor


def saturation(image: torch.Tensor, amount: Param, luminance_weights="rec709", factor=None) -> torch.Tensor:
    """Saturation about luminance: ``Y + (rgb - Y)(1 + amount/100)``; -100 gives grey ``Y``.

    ``factor`` (from :func:`saturation_curves`) multiplies ``1 + amount/100``, as URP does. An image given as its three
    planes (a tuple, :attr:`~torchgrade.runtime.ExecutionPolicy.pixel_planes`) is returned as planes.

    Examples:
        >>> grey = saturation(torch.tensor([1.0, 0.0, 0.0]).reshape(3, 1, 1), -100.0).flatten()
        >>> bool(grey[0] == grey[1] == grey[2])
        True
    """
    lum = luminance(image, luminance_weights)
    scale = 1.0 + scalar_param(amount, lum, "saturation") * 0.01
    scale = scale if factor is None else scale * factor
    return each_plane(lambda plane: lum + (plane - lum) * scale, image)


def saturation_matrix(image: torch.Tensor, amount: Param, luminance_weights="rec709") -> torch.Tensor:
    """:func:`saturation` without curves as one matrix: ``s I + (1 - s) 1 wᵀ``, ``s = 1 + amount/100`` and ``w`` the
    luminance weights; ``(3, 3)``, or ``(B, 3, 3)`` for a per-sample amount.

    Examples:
        >>> image = torch.rand(1, 3, 2, 2)
        >>> bool(torch.allclose(apply_matrix(saturation_matrix(image, 30.0), image), saturation(image, 30.0), atol=1e-6))
        True
    """
    scale = 1.0 + scalar_param(amount, image, "saturation") * 0.01
    scale = scale.reshape(scale.shape[:1] + (1, 1)) if scale.dim() else scale
    weights = {"rec709": REC709_LUMINANCE, "ap1": AP1_LUMINANCE}[luminance_weights]
    weights = constant(weights, image).expand(3, 3)
    return scale * torch.eye(3, dtype=image.dtype, device=image.device) + (1.0 - scale) * weights


def fast_tonemap(image: torch.Tensor) -> torch.Tensor:
    """Unity ``FastTonemap``: ``c / (1 + max(r, g, b))`` (the max taken ≥ 0), HDR into [0, 1).

    Examples:
        >>> fast_tonemap(torch.tensor([3.0, 1.0, 0.0]).reshape(3, 1, 1)).flatten().tolist()
        [0.75, 0.25, 0.0]
    """
    return image / (1.0 + channel_max(image).clamp_min(0.0))


def fast_tonemap_inverse(image: torch.Tensor) -> torch.Tensor:
    """Unity ``FastTonemapInvert``: ``c / (1 - max(r, g, b))``, the divisor kept ≥ 1/65505 (outputs ≤ 65505).

    Examples:
        >>> fast_tonemap_inverse(torch.tensor([0.75, 0.25, 0.0]).reshape(3, 1, 1)).flatten().tolist()
        [3.0, 1.0, 0.0]
    """
    return image / (1.0 - channel_max(image)).clamp_min(1.0 / (1.0 + HALF_MAX))


def yrgb_curves(image: torch.Tensor, master=None, red=None, green=None, blue=None) -> torch.Tensor:
    """Master, then red/green/blue curves in FastTonemap space, then ``max(0)`` (URP ``LutBuilderHdr``).

    The master curve maps each channel; each colour curve its own. Curves not given leave values alone.

    Examples:
        >>> image = torch.rand(3, 2, 2)
        >>> bool(torch.allclose(yrgb_curves(image, master=((0.0, 0.0), (1.0, 1.0))), image, atol=1e-6))
        True
    """
    x = fast_tonemap(image)
    if master is not None:
        x = evaluate_curve(master, x, name="curve_master")
    curves = {"curve_red": red, "curve_green": green, "curve_blue": blue}
    channels = [c if p is None else evaluate_curve(p, c, name=n) for c, (n, p) in zip(x.split(1, dim=CHANNEL), curves.items())]
    return fast_tonemap_inverse(torch.cat(channels, dim=CHANNEL)).clamp_min(0.0)
