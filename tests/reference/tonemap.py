"""Independent float64 references of every tone mapper, written pixel by pixel from their sources."""

import math
import warnings

import numpy as np

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour

from .pixels import LUM709, random_rgb

def ref_reinhard(rgb):
    c = np.clip(rgb, 0, 60)
    return c / (1 + c)


def ref_reinhard_extended(rgb, w=4.0):
    c = np.clip(rgb, 0, None)
    return np.clip(c * (1 + c / w**2) / (1 + c), 0, 1)


def ref_reinhard_luminance(rgb, w=4.0):
    lum = rgb @ LUM709
    out = np.empty_like(rgb)
    for i, (pixel, l_old) in enumerate(zip(rgb, lum)):
        l_new = l_old * (1 + l_old / w**2) / (1 + l_old)
        out[i] = pixel * (l_new / l_old) if l_old > 0 else pixel
    return np.clip(out, 0, 1)


def hable_t(x, a, b, c, d, e, f):
    return (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f


def ref_neutral(rgb):
    k = (0.2, 0.29, 0.24, 0.272, 0.02, 0.3)
    scale = 1 / hable_t(5.3, *k)
    return np.clip(hable_t(np.clip(rgb, 0, 60) * scale, *k) * scale, 0, 1)


def ref_hable(rgb, bias=2.0, w=11.2):
    k = (0.15, 0.50, 0.10, 0.20, 0.02, 0.30)
    return np.clip(hable_t(np.clip(rgb, 0, 60) * bias, *k) / hable_t(w, *k), 0, 1)


# --- Unity's AcesTonemap, written pixel by pixel with the shader's branches (ACES.hlsl, Color.hlsl) ---
SRGB_2_AP0 = np.array([[0.4397010, 0.3829780, 0.1773350], [0.0897923, 0.8134230, 0.0967616], [0.0175440, 0.1115440, 0.8707040]])


def _rgb_to_xyz(primaries, white):
    """SMPTE RP 177: the primaries' XYZ columns scaled so that RGB (1, 1, 1) is the white."""
    def xyz(x, y):
        return np.array([x / y, 1.0, (1 - x - y) / y])
    columns = np.stack([xyz(*p) for p in primaries], axis=1)
    return columns * np.linalg.solve(columns, xyz(*white))


def _bradford(source_white, target_white):
    cone = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]])
    def xyz(x, y):
        return np.array([x / y, 1.0, (1 - x - y) / y])
    return np.linalg.inv(cone) @ np.diag((cone @ xyz(*target_white)) / (cone @ xyz(*source_white))) @ cone


ACES_WHITE, D65 = (0.32168, 0.33767), (0.3127, 0.3290)
REC709_2_AP0_BRADFORD = (np.linalg.inv(_rgb_to_xyz(((0.7347, 0.2653), (0.0, 1.0), (0.0001, -0.077)), ACES_WHITE))
                         @ _bradford(D65, ACES_WHITE) @ _rgb_to_xyz(((0.64, 0.33), (0.30, 0.60), (0.15, 0.06)), D65))
"""Linear Rec.709 -> ACES2065-1 as OpenColorIO's configs build it (primaries, Bradford D65 -> ACES white)."""
AP0_2_AP1 = np.array([[1.4514393161, -0.2365107469, -0.2149285693], [-0.0765537734, 1.1762296998, -0.0996759264], [0.0083161484, -0.0060324498, 0.9977163014]])
AP1_2_XYZ = np.array([[0.6624541811, 0.1340042065, 0.1561876870], [0.2722287168, 0.6740817658, 0.0536895174], [-0.0055746495, 0.0040607335, 1.0103391003]])
XYZ_2_AP1 = np.array([[1.6410233797, -0.3248032942, -0.2364246952], [-0.6636628587, 1.6153315917, 0.0167563477], [0.0117218943, -0.0082844420, 0.9883948585]])
XYZ_2_REC709 = np.array([[3.2409699419, -1.5373831776, -0.4986107603], [-0.9692436363, 1.8759675015, 0.0415550574], [0.0556300797, -0.2039769589, 1.0569715142]])
D60_2_D65 = np.array([[0.98722400, -0.00611327, 0.0159533], [-0.00759836, 1.00186000, 0.0053302], [0.00307257, -0.00509595, 1.0816800]])
AP1_Y = np.array([0.272229, 0.674082, 0.0536895])


def smoothstep_hue_weight(centered_hue):
    """Unity's red-modifier weight: ``smoothstep(0, 1, 1 - |2 h / 135|)²``."""
    u = min(max(1 - abs(2 * centered_hue / 135), 0), 1)
    return (u * u * (3 - 2 * u)) ** 2


