"""Pyramid bloom: the :func:`bloom` functional, the :class:`Bloom` stage and its export form.

The passes follow Unity's custom-pipeline bloom (``DoBloom`` and the ``Bloom*`` shader passes):
prefilter at half resolution (:mod:`~torchgrade.bloom.prefilter`), a pyramid of levels blurred by Unity's 9 taps
down to ``downscale_limit`` pixels, at most ``max_iterations`` levels (:mod:`~torchgrade.bloom.pyramid`: every level
spans the frame, at every size), and the mode's composite (:mod:`~torchgrade.bloom.composite`).

**Engine options** (all off by default; at their defaults the output is bit-identical to Unity's settings alone):

* ``mode``: Bevy's ``"energy_conserving"`` and Godot's ``"screen"``, ``"softlight"``, ``"replace"``,
  ``"mix"`` besides Unity's ``"additive"`` and ``"scattering"`` (:data:`~torchgrade.bloom.COMPOSITES`);
  ``low_frequency_boost``, ``low_frequency_boost_curvature``, ``high_pass_frequency`` are Bevy's.
* ``karis_average`` (Karis 2013): each 2x2 block's source is the ``1 / (1 + Y)``-weighted mean of
  its pixels, capped per channel at the mean, so a lone hot pixel in a block hardly blooms.
* ``clamp`` (Unity's Bloom Clamp, default 65472 there): the block source is ``min(source, clamp)``
  per channel before the threshold. The default here, 65504, is the non-finite policy's bound: no clamp.
  Both keep the light accounting exact.
* ``anamorphic_ratio`` in [-1, 1]: each level is blurred by a Gaussian with ``sigma_x = 1.69 * 2^ratio`` and
  ``sigma_y = 1.69 * 2^-ratio`` (23 taps; 1.69 is the standard deviation of Unity's 9 taps; positive stretches the glow horizontally, negative
  vertically; HDRP's sign is the opposite). Blurs stay mirror-padded, so scattering still conserves light.
* ``tint`` (Unity's Bloom Tint): the glow is multiplied by ``srgb_to_linear(tint)``, given
  sRGB-encoded like Unity's colour picker. Scattering conserves light only at white.
* ``dirt`` and ``dirt_intensity`` (Unity's Lens Dirt): ``output += dirt_intensity * dirt * glow``,
  with the glow at full resolution (``intensity`` and ``tint`` applied) and the dirt texture
  ``(C, h, w)`` (C = 1 or 3) resampled bilinearly to the frame (stretched). It adds light in every mode.
"""

from __future__ import annotations

import inspect
import numbers
from typing import Optional

import torch
from torch import nn

from ..base.images import HALF_MAX, check_image, sanitize, to_input_dtype, working_dtype
from ..base.params import Param, color_param, is_constant, is_plain_number, scalar_param
from ..base.controls import Control, controls_signature
from ..base.stage import Stage
from ..color import srgb_to_linear
from ..runtime import constant
from .composite import BLOOM_MODES, COMPOSITES
from .prefilter import prefilter
from .blur import anamorphic_sigma
from .pyramid import active_levels, glow_pyramid, over_blocks, pyramid_depth, upsample
from .texture import as_texture, check_texture, resampled

__all__ = ["CONTROLS", "UNITY_SETTINGS", "OPTION_DEFAULTS", "MAX_FRAME_SIDE", "check_settings", "bloom_settings", "bloom", "bloom_with_settings", "Bloom",
           "FixedDepthBloom"]

# Finite bounds make every documented value safe on any finite frame: a threshold of 100 is linear
# 62,500 (srgb_to_linear), just below the non-finite policy's 65,504, and gains up to 100 keep
# 100 · 100 · 65,504 far from float32's overflow. 16 is Unity's k_MaxPyramidSize.
MAX_THRESHOLD = 100.0
MAX_GAIN = 100.0

CONTROLS = {
    "mode": Control("additive", BLOOM_MODES),
    "threshold": Control(1.0, (0.0, MAX_THRESHOLD)),
    "knee": Control(0.5, (0.0, 1.0)),
    "intensity": Control(1.0, (0.0, MAX_GAIN)),
    "scatter": Control(0.7, (0.05, 0.95)),
    "max_iterations": Control(16, (0, 16)),
    "downscale_limit": Control(2, (1, 16384)),  # MAX_FRAME_SIDE: no frame has a larger side
    "fade_fireflies": Control(True),
    "bicubic_upsampling": Control(False),
    "tint": Control((1.0, 1.0, 1.0), (0.0, MAX_GAIN)),
    "clamp": Control(HALF_MAX, (0.0, 1e6)),  # above 65504 it changes nothing: the source is already bounded there
    "anamorphic_ratio": Control(0.0, (-1.0, 1.0)),
    "karis_average": Control(False),
    "dirt": Control(None),
    "dirt_intensity": Control(0.0, (0.0, MAX_GAIN)),
    "low_frequency_boost": Control(0.7, (0.0, 1.0)),
    "low_frequency_boost_curvature": Control(0.95, (0.0, 0.99)),
    "high_pass_frequency": Control(1.0, (0.01, 1.0)),
}
"""Every bloom control with its default and range (``tint`` per channel, sRGB-encoded), in :func:`bloom`'s order."""

