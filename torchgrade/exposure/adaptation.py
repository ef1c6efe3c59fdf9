"""Temporal adaptation and the middle-grey operator: one frame of eye adaptation as a pure function
(:func:`auto_exposure`), with the controls table and checks the module shares."""

from __future__ import annotations

from typing import Optional

import torch

from ..color import luminance
from ..core import HALF_MAX, Param, check_choice, check_image, check_range, is_tracing, sanitize, scalar_param, to_input_dtype, working_dtype
from ..runtime import constant
from ..stage import Control
from .metering import METERING_MODES, meter_sanitized

__all__ = ["CONTROLS", "MIN_LUMINANCE", "MAX_ADAPTED", "OPERATORS", "adapt_luminance", "auto_exposure", "check_bounds", "check_step",
           "checked_control", "exposed_frame", "exposure_operator"]

MIN_LUMINANCE = 1e-3
"""Default lower bound of the adapted luminance: the largest exposure gain is ``middle_grey / 1e-3``."""

MAX_ADAPTED = HALF_MAX
"""Default upper bound of the adapted luminance: the non-finite policy's bound, so no limit in practice."""

# Positive luminances stop at 1e-6 and middle grey at 100 (the largest gain is then 1e8), max_luminance at 0.01
# (Reinhard divides by its square): Reinhard's operator and its gradients stay finite in float32 on 65504.
SMALLEST, MAX_MIDDLE_GREY, MIN_WHITE = 1e-6, 100.0, 0.01

OPERATORS = ("exposure", "reinhard")


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
}
"""The controls of :func:`auto_exposure` and :class:`~torchgrade.exposure.AutoExposure`: defaults and documented ranges."""


def check_bounds(min_luminance, max_adapted) -> None:
    """Raise ``ValueError`` where ``min_luminance`` exceeds ``max_adapted``."""
    low, high = (torch.as_tensor(v, dtype=torch.float64).detach() for v in (min_luminance, max_adapted))
    if bool((low > high).any()):
        raise ValueError(f"min_luminance ({low.tolist()}) must not exceed max_adapted ({high.tolist()})")


def checked_control(name: str, value):
    """Control ``name`` of :data:`CONTROLS`, checked (a list made a tensor): the table's
    choices or range, and a positive control (range from :data:`SMALLEST`) named as such."""
    value = _from_list(value)
    control = CONTROLS[name]
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
    check_bounds(controls["min_luminance"], controls["max_adapted"])


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
      computed as ``(middle_grey / adapted) * (1 + scaled / max_luminance²) / (1 + scaled)``, which
      never divides by ``L``. Negative luminances (out-of-gamut pixels) use the curve's slope at 0.

    Examples:
        >>> exposure_operator(torch.full((3, 1, 1), 0.72), torch.tensor(0.72), 0.18, 16.0).flatten().tolist()
        [0.18000000715255737, 0.18000000715255737, 0.18000000715255737]
    """
    gain = middle_grey / adapted
    if operator == "exposure":
        return image * gain
    check_choice("operator", operator, OPERATORS)
    scaled = (luminance(image) * gain).clamp_min(0)
    return image * (gain * (1 + scaled / (max_luminance * max_luminance)) / (1 + scaled))


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
) -> tuple[torch.Tensor, torch.Tensor]:
    """One frame of eye adaptation, stateless: ``(image, adapted, dt) -> (exposed image, new adapted)``.

    1. ``metered = meter_luminance(image, metering)``, bounded to ``[min_luminance, max_adapted]``;
    2. ``new = adapt_luminance(adapted, metered, dt, speed, ...)``, bounded the same way; where ``adapted``
       is ``None`` or ``<= 0`` (no history: a first frame) ``new = metered``, so a server starts a
       sequence by feeding zeros; a NaN or infinite state or ``dt`` starts it again the same way;
    3. the image is exposed with ``new`` by :func:`exposure_operator` and bounded to ±65504. ``new`` is
       finite and at least ``min_luminance``, so the exposed frame has no NaN.

    ``adapted`` and the returned state have shape ``image.shape[:-3]`` (``(B,)`` for a batch).
    Every control is a number, a 0-d tensor or a per-sample ``(B,)`` tensor. Differentiable with
    respect to the image (through the operator and the metering), ``middle_grey`` and the other
    continuous controls. Bounds: ``MIN_LUMINANCE`` (1e-3) keeps the gain of a black frame finite;
    ``MAX_ADAPTED`` (65504) sets no upper limit. The document's ``[0.3, 1.0]`` can be passed instead.

    Examples:
        >>> exposed, adapted = auto_exposure(torch.full((1, 3, 4, 4), 0.72), None, metering='mean')
        >>> round(exposed.mean().item(), 4), [round(v, 4) for v in adapted.tolist()]
        (0.18, [0.72])
    """
    check_image(image)
    controls = dict(
        middle_grey=middle_grey, max_luminance=max_luminance, speed=speed, metering=metering, operator=operator,
        speed_to_light=speed_to_light, speed_to_dark=speed_to_dark, min_luminance=min_luminance, max_adapted=max_adapted,
    )
    if not is_tracing():
        _check_controls(controls)
        check_range(dt, "dt", 0.0, HALF_MAX)
    return exposed_frame(image, adapted, dt, **controls)


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


def exposed_frame(image: torch.Tensor, adapted: Optional[torch.Tensor], dt: Param, **controls) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`auto_exposure` of controls already checked (a stage's), reading nothing back from the device."""
    metering, operator = controls["metering"], controls["operator"]
    x = working_dtype(image)
    numbers = {name: value for name, value in controls.items() if name not in ("metering", "operator")}
    c = {name: None if value is None else scalar_param(value, x, name) for name, value in numbers.items()}
    scene = sanitize(x)
    bounds = c["min_luminance"], c["max_adapted"]
    metered = _bounded(meter_sanitized(scene, metering).reshape(x.shape[:-3] + (1, 1, 1)), *bounds)
    if adapted is None:
        new = metered
    else:
        previous = _previous_state(adapted, x)
        dt = scalar_param(dt, x, "dt")
        moved = adapt_luminance(previous, metered, dt, c["speed"], c["speed_to_light"], c["speed_to_dark"])
        # a state that is not a positive number, or a step that is not finite or negative, starts the sequence again
        new = torch.where((previous > 0) & (dt >= 0) & moved.isfinite(), _bounded(moved, *bounds), metered)
    # new is finite and positive, so the exposed frame has no NaN: bounding it is the whole non-finite policy
    exposed = exposure_operator(scene, new, c["middle_grey"], c["max_luminance"], operator)
    return to_input_dtype(exposed.clamp(-HALF_MAX, HALF_MAX), image), new.reshape(x.shape[:-3])


def _bounded(luminance: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """``min(max(luminance, low), high)``."""
    return torch.minimum(torch.maximum(luminance, low), high)
