"""Unity's custom-pipeline bloom in float64 NumPy, transcribed from the shader passes and ``DoBloom`` of the
project's source documents (``../shared/seeds/004``: ``BloomPrefilterPassFragment``,
``BloomPrefilterFirefliesPassFragment``, ``BloomHorizontalPassFragment``, ``BloomVerticalPassFragment``,
``BloomAddPassFragment``, ``BloomScatterPassFragment``, ``BloomScatterFinalPassFragment``, ``ApplyBloomThreshold``
and ``PostFXStack.DoBloom``), and Unity's ``SampleTexture2DBicubic`` (``Filtering.hlsl`` of its render pipeline
core). Written from that text, not from torchgrade.

Render textures are sampled as a GPU samples them: bilinear filtering at normalised coordinates (texel ``i`` of a
side of ``n`` centred at ``(i + 0.5) / n``), with the sampler's address mode applied to each texel index of the 2x2
footprint: ``"clamp"`` is Unity's ``sampler_linear_clamp``; ``"mirror"`` (half-sample symmetric, a GPU's MIRROR
mode) is the one sampler state in which torchgrade's edge rule differs. Textures are float64 (Unity's are half
floats). Images are ``(H, W, 3)`` arrays.
"""

import numpy as np

LUMINANCE = np.array([0.2126729, 0.7151522, 0.0721750])
"""Unity's ``Luminance`` (``Color.hlsl``) of linear Rec.709."""

HORIZONTAL_OFFSETS = np.arange(-4.0, 5.0)
HORIZONTAL_WEIGHTS = np.array([0.01621622, 0.05405405, 0.12162162, 0.19459459, 0.22702703,
                               0.19459459, 0.12162162, 0.05405405, 0.01621622])
VERTICAL_OFFSETS = np.array([-3.23076923, -1.38461538, 0.0, 1.38461538, 3.23076923])
VERTICAL_WEIGHTS = np.array([0.07027027, 0.31621622, 0.22702703, 0.31621622, 0.07027027])
FIREFLY_OFFSETS = [(0.0, 0.0), (-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)]


def texel(index: np.ndarray, size: int, address: str) -> np.ndarray:
    """The texel an integer index reads under the sampler's address mode."""
    if address == "clamp":
        return np.clip(index, 0, size - 1)
    period = np.mod(index, 2 * size)
    return np.where(period < size, period, 2 * size - 1 - period)


def sample(texture: np.ndarray, u: np.ndarray, v: np.ndarray, address: str) -> np.ndarray:
    """``SAMPLE_TEXTURE2D`` with bilinear filtering at normalised ``(u, v)`` (broadcast together): ``(..., 3)``."""
    height, width = texture.shape[:2]
    x, y = np.asarray(u, dtype=np.float64) * width - 0.5, np.asarray(v, dtype=np.float64) * height - 0.5
    x, y = np.broadcast_arrays(x, y)
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)

    def fetch(row, column):
        return texture[texel(row, height, address), texel(column, width, address)]

    top = (1 - fx) * fetch(y0, x0) + fx * fetch(y0, x0 + 1)
    bottom = (1 - fx) * fetch(y0 + 1, x0) + fx * fetch(y0 + 1, x0 + 1)
    return (1 - fy) * top + fy * bottom


def bicubic_filter(fraction: np.ndarray):
    """``BicubicFilter``: the two weights and offsets of the 4 bilinear taps that make the cubic B-spline."""
    x = fraction
    rightmost = 0.16666667 + x * (-0.5 + x * (0.5 - x * 0.16666667))
    middle_right = 0.66666667 + x * (-1.0 + 0.5 * x) * x
    middle_left = 0.16666667 + x * (0.5 + x * (0.5 - x * 0.5))
    leftmost = 1.0 - middle_right - middle_left - rightmost
    weights = (rightmost + middle_right, middle_left + leftmost)
    offsets = (-1.0 + middle_right / weights[0], 1.0 + leftmost / weights[1])
    return weights, offsets


def sample_bicubic(texture: np.ndarray, u: np.ndarray, v: np.ndarray, address: str, max_coord=1.0) -> np.ndarray:
    """``SampleTexture2DBicubic(tex, sampler, uv, texSize, maxCoord = 1.0)``.

    ``maxCoord`` keeps the taps inside the used part of a texture (1.0: all of it). With clamped addressing it
    changes no value (a tap past 1.0 reads the edge texel either way; a test checks it); with mirrored addressing
    it would clamp at one edge and mirror at the other, so ``max_coord=None`` leaves it out there.
    """
    height, width = texture.shape[:2]
    u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
    xy = (u * width + 0.5, v * height + 0.5)
    whole = [np.floor(c) for c in xy]
    (wx, ox), (wy, oy) = (bicubic_filter(c - f) for c, f in zip(xy, whole))

    def tap(offset_x, offset_y):
        tu, tv = (whole[0] + offset_x - 0.5) / width, (whole[1] + offset_y - 0.5) / height
        if max_coord is not None:
            tu, tv = np.minimum(tu, max_coord), np.minimum(tv, max_coord)
        return sample(texture, tu, tv, address)

    w = lambda a: a[..., None]  # noqa: E731
    return (w(wy[0]) * (w(wx[0]) * tap(ox[0], oy[0]) + w(wx[1]) * tap(ox[1], oy[0]))
            + w(wy[1]) * (w(wx[0]) * tap(ox[0], oy[1]) + w(wx[1]) * tap(ox[1], oy[1])))