UNITY_SETTINGS = tuple(CONTROLS)[: tuple(CONTROLS).index("tint")]
"""Unity's settings, always in a config; the engine options after them appear only when not at their defaults."""

OPTION_DEFAULTS = {name: control.default for name, control in CONTROLS.items() if name not in UNITY_SETTINGS}
"""The engine options and their defaults (Bevy's for its three), at which Unity's bloom is unchanged."""


def check_settings(settings: dict) -> None:
    """Raise ``ValueError`` naming the first setting outside its :data:`CONTROLS` entry (as :class:`Bloom` does). A
    tensor's values are not read (on a GPU each read would wait for the device): a stage checks its own when they are
    set, and its learnable ones before every forward.

    Examples:
        >>> check_settings({"scatter": 0.99})
        Traceback (most recent call last):
        ...
        ValueError: scatter must lie in [0.05, 0.95], got 0.99
        >>> check_settings({"scatter": torch.tensor(0.99)})  # not read
    """
    for name, value in settings.items():
        if not isinstance(value, torch.Tensor):
            CONTROLS[name].check(name, value)
    check_texture(settings.get("dirt"), "dirt", values=False)


def bloom_settings(given: dict) -> dict:
    """Every setting of :data:`CONTROLS`, in its order: ``given`` (flags as bools) or the default.

    Raises ``TypeError`` for a name that is not a bloom setting, as a misspelt keyword would.

    Examples:
        >>> settings = bloom_settings({"intensity": 0.5, "karis_average": 1})
        >>> settings["intensity"], settings["karis_average"], settings["scatter"]
        (0.5, True, 0.7)
    """
    unknown = sorted(set(given) - set(CONTROLS))
    if unknown:
        raise TypeError(f"unknown bloom setting(s) {unknown}; known: {', '.join(CONTROLS)}")
    settings = {name: given.get(name, control.default) for name, control in CONTROLS.items()}
    return {name: bool(value) if CONTROLS[name].kind == "bool" else value for name, value in settings.items()}


def bloom(image: torch.Tensor, *, fixed_depth: Optional[int] = None, **settings) -> torch.Tensor:
    """Bloom an HDR image ``(..., 3, H, W)``; see :mod:`torchgrade.bloom` for the passes and guarantees.

    Keyword Args:
        mode: one of :data:`~torchgrade.bloom.BLOOM_MODES`: ``"additive"`` (``image + intensity * glow``),
            ``"scattering"`` (moves light; conserves it), ``"energy_conserving"`` (Bevy's), or Godot's
            ``"screen"``, ``"softlight"``, ``"replace"``, ``"mix"``.
        threshold: gamma-space threshold >= 0 (Unity's inspector units); linear ``srgb_to_linear(threshold)``.
        knee: soft-knee width in [0, 1], as a fraction of the linear threshold.
        intensity: >= 0; clamped to 1 in the lerp modes (scattering, energy_conserving, mix).
        scatter: in [0.05, 0.95] (Unity's slider); weight of the lower level in scattering mode.
        max_iterations: most pyramid levels (>= 0).
        downscale_limit: smallest level side in pixels (>= 1).
        fade_fireflies: luminance-weighted 5-tap prefilter.
        bicubic_upsampling: cubic B-spline instead of bilinear upsampling.
        tint: sRGB-encoded RGB >= 0 multiplying the glow, ``(3,)`` or ``(B, 3)``.
        clamp: >= 0, upper bound of each block's bloom source per channel (Unity's Bloom Clamp).
        anamorphic_ratio: in [-1, 1]; stretches the blur horizontally (> 0) or vertically (< 0).
        karis_average: Karis' luminance-weighted 2x2 average in the prefilter.
        dirt: lens dirt texture ``(1 or 3, h, w)``, resampled to the frame.
        dirt_intensity: >= 0, weight of the dirt-modulated glow added to the output.
        low_frequency_boost: Bevy's control of the energy-conserving level weights, in [0, 1].
        low_frequency_boost_curvature: Bevy's control of the energy-conserving level weights, in [0, 0.99].
        high_pass_frequency: Bevy's control of the energy-conserving level weights, in [0.01, 1].

    Continuous parameters are numbers, 0-d tensors or per-sample ``(B,)`` tensors, differentiable.

    ``fixed_depth``: build that many pyramid levels whatever the frame size and mask out, with tensor
    arithmetic on the runtime shape (:func:`~torchgrade.bloom.active_levels`), the levels this frame
    does not have. The result equals the default path for every frame whose own depth is at most
    ``fixed_depth``; it is the form a traced (ONNX) graph uses, so one graph serves every resolution: its steps take
    the forms of any size (:mod:`~torchgrade.bloom.pyramid`).

    Identity cases return the input object untouched: ``intensity`` a plain 0 (in every mode,
    ``replace`` included), or a pyramid of depth 0 (a side of the quarter-resolution level below
    ``downscale_limit``, or ``max_iterations == 0``). In additive mode, when no block reaches the
    knee, the output equals the sanitized input exactly. Options at their defaults (white tint, clamp 65504, ratio 0,
    dirt intensity 0) are not computed.

    Examples:
        >>> image = torch.zeros(1, 3, 16, 16); image[..., 8, 8] = 100.0
        >>> out = bloom(image, mode="scattering")
        >>> round(float(out.sum() / image.sum()), 4), bool(out[..., 8, 0].gt(0).all())
        (1.0, True)
    """
    check_image(image)
    settings = bloom_settings(settings)
    check_settings(settings)
    return bloom_with_settings(image, settings, fixed_depth)


