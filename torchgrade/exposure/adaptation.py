"""Temporal adaptation and the middle-grey operator: one frame of eye adaptation as a pure function
(:func:`auto_exposure`), with the controls table and checks the module shares."""

from __future__ import annotations

from typing import Optional, cast

import torch

from ..base.images import HALF_MAX, check_image, sanitize, to_input_dtype, working_dtype
from ..base.params import Param, check_choice, check_range, is_plain_number, scalar_param
from ..base.controls import Control
from ..color import luminance
from ..runtime import constant
from .metering import (HISTOGRAM_BLOCK, HISTOGRAM_RANGE, METERING_MASKS, METERING_MODES, meter_histogram, meter_sanitized,
                       metering_weights)

__all__ = ["CONTROLS", "MIN_LUMINANCE", "MAX_ADAPTED", "OPERATORS", "STOPS_RANGE", "adapt_luminance", "auto_exposure", "check_bounds",
           "check_step", "checked_control", "compensation_at", "exposed_frame", "exposure_key", "exposure_operator", "metered_luminance"]

MIN_LUMINANCE = 1e-3
"""Default lower bound of the adapted luminance: the largest exposure gain is ``middle_grey / 1e-3``."""

MAX_ADAPTED = HALF_MAX
"""Default upper bound of the adapted luminance: the non-finite policy's bound, so no limit in practice."""

# Positive luminances stop at 1e-6 and middle grey at 100 (the largest gain is then 1e8), max_luminance at 0.01
# (Reinhard divides by its square): Reinhard's operator and its gradients stay finite in float32 on 65504.
SMALLEST, MAX_MIDDLE_GREY, MIN_WHITE = 1e-6, 100.0, 0.01

OPERATORS = ("exposure", "reinhard")

STOPS_RANGE = (-32.0, 32.0)
"""Range of every control in stops (limits, compensation, the curve, fixed exposure): 2^32 either way."""

MAX_COMPENSATION_POINTS = 64
"""Most ``(metered stops, compensation stops)`` pairs a compensation curve holds (a grading curve's own limit is
:data:`torchgrade.grading.curves.MAX_CURVE_POINTS`)."""
MAX_MASK_SIDE = 4096


CONTROLS = {
    "middle_grey": Control(0.18, (SMALLEST, MAX_MIDDLE_GREY)),
    "max_luminance": Control(16.0, (MIN_WHITE, HALF_MAX)),
    "speed": Control(1.0, (0.0, HALF_MAX)),
    "metering": Control("log", METERING_MODES),
    "operator": Control("exposure", OPERATORS),
    "speed_to_light": Control(None, (0.0, HALF_MAX)),
    "speed_to_dark": Control(None, (0.0, HALF_MAX)),
    "min_luminance": Control(MIN_LUMINANCE, (SMALLEST, HALF_MAX)),
    "max_adapted": Control(MAX_ADAPTED, (SMALLEST, HALF_MAX)),
    "metering_mask": Control("average", kind="value"),
    "low_percent": Control(40.0, (0.0, 100.0)),
    "high_percent": Control(90.0, (0.0, 100.0)),
    "histogram_block": Control(HISTOGRAM_BLOCK, (1, 16)),  # 16x16 blocks at most
    "min_ev": Control(None, STOPS_RANGE),
    "max_ev": Control(None, STOPS_RANGE),
    "compensation": Control(0.0, STOPS_RANGE),
    "compensation_curve": Control(None, kind="value"),
    "fixed_exposure": Control(None, STOPS_RANGE),
}
"""The controls of :func:`auto_exposure` and :class:`~torchgrade.exposure.AutoExposure`: defaults and documented ranges."""


def _numbers(value) -> torch.Tensor:
    return torch.as_tensor(value, dtype=torch.float64).detach().cpu()