def aces_pixel(rgb):
    aces = rrt_glow_and_red(SRGB_2_AP0 @ np.clip(rgb, 0, 60), smoothstep_hue_weight)
    cg = sat_adjust(np.maximum(AP0_2_AP1 @ aces, 0), 0.96, AP1_Y)  # Unity rounds AP1's luminance row
    post = cg * (2.785085 * cg + 0.107772) / (cg * (2.936045 * cg + 0.887122) + 0.806889)
    xyz = AP1_2_XYZ @ post
    total = max(xyz.sum(), 1e-4)
    cx, cy = xyz[0] / total, xyz[1] / total
    big_y = min(max(xyz[1], 0), 65504) ** 0.9811
    m = big_y / max(cy, 1e-4)
    linear = sat_adjust(XYZ_2_AP1 @ np.array([cx * m, big_y, (1 - cx - cy) * m]), 0.93, AP1_Y)
    return np.clip(XYZ_2_REC709 @ (D60_2_D65 @ (AP1_2_XYZ @ linear)), 0, 1)


def ref_aces(rgb):
    return np.array([aces_pixel(p) for p in rgb])


# --- ACES 1.0.3 RRT + ODT RGBmonitor_100nits_dim, written from the CTL pixel by pixel ---
AP1_RGB2Y = AP1_2_XYZ[1]
SPLINE_M = np.array([[0.5, -1.0, 0.5], [-1.0, 1.0, 0.5], [0.5, 0.0, 0.0]])
RRT_PARAMS = dict(
    low=[-4.0, -4.0, -3.1573765773, -0.4852499958, 1.8477324706, 1.8477324706],
    high=[-0.7185482425, 2.0810307172, 3.6681241237, 4.0, 4.0, 4.0],
    min=(0.18 * 2.0**-15, 0.0001), mid=(0.18, 4.8), max=(0.18 * 2.0**18, 10000.0), slope_low=0.0, slope_high=0.0, knots=4,
)


def segmented_spline_fwd(x, c):
    logx = math.log10(max(x, 5.96046448e-08))
    lmin, lmid, lmax = (math.log10(c[k][0]) for k in ("min", "mid", "max"))
    if logx <= lmin:
        return 10 ** (logx * c["slope_low"] + (math.log10(c["min"][1]) - c["slope_low"] * lmin))
    if logx >= lmax:
        return 10 ** (logx * c["slope_high"] + (math.log10(c["max"][1]) - c["slope_high"] * lmax))
    coefs, start, end = (c["low"], lmin, lmid) if logx < lmid else (c["high"], lmid, lmax)
    knot_coord = (c["knots"] - 1) * (logx - start) / (end - start)
    j = int(knot_coord)
    t = knot_coord - j
    return 10 ** (np.array([t * t, t, 1.0]) @ (np.array(coefs[j : j + 3]) @ SPLINE_M))


ODT_48NITS = dict(
    low=[-1.6989700043, -1.6989700043, -1.4779, -1.2291, -0.8648, -0.448, 0.00518, 0.4511080334, 0.9113744414, 0.9113744414],
    high=[0.5154386965, 0.8470437783, 1.1358, 1.3802, 1.5197, 1.5985, 1.6467, 1.6746091357, 1.687873339, 1.687873339],
    min=(segmented_spline_fwd(0.18 * 2.0**-6.5, RRT_PARAMS), 0.02),
    mid=(segmented_spline_fwd(0.18, RRT_PARAMS), 4.8),
    max=(segmented_spline_fwd(0.18 * 2.0**6.5, RRT_PARAMS), 48.0),
    slope_low=0.0, slope_high=0.04, knots=8,
)


def cubic_basis_shaper(x, w):
    m = [[-1 / 6, 3 / 6, -3 / 6, 1 / 6], [3 / 6, -6 / 6, 3 / 6, 0], [-3 / 6, 0, 3 / 6, 0], [1 / 6, 4 / 6, 1 / 6, 0]]
    knots = [-w / 2, -w / 4, 0, w / 4, w / 2]
    if not knots[0] < x < knots[4]:
        return 0.0
    knot_coord = (x - knots[0]) * 4 / w
    j = int(knot_coord)
    t = knot_coord - j
    monomials = [t**3, t**2, t, 1.0]
    return sum(monomials[i] * m[i][3 - j] for i in range(4)) * 1.5