vars(bloom)["__signature__"] = controls_signature(  # what help() and inspect.signature show
    {**CONTROLS, "fixed_depth": Control(None)}, leading=(inspect.Parameter("image", inspect.Parameter.POSITIONAL_OR_KEYWORD),)
)


def bloom_with_settings(image: torch.Tensor, settings: dict, fixed_depth=None, *, nan_free: bool = False) -> torch.Tensor:
    """:func:`bloom` on ``settings`` already checked (every one of :func:`bloom_settings`): depth, identity shortcuts,
    working precision, prefilter, composite. Nothing is read back: a stage's controls were checked when set, and
    random ones are drawn inside their ranges. ``nan_free``: ``image`` holds no NaN (:func:`~torchgrade.base.images.sanitize`)."""
    height, width = image.shape[-2:]
    most, limit = settings["max_iterations"], settings["downscale_limit"]
    active: int | torch.Tensor
    if fixed_depth is None:
        depth = active = pyramid_depth(height, width, most, limit)
    else:
        depth, active = fixed_depth, active_levels(image, min(most, fixed_depth), limit)
    if depth == 0 or is_constant(settings["intensity"], 0.0):
        return image

    scene = sanitize(working_dtype(image), nan_free=nan_free).reshape(-1, 3, height, width)
    reference = scene if image.dim() == 4 else scene[0]  # per-sample parameters need a (B, 3, H, W) image

    def param(name):
        convert = color_param if name == "tint" else scalar_param
        return convert(settings[name], reference, name)

    def number_or_param(name):  # a number folds into terms made once (runtime.folded)
        return settings[name] if is_plain_number(settings[name]) else param(name)

    any_size = fixed_depth is not None
    bound = None if is_constant(settings["clamp"], HALF_MAX) else param("clamp")
    light, fraction = prefilter(scene, number_or_param("threshold"), number_or_param("knee"), settings["fade_fireflies"],
                                settings["karis_average"], bound, any_size)
    out = _composited(scene, light, fraction, settings, param, depth, active, any_size)
    if isinstance(active, torch.Tensor) and not COMPOSITES[settings["mode"]].zero_is_identity:  # any_size
        out = torch.where(active > 0, out, scene)  # a frame too small for any level is not bloomed
    return to_input_dtype(out.reshape(image.shape), image)


def _composited(scene, light, fraction, settings: dict, param, depth: int, active, any_size: bool) -> torch.Tensor:
    """The glow of the prefiltered ``light`` at full resolution (tint, lens dirt) blended into ``scene`` by the mode;
    ``any_size``: the fixed-depth form, its levels masked by ``active`` (:func:`bloom`)."""
    composite = COMPOSITES[settings["mode"]]
    bicubic = settings["bicubic_upsampling"]
    strength = param("intensity")
    if composite.lerp:  # a lerp's weight is at most 1; a plain number is bounded before it is a constant (no launch)
        number = settings["intensity"]
        strength = constant(min(float(number), 1.0), strength) if is_plain_number(number) else strength.clamp(max=1.0)
    sigma = None if is_constant(settings["anamorphic_ratio"], 0.0) else anamorphic_sigma(param("anamorphic_ratio"))
    weight = None if composite.level_weight is None else composite.level_weight(param, active, strength)
    glow = glow_pyramid(light, depth, weight, bicubic, sigma, active if any_size else None, any_size)
    if any_size:
        # A frame too small for any level is not bloomed: intensity 0 leaves it as it is in every mode whose
        # ``zero_is_identity`` holds, for the cost of a scalar product instead of a frame-sized select.
        strength = strength * (active > 0)
    glow = upsample(strength * glow, [light.shape[-2:], scene.shape[-2:]], bicubic, any_size)
    if not is_constant(settings["tint"], 1.0):
        glow = glow * srgb_to_linear(param("tint"))
    lens = None
    if settings["dirt"] is not None and not is_constant(settings["dirt_intensity"], 0.0):
        lens = param("dirt_intensity") * resampled(settings["dirt"], scene.shape[-2:], scene) * glow
        glow = glow.clone()  # the lens term keeps the glow for its gradient; the blend overwrites it
    if composite.scatters:  # the share each block keeps scales the frame's 2x2 blocks: no frame of it is written
        image, glow_blocks, kept = over_blocks(1.0 - strength * fraction, scene, glow, any_size=any_size)
        out = composite.blend(image, glow_blocks, strength, kept).reshape(scene.shape)
    else:
        out = composite.blend(scene, glow, strength, None)
    return out if lens is None else out + lens