def check_bounds(min_luminance, max_adapted, min_ev=None, max_ev=None, low_percent=40.0, high_percent=90.0, metering="log") -> None:
    """Raise ``ValueError`` where a lower bound exceeds its upper one: ``min_luminance`` and ``max_adapted``,
    ``min_ev`` and ``max_ev``, and, for histogram metering, ``low_percent`` and ``high_percent`` (an empty band).

    Examples:
        >>> check_bounds(1e-3, 1.0, min_ev=2.0, max_ev=1.0)
        Traceback (most recent call last):
        ...
        ValueError: min_ev ([2.0]) must be below max_ev ([1.0])
    """
    pairs = [("min_luminance", min_luminance, "max_adapted", max_adapted, False)]
    if min_ev is not None and max_ev is not None:
        pairs.append(("min_ev", min_ev, "max_ev", max_ev, True))
    if metering == "histogram":
        pairs.append(("low_percent", low_percent, "high_percent", high_percent, True))
    for low_name, low, high_name, high, strict in pairs:
        if any(isinstance(v, torch.Tensor) and v.is_meta for v in (low, high)):
            continue  # a stage moved to the meta device holds no values to compare
        low, high = _numbers(low), _numbers(high)
        if bool((low >= high).any() if strict else (low > high).any()):
            relation = "be below" if strict else "not exceed"
            raise ValueError(f"{low_name} ({low.reshape(-1).tolist()}) must {relation} {high_name} ({high.reshape(-1).tolist()})")


def histogram_range(min_ev, max_ev) -> tuple:
    """The stops around middle grey the histogram spans: :data:`HISTOGRAM_RANGE`, widened to the limits where they
    reach beyond it. Wider than the limits, so a scene scaled by ``2^k`` meters ``k`` stops more until a limit holds it.

    Examples:
        >>> histogram_range(None, torch.tensor(12.0))
        (-8.0, tensor(12.))
    """
    low, high = HISTOGRAM_RANGE
    return (low if min_ev is None else torch.clamp(min_ev, max=low), high if max_ev is None else torch.clamp(max_ev, min=high))


def check_metering_mask(mask):
    """``"average"``, ``"center"``, ``"spot"``, or a 2-D mask of finite weights >= 0 with some weight (a list made a
    tensor), at most :data:`MAX_MASK_SIDE` a side; ``ValueError`` otherwise.

    Examples:
        >>> check_metering_mask([[0.0, 1.0], [1.0, 0.0]]).shape
        torch.Size([2, 2])
    """
    if isinstance(mask, str):
        check_choice("metering_mask", mask, METERING_MASKS)
        return mask
    if isinstance(mask, (list, tuple)):
        try:
            mask = torch.tensor(mask, dtype=torch.get_default_dtype())
        except (TypeError, ValueError, RuntimeError, OverflowError) as error:
            raise ValueError(f"metering_mask must be one of {METERING_MASKS} or a 2-D grid of weights: {error}") from None
    if not isinstance(mask, torch.Tensor) or mask.dim() != 2 or not mask.is_floating_point() or min(mask.shape) < 1:
        raise ValueError(f"metering_mask must be one of {METERING_MASKS} or a 2-D float tensor of weights, got {mask!r:.80}")
    if max(mask.shape) > MAX_MASK_SIDE:
        raise ValueError(f"metering_mask must be at most {MAX_MASK_SIDE} a side, got shape {tuple(mask.shape)}")
    weights = mask.detach().double()
    if not bool(weights.isfinite().all()) or bool((weights < 0).any()) or not bool((weights > 0).any()):
        raise ValueError("metering_mask must hold finite weights >= 0, at least one of them > 0")
    return mask


def check_compensation_curve(curve):
    """``None``, or 2 to :data:`MAX_COMPENSATION_POINTS` ``(metered stops, compensation stops)`` pairs in
    :data:`STOPS_RANGE` with the metered stops increasing, as a tuple of float pairs; ``ValueError`` otherwise.

    Examples:
        >>> check_compensation_curve([[-8, -3], [0, 0]])
        ((-8.0, -3.0), (0.0, 0.0))
    """
    if curve is None:
        return None
    try:
        points = tuple((float(ev), float(stops)) for ev, stops in curve)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"compensation_curve must be a list of [metered stops, compensation stops] pairs, got {curve!r:.80}") from None
    if not 2 <= len(points) <= MAX_COMPENSATION_POINTS:
        raise ValueError(f"compensation_curve must have 2 to {MAX_COMPENSATION_POINTS} points, got {len(points)}")
    low, high = STOPS_RANGE
    if not all(low <= v <= high for point in points for v in point):
        raise ValueError(f"compensation_curve values must lie in [{low}, {high}] stops, got {list(points)}")
    if not all(a[0] < b[0] for a, b in zip(points, points[1:])):
        raise ValueError(f"compensation_curve's metered stops must increase, got {[p[0] for p in points]}")
    return points