def rrt_glow_and_red(aces, hue_weight, tiny=1e-4):
    """Unity floors the saturation's terms at 1e-4 (half precision); the CTL's TINY is 1e-10."""
    ma, mi = aces.max(), aces.min()
    sat = (max(ma, tiny) - max(mi, tiny)) / max(ma, 1e-2)
    r, g, b = aces
    yc = (r + g + b + 1.75 * math.sqrt(max(b * (b - g) + g * (g - r) + r * (r - b), 0))) / 3
    x = (sat - 0.4) / 0.2
    t = max(1 - abs(x / 2), 0)
    s = (1 + math.copysign(1, x) * (1 - t * t)) / 2 if x != 0 else 0.5
    gain = 0.05 * s
    glow = gain if yc <= 2 / 3 * 0.08 else 0.0 if yc >= 2 * 0.08 else gain * (0.08 / yc - 0.5)
    aces = aces * (1 + glow)
    r, g, b = aces
    hue = 0.0 if r == g == b else math.degrees(math.atan2(math.sqrt(3) * (g - b), 2 * r - g - b))
    hue = hue + 360 if hue < 0 else hue
    centered = hue - 360 if hue > 180 else hue
    aces[0] += hue_weight(centered) * sat * (0.03 - aces[0]) * (1 - 0.82)
    return aces


def sat_adjust(rgb, factor, weights=AP1_RGB2Y):
    return factor * rgb + (1 - factor) * (rgb @ weights)


def aces_reference_pixel(rgb):
    # rrt.ctl takes every ACES value (negative and beyond 60 included) through glow and red modifier
    aces = rrt_glow_and_red(REC709_2_AP0_BRADFORD @ rgb, lambda h: cubic_basis_shaper(h, 135.0), tiny=1e-10)
    pre = sat_adjust(np.clip(AP0_2_AP1 @ np.maximum(aces, 0), 0, 65504), 0.96)
    oces = np.linalg.inv(AP0_2_AP1) @ np.array([segmented_spline_fwd(v, RRT_PARAMS) for v in pre])
    post = np.array([segmented_spline_fwd(v, ODT_48NITS) for v in AP0_2_AP1 @ oces])
    linear_cv = (post - 0.02) / (48.0 - 0.02)
    xyz = AP1_2_XYZ @ linear_cv  # darkSurround_to_dimSurround, in xyY
    total = xyz.sum() if xyz.sum() != 0 else 1e-10
    cx, cy, big_y = xyz[0] / total, xyz[1] / total, max(xyz[1], 0) ** 0.9811
    linear_cv = XYZ_2_AP1 @ np.array([cx * big_y / max(cy, 1e-10), big_y, (1 - cx - cy) * big_y / max(cy, 1e-10)])
    linear_cv = sat_adjust(linear_cv, 0.93)
    return np.clip(XYZ_2_REC709 @ (D60_2_D65 @ (AP1_2_XYZ @ linear_cv)), 0, 1)


def ref_aces_reference(rgb):
    return np.array([aces_reference_pixel(p) for p in rgb])


def ref_aces_hill(rgb):
    aces_input = np.array([[0.59719, 0.35458, 0.04823], [0.07600, 0.90834, 0.01566], [0.02840, 0.13383, 0.83777]])
    aces_output = np.array([[1.60475, -0.53108, -0.07367], [-0.10208, 1.10813, -0.00605], [-0.00327, -0.07276, 1.07602]])
    v = np.clip(rgb, 0, 60) @ aces_input.T
    fit = (v * (v + 0.0245786) - 0.000090537) / (v * (0.983729 * v + 0.4329510) + 0.238081)
    return np.clip(fit @ aces_output.T, 0, 1)


def ref_aces_narkowicz(rgb):
    x = np.clip(rgb, 0, 60) * 0.6
    return np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0, 1)


def glsl_mat3(*columns):
    """A GLSL ``mat3(...)`` (column-major arguments) as a row-major numpy matrix."""
    return np.array(columns, dtype=np.float64).reshape(3, 3).T


AGX_MIN_EV, AGX_MAX_EV = -12.4739311883324, 4.02606881166759


def ref_agx(rgb):
    """Wrensch's minimal AgX (agx, agxDefaultContrastApprox, agxEotf) as published in GLSL."""
    inset = glsl_mat3(0.842479062253094, 0.0423282422610123, 0.0423756549057051, 0.0784335999999992, 0.878468636469772,
                      0.0784336, 0.0792237451477643, 0.0791661274605434, 0.879142973793104)
    outset = glsl_mat3(1.19687900512017, -0.0528968517574562, -0.0529716355144438, -0.0980208811401368, 1.15190312990417,
                       -0.0980434501171241, -0.0990297440797205, -0.0989611768448433, 1.15107367264116)
    with np.errstate(divide="ignore"):
        val = np.clip(np.log2(np.clip(rgb, 0, 60) @ inset.T), AGX_MIN_EV, AGX_MAX_EV)
    x = (val - AGX_MIN_EV) / (AGX_MAX_EV - AGX_MIN_EV)
    x2, x4 = x * x, x**4
    val = 15.5 * x4 * x2 - 40.14 * x4 * x + 31.96 * x4 - 6.868 * x2 * x + 0.4298 * x2 + 0.1191 * x - 0.00232
    return np.clip(np.maximum(val @ outset.T, 0) ** 2.2, 0, 1)