class Bloom(Stage):
    """Bloom stage; ``Bloom(...)(image)`` is :func:`bloom` with the stored settings.

    Continuous controls may be numbers (kept as floats), tensors (registered as buffers, so they
    follow ``.to(device)``) or ``nn.Parameter`` (registered as parameters, so ``parameters()`` yields
    them and they can be learned); ``dirt`` is a buffer. ``to_config()`` returns the constructor
    arguments as plain Python values: Unity's always, the engine options when not at their defaults.

    Examples:
        >>> stage = Bloom(mode="scattering", intensity=0.5, tint=(1.0, 0.9, 0.8))
        >>> stage.to_config()["tint"], stage.is_identity, Bloom(max_iterations=0).is_identity
        ([1.0, 0.9, 0.8], False, True)
        >>> stage(torch.rand(1, 3, 16, 16)).shape
        torch.Size([1, 3, 16, 16])
    """

    controls = CONTROLS
    always_in_config = UNITY_SETTINGS
    intensity: Param
    max_iterations: int
    downscale_limit: int

    def __init__(self, **controls) -> None:
        super().__init__()
        self.init_controls(**controls)

    def check_control(self, name: str, value):
        """Numbers kept as floats and colours as float tuples (so configs read as given); ``dirt`` checked as a texture."""
        if name == "dirt":
            value = as_texture(value)
            check_texture(value, "dirt")
            return value
        kind = self.control_table()[name].kind
        if kind == "bool":
            return bool(value)
        return _as_floats(value) if kind == "number" else value

    def is_default(self, name: str) -> bool:
        # a tensor (a per-sample value, a buffer) is written even at its default: a config lists every tensor it was given
        return not isinstance(getattr(self, name), torch.Tensor) and super().is_default(name)

    @property
    def is_identity(self) -> bool:
        """True when no image can change: no pyramid level (``max_iterations == 0``) or ``intensity`` a plain 0."""
        return self.max_iterations == 0 or is_constant(self.intensity, 0.0)

    def forward(self, image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
        check_image(image)
        return bloom_with_settings(image, self.params(), nan_free=nan_free)

    def export_form(self) -> nn.Module:
        """The fixed-depth form (:class:`FixedDepthBloom`) that one ONNX graph serves every frame size with."""
        return FixedDepthBloom(self)


Bloom.__signature__ = controls_signature(CONTROLS)


def _as_floats(value):
    """Python numbers as floats, sequences of them as tuples of floats; tensors as they are."""
    if isinstance(value, torch.Tensor):
        return value
    return float(value) if isinstance(value, numbers.Real) else tuple(float(v) for v in value)


MAX_FRAME_SIDE = 16384
"""Largest frame side an exported bloom serves exactly: the graph holds that frame's pyramid depth."""


class FixedDepthBloom(nn.Module):
    """:class:`Bloom` as a traced graph runs it: every level a frame up to :data:`MAX_FRAME_SIDE` a side
    can have is built, and the levels a frame does not have are masked out at run time
    (:func:`bloom`'s ``fixed_depth``), so one graph serves every frame size.

    Examples:
        >>> stage = Bloom(intensity=0.5)
        >>> image = torch.rand(1, 3, 24, 40) * 4
        >>> bool(torch.allclose(FixedDepthBloom(stage)(image), stage(image), atol=1e-6))
        True
    """

    takes_nan_free = True  # as the stage (Stage.takes_nan_free)

    def __init__(self, stage: Bloom):
        super().__init__()
        self.stage = stage
        self.depth = pyramid_depth(MAX_FRAME_SIDE, MAX_FRAME_SIDE, stage.max_iterations, stage.downscale_limit)

    def forward(self, image: torch.Tensor, *, nan_free: bool = False) -> torch.Tensor:
        check_image(image)
        return bloom_with_settings(image, self.stage.params(), fixed_depth=self.depth, nan_free=nan_free)