def checked_control(name: str, value):
    """Control ``name`` of :data:`CONTROLS`, checked (a list made a tensor): the table's
    choices or range, and a positive control (range from :data:`SMALLEST`) named as such."""
    if name == "metering_mask":
        return check_metering_mask(value)
    if name == "compensation_curve":
        return check_compensation_curve(value)
    value = _from_list(value)
    control = CONTROLS[name]
    if control.kind == "int":
        return control.check(name, value)
    if control.kind == "choice":
        check_choice(name, value, control.range)
    elif value is not None:
        t = value.detach() if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=torch.float64)
        if control.range[0] > 0 and not bool((t > 0).all()):
            raise ValueError(f"{name} must be a number > 0, got {t.tolist()}")
        check_range(value, name, *control.range)
    return value


def _check_controls(controls: dict) -> None:
    """Validate :func:`auto_exposure`'s controls against :data:`CONTROLS` and order the bounds."""
    for name, value in controls.items():
        checked_control(name, value)
    check_bounds(**{name: controls[name] for name in BOUNDS})


BOUNDS = ("min_luminance", "max_adapted", "min_ev", "max_ev", "low_percent", "high_percent", "metering")
"""The controls :func:`check_bounds` orders."""


def _from_list(value):
    """A per-sample control written as a list (as ``AutoExposure.to_config()`` writes it) as a tensor."""
    return torch.tensor(value, dtype=torch.get_default_dtype()) if isinstance(value, (list, tuple)) else value


def adapt_luminance(
    adapted: torch.Tensor, metered: torch.Tensor, dt, speed=1.0, speed_to_light=None, speed_to_dark=None
) -> torch.Tensor:
    """Move ``adapted`` towards ``metered``: ``adapted + (metered - adapted) * (1 - exp(-dt * speed))``.

    Exponential adaptation (the document's formula with its direction corrected, see the module
    docstring): ``dt = 0`` keeps ``adapted``, a long ``dt`` reaches ``metered``. As in HDRP's
    automatic exposure, ``speed_to_light`` (the scene got brighter: ``metered > adapted``) and
    ``speed_to_dark`` (it got darker) replace ``speed`` when given. Arguments broadcast.

    Examples:
        >>> adapted, metered = torch.tensor(1.0), torch.tensor(2.0)
        >>> adapt_luminance(adapted, metered, torch.tensor(0.0)).item(), adapt_luminance(adapted, metered, torch.tensor(100.0)).item()
        (1.0, 2.0)
    """
    if speed_to_light is not None or speed_to_dark is not None:
        to_light = speed if speed_to_light is None else speed_to_light
        to_dark = speed if speed_to_dark is None else speed_to_dark
        to_light, to_dark = (s.to(metered) if isinstance(s, torch.Tensor) else constant(float(s), metered) for s in (to_light, to_dark))
        speed = torch.where(metered > adapted, to_light, to_dark)
    return adapted + (metered - adapted) * -torch.expm1(-dt * speed)


def exposure_operator(
    image: torch.Tensor, adapted: torch.Tensor, middle_grey, max_luminance, operator: str = "exposure"
) -> torch.Tensor:
    """Expose ``image`` so that luminance ``adapted`` maps to ``middle_grey``; arguments broadcast.

    With ``scaled = L * middle_grey / adapted``:

    * ``"exposure"``: ``rgb * middle_grey / adapted`` (scene-referred, ``rgb * scaled / L``);
    * ``"reinhard"``: ``rgb * compressed / L`` with
      ``compressed = scaled * (1 + scaled / max_luminance²) / (1 + scaled)`` (Reinhard 2002, Eq. 4),
      computed as ``(middle_grey / adapted) / (1 + scaled) * (1 + scaled / max_luminance²)``, which
      never divides by ``L`` and stays finite at every control's bound (the product of the two gains first
      overflowed, and a black channel times infinity is NaN). Negative luminances (out-of-gamut pixels) use the
      curve's slope at 0.

    Examples:
        >>> exposure_operator(torch.full((3, 1, 1), 0.72), torch.tensor(0.72), 0.18, 16.0).flatten().tolist()
        [0.18000000715255737, 0.18000000715255737, 0.18000000715255737]
    """
    gain = middle_grey / adapted
    if operator == "exposure":
        return image * gain
    check_choice("operator", operator, OPERATORS)
    scaled = (luminance(image) * gain).clamp_min(0)
    return image * (gain / (1 + scaled) * (1 + scaled / (max_luminance * max_luminance)))