def ref_agx_godot(rgb):
    """Godot 4.4's tonemap_agx as published in GLSL, then the display clip."""
    inset = glsl_mat3(0.54490813676363087053, 0.14044005884001287035, 0.088827411851915368603, 0.37377945959812267119,
                      0.75410959864013760045, 0.17887712465043811023, 0.081384976686647875101, 0.10543358536857773485,
                      0.73224999956948382528)
    outset = glsl_mat3(1.9645509602733325934, -0.29932243390911083839, -0.16436833806080403409, -0.85585845117807513559,
                       1.3264510741502356555, -0.23822464068860595117, -0.10886710826831608324, -0.027084020983874825605,
                       1.402665347143271889)
    color = np.maximum(np.clip(rgb, 0, 60), 2e-10) @ inset.T
    color = (np.clip(np.log2(color), AGX_MIN_EV, AGX_MAX_EV) - AGX_MIN_EV) / (AGX_MAX_EV - AGX_MIN_EV)
    x2, x4 = color * color, color**4
    color = 0.021 * color + 4.0111 * x2 - 25.682 * x2 * color + 70.359 * x4 - 74.778 * x4 * color + 27.069 * x4 * x2
    return np.clip(np.maximum(color, 0) ** 2.4 @ outset.T, 0, 1)


def khronos_pixel(color):
    start_compression, desaturation = 0.8 - 0.04, 0.15
    x = color.min()
    offset = x - 6.25 * x * x if x < 0.08 else 0.04
    color = color - offset
    peak = color.max()
    if peak < start_compression:
        return color
    d = 1 - start_compression
    new_peak = 1 - d * d / (peak + d - start_compression)
    color = color * (new_peak / peak)
    g = 1 - 1 / (desaturation * (peak - new_peak) + 1)
    return color * (1 - g) + new_peak * g


def ref_khronos_pbr_neutral(rgb):
    return np.clip([khronos_pixel(p) for p in np.clip(rgb, 0, 60)], 0, 1)


def ref_filmic(rgb, a=0.15, b=0.50, c=0.10, d=0.20, e=0.02, f=0.30, w=11.2, bias=2.0):
    return np.clip(hable_t(np.clip(rgb, 0, 60) * bias, a, b, c, d, e, f) / hable_t(w, a, b, c, d, e, f), 0, 1)


def film_tone_map_channel(log_color, slope, toe, shoulder, black_clip, white_clip):
    """Unreal's FilmToneMap curve for one channel (TonemapCommon.ush), with its branches."""
    toe_scale, shoulder_scale = 1 + black_clip - toe, 1 + white_clip - shoulder
    if toe > 0.8:
        toe_match = (1 - toe - 0.18) / slope + math.log10(0.18)
    else:
        bt = (0.18 + black_clip) / toe_scale - 1
        toe_match = math.log10(0.18) - 0.5 * math.log((1 + bt) / (1 - bt)) * (toe_scale / slope)
    straight_match = (1 - toe) / slope - toe_match
    shoulder_match = shoulder / slope - straight_match
    straight = slope * (log_color + straight_match)
    toe_color = -black_clip + (2 * toe_scale) / (1 + math.exp(min((-2 * slope / toe_scale) * (log_color - toe_match), 700)))
    shoulder_color = (1 + white_clip) - (2 * shoulder_scale) / (1 + math.exp(min((2 * slope / shoulder_scale) * (log_color - shoulder_match), 700)))
    toe_color = toe_color if log_color < toe_match else straight
    shoulder_color = shoulder_color if log_color > shoulder_match else straight
    t = min(max((log_color - toe_match) / (shoulder_match - toe_match), 0), 1)
    t = 1 - t if shoulder_match < toe_match else t
    t = (3 - 2 * t) * t * t
    return toe_color + t * (shoulder_color - toe_color)