def centres(height: int, width: int):
    """The normalised coordinates of a ``height x width`` target's pixel centres: ``u (1, W)``, ``v (H, 1)``."""
    return (np.arange(width) + 0.5)[None, :] / width, (np.arange(height) + 0.5)[:, None] / height


def gamma_to_linear(value: float) -> float:
    """``Mathf.GammaToLinearSpace``: the sRGB transfer function."""
    return value / 12.92 if value <= 0.04045 else ((value + 0.055) / 1.055) ** 2.4


def threshold_vector(threshold: float, knee: float) -> np.ndarray:
    """``DoBloom``'s ``_BloomThreshold``."""
    x = gamma_to_linear(threshold)
    y = x * knee
    z = 2.0 * y
    w = 0.25 / (y + 0.00001)
    return np.array([x, y - x, z, w])


def apply_bloom_threshold(color: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``ApplyBloomThreshold``."""
    brightness = color.max(axis=-1)
    soft = np.clip(brightness + t[1], 0.0, t[2])
    soft = soft * soft * t[3]
    contribution = np.maximum(soft, brightness - t[0])
    contribution /= np.maximum(brightness, 0.00001)
    return color * contribution[..., None]


def prefilter(source: np.ndarray, size, t: np.ndarray, fade_fireflies: bool, address: str) -> np.ndarray:
    """``BloomPrefilterPassFragment`` or ``BloomPrefilterFirefliesPassFragment`` into a ``size`` target."""
    u, v = centres(*size)
    if not fade_fireflies:
        return apply_bloom_threshold(sample(source, u, v, address), t)
    height, width = source.shape[:2]
    color, weight_sum = 0.0, 0.0
    for dx, dy in FIREFLY_OFFSETS:
        c = apply_bloom_threshold(sample(source, u + dx / width * 2.0, v + dy / height * 2.0, address), t)
        w = 1.0 / (c @ LUMINANCE + 1.0)
        color = color + c * w[..., None]
        weight_sum = weight_sum + w
    return color / weight_sum[..., None]


def horizontal(source: np.ndarray, size, address: str) -> np.ndarray:
    """``BloomHorizontalPassFragment`` into a ``size`` target: 9 taps 2 source texels apart."""
    u, v = centres(*size)
    width = source.shape[1]
    return sum(w * sample(source, u + o * 2.0 / width, v, address) for o, w in zip(HORIZONTAL_OFFSETS, HORIZONTAL_WEIGHTS))


def vertical(source: np.ndarray, address: str) -> np.ndarray:
    """``BloomVerticalPassFragment`` into a target of the source's size: 5 bilinear taps."""
    height, width = source.shape[:2]
    u, v = centres(height, width)
    return sum(w * sample(source, u, v + o / height, address) for o, w in zip(VERTICAL_OFFSETS, VERTICAL_WEIGHTS))


def combine(low: np.ndarray, high: np.ndarray, intensity: float, scatter: bool, bicubic: bool, address: str,
            t=None) -> np.ndarray:
    """``BloomAddPassFragment``, ``BloomScatterPassFragment`` or (with ``t``) ``BloomScatterFinalPassFragment`` into
    a target of ``high``'s size."""
    u, v = centres(*high.shape[:2])
    max_coord = 1.0 if address == "clamp" else None
    low_res = sample_bicubic(low, u, v, address, max_coord) if bicubic else sample(low, u, v, address)
    high_res = sample(high, u, v, address)
    if not scatter:
        return low_res * intensity + high_res
    if t is not None:
        low_res = low_res + high_res - apply_bloom_threshold(high_res, t)
    return high_res + (low_res - high_res) * intensity


def unity_bloom(image: np.ndarray, *, mode="additive", threshold=1.0, knee=0.5, intensity=1.0, scatter=0.7,
                max_iterations=16, downscale_limit=2, fade_fireflies=True, bicubic=False, address="clamp") -> np.ndarray:
    """``PostFXStack.DoBloom`` and its final draw: the bloomed ``image`` ``(H, W, 3)``, or ``image`` where Unity skips
    bloom."""
    image = np.asarray(image, dtype=np.float64)
    width, height = image.shape[1] // 2, image.shape[0] // 2
    if max_iterations == 0 or intensity <= 0 or height < downscale_limit * 2 or width < downscale_limit * 2:
        return image
    t = threshold_vector(threshold, knee)
    source = prefilter(image, (height, width), t, fade_fireflies, address)
    width, height = width // 2, height // 2
    levels = []
    for _ in range(max_iterations):
        if height < downscale_limit or width < downscale_limit:
            break
        source = vertical(horizontal(source, (height, width), address), address)
        levels.append(source)
        width, height = width // 2, height // 2
    scattering = mode == "scattering"
    glow = levels[-1]
    for level in reversed(levels[:-1]):
        glow = combine(glow, level, scatter if scattering else 1.0, scattering, bicubic, address)
    final_intensity = min(intensity, 1.0) if scattering else intensity
    return combine(glow, image, final_intensity, scattering, bicubic, address, t if scattering else None)