def _previous_state(adapted: Param, image: torch.Tensor) -> torch.Tensor:
    """The incoming adapted luminance as 0-d or ``(B, 1, 1, 1)``: a number, 0-d or ``image.shape[:-3]``."""
    t = torch.as_tensor(adapted, dtype=image.dtype, device=image.device)
    if t.dim() == 0:
        return t
    if t.shape != image.shape[:-3]:
        raise ValueError(f"adapted must have shape {tuple(image.shape[:-3])} (one value per image), got {tuple(t.shape)}")
    return t.reshape(t.shape + (1, 1, 1))


def auto_exposure(
    image: torch.Tensor,
    adapted: Optional[torch.Tensor] = None,
    dt: Param = 0.0,
    *,
    middle_grey: Param = 0.18,
    max_luminance: Param = 16.0,
    speed: Param = 1.0,
    speed_to_light: Optional[Param] = None,
    speed_to_dark: Optional[Param] = None,
    min_luminance: Param = MIN_LUMINANCE,
    max_adapted: Param = MAX_ADAPTED,
    metering: str = "log",
    operator: str = "exposure",
    metering_mask="average",
    low_percent: Param = 40.0,
    high_percent: Param = 90.0,
    histogram_block: int = HISTOGRAM_BLOCK,
    min_ev: Optional[Param] = None,
    max_ev: Optional[Param] = None,
    compensation: Param = 0.0,
    compensation_curve=None,
    fixed_exposure: Optional[Param] = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """One frame of eye adaptation, stateless: ``(image, adapted, dt) -> (exposed image, new adapted)``.

    Stops are counted from middle grey: a frame whose metered luminance is ``middle_grey`` meters 0 stops,
    ``log2(L / middle_grey)`` in general (EV relative to middle grey, not EV100: an image's values are relative
    until calibrated; for a frame in cd/m², EV100 = ``log2(L * 100 / 12.5)``, HDRP's and Unreal's K = 12.5).

    1. ``metered = meter_luminance(image, metering, metering_mask, ...)`` (``"histogram"`` averages the
       ``[low_percent, high_percent]`` band of the histogram over ±8 stops, or the limits where wider, counted a
       value for each square of ``histogram_block`` pixels a side, the mean of its stops; 1 counts every pixel),
       bounded to ``[min_ev, max_ev]`` stops (HDRP's Limit Min/Max, Unreal's Min/Max EV100) and to
       ``[min_luminance, max_adapted]``;
    2. ``new = adapt_luminance(adapted, metered, dt, speed, ...)``, bounded the same way; where ``adapted``
       is ``None`` or ``<= 0`` (no history: a first frame) ``new = metered``, so a server starts a
       sequence by feeding zeros; a NaN or infinite state or ``dt`` starts it again the same way. With
       ``fixed_exposure`` (stops; HDRP's Fixed mode, Unreal's Manual) nothing is metered: the target is
       ``middle_grey * 2^-fixed_exposure``, not limited, reached at once on a first frame and at the adaptation's
       speed from a state (a change of fixed exposure mid-sequence eases in, and a served graph keeps its inputs);
    3. the image is exposed with ``new`` by :func:`exposure_operator` with the key
       ``middle_grey * 2^(compensation + curve(stops of new))`` (``compensation_curve``: piecewise-linear
       ``(metered stops, compensation stops)`` points, constant past its ends, not applied to a fixed exposure)
       and bounded to ±65504. ``new`` is finite and at least ``min_luminance``, so the exposed frame has no NaN.

    ``adapted`` and the returned state have shape ``image.shape[:-3]`` (``(B,)`` for a batch).
    Every number control is a number, a 0-d tensor or a per-sample ``(B,)`` tensor. Differentiable with
    respect to the image (through the operator and the metering: histogram metering carries the gradient of
    the pixels it averages, not of its choice of pixels), ``middle_grey`` and the other continuous controls.
    Bounds: ``MIN_LUMINANCE`` (1e-3) keeps the gain of a black frame finite; ``MAX_ADAPTED`` (65504) sets no
    upper limit.

    Examples:
        >>> exposed, adapted = auto_exposure(torch.full((1, 3, 4, 4), 0.72), None, metering='mean')
        >>> round(exposed.mean().item(), 4), [round(v, 4) for v in adapted.tolist()]
        (0.18, [0.72])
        >>> exposed, _ = auto_exposure(torch.full((1, 3, 4, 4), 0.72), None, metering='histogram', min_ev=-1.0, max_ev=1.0)
        >>> round(exposed.mean().item(), 4)  # 0.72 is 2 stops over grey: the limit leaves it 1 stop over
        0.36
    """
    check_image(image)
    controls = dict(
        middle_grey=middle_grey, max_luminance=max_luminance, speed=speed, metering=metering, operator=operator,
        speed_to_light=speed_to_light, speed_to_dark=speed_to_dark, min_luminance=min_luminance, max_adapted=max_adapted,
        metering_mask=metering_mask, low_percent=low_percent, high_percent=high_percent, histogram_block=histogram_block,
        min_ev=min_ev, max_ev=max_ev,
        compensation=compensation, compensation_curve=compensation_curve, fixed_exposure=fixed_exposure,
    )
    _check_given(controls, dt)
    return exposed_frame(image, adapted, dt, **controls)


def _check_given(controls: dict, dt) -> None:
    """:func:`auto_exposure`'s controls and step checked as the stage checks them, where they are plain values, the mask
    and the curve in the forms the operator takes (written back into ``controls``): a tensor's values are not read (on
    a GPU each read would wait for the device; a stage checks its own when they are set, and its learnable ones before
    every forward)."""
    for name, value in controls.items():
        if not isinstance(value, torch.Tensor):
            checked = checked_control(name, value)
            if name in ("metering_mask", "compensation_curve"):
                controls[name] = checked
    bounds = {name: controls[name] for name in BOUNDS}
    if not any(isinstance(value, torch.Tensor) for value in bounds.values()):
        check_bounds(**bounds)
    if not isinstance(dt, torch.Tensor):
        check_range(dt, "dt", 0.0, HALF_MAX)


def check_step(dt) -> None:
    """Raise ``ValueError`` unless a number ``dt`` lies in [0, 65504], checked in Python; a tensor is not read
    (a stage's forward reads nothing back from the device): a negative, NaN or infinite step there restarts the
    sequence as :func:`auto_exposure` says.

    Examples:
        >>> check_step(-1.0)
        Traceback (most recent call last):
        ...
        ValueError: dt must lie in [0.0, 65504.0], got -1.0
    """
    if isinstance(dt, torch.Tensor):
        return
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not 0.0 <= dt <= HALF_MAX:
        raise ValueError(f"dt must lie in [0.0, {HALF_MAX}], got {dt!r}")


NOT_NUMBERS = ("metering", "operator", "metering_mask", "histogram_block", "compensation_curve")
"""The controls that are not numbers a frame broadcasts: choices, the mask, the histogram's block and the curve."""


def exposed_frame(image: torch.Tensor, adapted: Optional[torch.Tensor], dt: Param, *, nan_free: bool = False,
                  **controls) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`auto_exposure` of controls already checked (a stage's), reading nothing back from the device.
    ``nan_free``: ``image`` holds no NaN (:func:`~torchgrade.base.images.sanitize`)."""
    x = working_dtype(image)
    c = {name: None if value is None else scalar_param(value, x, name) for name, value in controls.items() if name not in NOT_NUMBERS}
    scene = sanitize(x, nan_free=nan_free)
    if c["fixed_exposure"] is not None:
        target = (cast(torch.Tensor, c["middle_grey"]) * torch.exp2(-c["fixed_exposure"])).expand(x.shape[:-3] + (1, 1, 1))
        new = _adapted(scene, target, adapted, dt, c, limited=False)
    else:
        new = _adapted(scene, metered_luminance(scene, c, controls), adapted, dt, c)
    key = exposure_key(new, c, controls["compensation_curve"])
    # new is finite and positive, so the exposed frame has no NaN: bounding it is the whole non-finite policy
    exposed = exposure_operator(scene, new, key, c["max_luminance"], controls["operator"])
    return to_input_dtype(exposed.clamp(-HALF_MAX, HALF_MAX), image), new.reshape(x.shape[:-3])


def exposure_key(adapted: torch.Tensor, c: dict, curve) -> torch.Tensor:
    """The luminance ``adapted`` is exposed to: ``middle_grey * 2^(compensation + curve(log2(adapted / middle_grey)))``,
    the curve left out for a fixed exposure (``c``: the number controls as :func:`~torchgrade.base.params.scalar_param` tensors).
    The exposure applied is ``log2(key / adapted)`` stops."""
    stops = c["compensation"]
    if c["fixed_exposure"] is None:
        stops = stops + compensation_at(curve, torch.log2(adapted / c["middle_grey"]))
    return c["middle_grey"] * torch.exp2(stops)


def metered_luminance(scene: torch.Tensor, c: dict, controls: dict) -> torch.Tensor:
    """The sanitized frame's metered luminance, ``(..., 1, 1, 1)``, bounded by the limits (``c``: the number
    controls as :func:`~torchgrade.base.params.scalar_param` tensors; ``controls``: all of them as given)."""
    if controls["metering"] == "histogram":
        low, high = histogram_range(c["min_ev"], c["max_ev"])
        # the percents and middle grey as given where they are plain numbers: arithmetic on them launches nothing
        low_percent, high_percent, grey = (controls[name] if is_plain_number(controls[name]) else c[name]
                                           for name in ("low_percent", "high_percent", "middle_grey"))
        metered = meter_histogram(scene, controls["metering_mask"], low, high, low_percent, high_percent, grey, controls["histogram_block"])
    else:
        metered = meter_sanitized(scene, controls["metering"], metering_weights(controls["metering_mask"], scene))
    return _limited(metered.reshape(scene.shape[:-3] + (1, 1, 1)), c)


def _adapted(scene: torch.Tensor, target: torch.Tensor, adapted: Optional[torch.Tensor], dt: Param, c: dict, limited: bool = True) -> torch.Tensor:
    """The new adapted luminance: ``target`` on a first frame, else ``adapted`` moved towards it by :func:`adapt_luminance`
    (and bounded by the limits where ``limited``: a fixed exposure is not)."""
    if adapted is None:
        return target
    # A state that is not a positive number, or a step outside [0, 65504] (NaN too), starts the sequence again. A
    # tensor step is not read: it is bounded for the branch not taken (a NaN there would make the gradient NaN).
    previous = _previous_state(adapted, scene)
    if isinstance(dt, torch.Tensor):
        dt = scalar_param(dt, scene, "dt")
        valid = (dt >= 0.0) & (dt <= HALF_MAX)  # false for NaN
        step, keeps = torch.where(valid, dt, 0.0), (previous > 0) & valid
    elif 0.0 <= dt <= HALF_MAX:
        step, keeps = scalar_param(dt, scene, "dt"), previous > 0
    else:
        return target
    moved = adapt_luminance(previous, target, step, c["speed"], c["speed_to_light"], c["speed_to_dark"])
    return torch.where(keeps & moved.isfinite(), _limited(moved, c) if limited else moved, target)


def _limited(luminance: torch.Tensor, c: dict) -> torch.Tensor:
    """``luminance`` bounded to ``[min_ev, max_ev]`` stops around middle grey (where set), then to ``[min_luminance, max_adapted]``."""
    if c["min_ev"] is not None:
        luminance = torch.maximum(luminance, c["middle_grey"] * torch.exp2(c["min_ev"]))
    if c["max_ev"] is not None:
        luminance = torch.minimum(luminance, c["middle_grey"] * torch.exp2(c["max_ev"]))
    return torch.clamp(luminance, c["min_luminance"], c["max_adapted"])


def compensation_at(curve, stops: torch.Tensor) -> torch.Tensor:
    """The compensation curve's stops at metered ``stops``: piecewise linear through its ``(metered, compensation)``
    points, constant past the first and last (Bevy's ``AutoExposureCompensationCurve``, Unreal's exposure
    compensation curve); 0 without a curve. ``y0 + sum_i slope_i * (clamp(x, x_i, x_i+1) - x_i)``: no lookup.

    Examples:
        >>> compensation_at(((-8.0, -3.0), (0.0, 0.0)), torch.tensor([-12.0, -4.0, 3.0])).tolist()
        [-3.0, -1.5, 0.0]
    """
    if curve is None:
        return torch.zeros((), dtype=stops.dtype, device=stops.device)
    xs, ys = zip(*curve)
    slopes = tuple((y1 - y0) / (x1 - x0) for x0, x1, y0, y1 in zip(xs, xs[1:], ys, ys[1:]))
    starts, ends = constant(xs[:-1], stops), constant(xs[1:], stops)
    ramps = torch.clamp(stops.unsqueeze(-1), starts, ends) - starts
    return ys[0] + (ramps * constant(slopes, stops)).sum(dim=-1)