def unreal_filmic_pixel(rgb, slope=0.88, toe=0.55, shoulder=0.26, black_clip=0.0, white_clip=0.04):
    aces = rrt_glow_and_red(SRGB_2_AP0 @ np.clip(rgb, 0, 60), smoothstep_hue_weight)
    working = sat_adjust(np.maximum(AP0_2_AP1 @ aces, 0), 0.96)
    # Black as log10 = -1000: HLSL's -inf would make the final lerp 0 · inf.
    log_color = [math.log10(v) if v > 0 else -1000.0 for v in working]
    tone = np.array([film_tone_map_channel(v, slope, toe, shoulder, black_clip, white_clip) for v in log_color])
    tone = np.maximum(sat_adjust(tone, 0.93), 0)
    return np.clip(XYZ_2_REC709 @ (D60_2_D65 @ (AP1_2_XYZ @ tone)), 0, 1)


def ref_unreal_filmic(rgb, **controls):
    return np.array([unreal_filmic_pixel(p, **controls) for p in rgb])


def ref_bt2390_pq(e1, min_nits, max_nits):
    """ITU-R BT.2390-4 section 5.4.1 with L_B = 0 and L_W = 10000 cd/m^2, on PQ values."""
    max_lum, min_lum = colour.models.eotf_inverse_ST2084(max_nits), colour.models.eotf_inverse_ST2084(min_nits)
    ks = 1.5 * max_lum - 0.5
    t = (np.minimum(e1, 1.0) - ks) / (1 - ks)
    p = (2 * t**3 - 3 * t**2 + 1) * ks + (t**3 - 2 * t**2 + t) * (1 - ks) + (-2 * t**3 + 3 * t**2) * max_lum
    e2 = np.where(e1 < ks, e1, p)
    return e2 + min_lum * (1 - e2) ** 4


def ref_unity_reinhard(nits, peak):
    m = 10000.0 * peak / (10000.0 - peak)
    return nits * m / (nits + m)


def ref_neutral_hdr(rgb, paper_white=203.0, min_nits=0.005, peak=1000.0, hue_shift=0.0, method="bt2390"):
    """Unity HDROutput.hlsl HDRMappingFromRec709 (Rec.2020 output, BT.2390 or Reinhard range reduction)."""
    to_2020 = colour.matrix_RGB_to_RGB(colour.RGB_COLOURSPACES["ITU-R BT.709"], colour.RGB_COLOURSPACES["ITU-R BT.2020"])
    nits = np.minimum(rgb @ to_2020.T * paper_white, 10000.0)  # the PQ range
    pq, unpq = colour.models.eotf_inverse_ST2084, colour.models.eotf_ST2084
    if method == "bt2390":
        reduce_pq, reduce_nits = (lambda e: ref_bt2390_pq(e, min_nits, peak)), (lambda x: unpq(ref_bt2390_pq(pq(x), min_nits, peak)))
    else:
        reduce_pq, reduce_nits = (lambda e: pq(ref_unity_reinhard(unpq(e), peak))), (lambda x: ref_unity_reinhard(x, peak))
    ictcp = colour.RGB_to_ICtCp(nits, method="ITU-R BT.2100-2 PQ")
    reduced = reduce_pq(ictcp[:, 0])
    saturation = np.minimum(1.0, reduced / np.maximum(ictcp[:, 0], 1e-6)) ** 2
    keeping = colour.ICtCp_to_RGB(np.stack([reduced, ictcp[:, 1] * saturation, ictcp[:, 2] * saturation], 1), method="ITU-R BT.2100-2 PQ")
    out = (1 - hue_shift) * keeping + hue_shift * reduce_nits(nits)
    return np.clip(out / peak, 0, 1)


REFERENCES = {
    "none": lambda rgb: np.clip(rgb, 0, 1),
    "reinhard": ref_reinhard,
    "reinhard_extended": ref_reinhard_extended,
    "reinhard_luminance": ref_reinhard_luminance,
    "neutral": ref_neutral,
    "aces": ref_aces,
    "hable": ref_hable,
    "filmic": ref_filmic,
    "unreal_filmic": ref_unreal_filmic,
    "aces_reference": ref_aces_reference,
    "aces_hill": ref_aces_hill,
    "aces_narkowicz": ref_aces_narkowicz,
    "agx": ref_agx,
    "agx_godot": ref_agx_godot,
    "khronos_pbr_neutral": ref_khronos_pbr_neutral,
    "neutral_hdr": ref_neutral_hdr,
}


def hdr_samples():
    rgb = random_rgb(400, high=1.0, seed=3) ** 3 * 80.0  # 0..80, dense near 0
    rgb[:12] = np.array([0.0, 0.01, 0.18, 0.5, 1, 2, 4, 8, 16, 59, 60, 200])[:, None]  # greys
    rgb[12:15] = np.eye(3) * 5.0  # saturated primaries
    return rgb
