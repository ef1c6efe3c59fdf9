"""Eye adaptation (auto exposure): scene metering, temporal adaptation and the middle-grey operator.

The stage follows the eye-adaptation method of source document 002 (meter the frame by
downsampling it to a fixed power-of-two size and averaging 2x2 blocks down to 1x1, move an
adapted luminance towards the metered one over time, then expose the frame so that the adapted
luminance lands on middle grey), with two corrections to that document:

* **Adaptation direction.** The document computes ``avg + (prev - avg) * (1 - pow(0.98, 30 dt))``,
  which returns the *new* average at ``dt = 0`` and drifts back towards the *previous* value as
  time passes. torchgrade moves from the previous value towards the new one:
  ``adapted + (metered - adapted) * (1 - exp(-dt * speed))``, so ``dt = 0`` changes nothing and a
  long ``dt`` settles on the metered value. (The document's rate ``pow(0.98, 30 dt)`` is
  ``exp(-dt * 30 ln(1 / 0.98))``, i.e. ``speed ≈ 0.606`` per second.)
* **Colour scaling.** The document returns ``Lcompressed * rgb``; a colour is brought to a new
  luminance by multiplying it by ``Lcompressed / L``. torchgrade writes that ratio without
  dividing by ``L`` (``scaled / L = middle_grey / adapted``), so it is exact and safe at ``L = 0``.

Two operators are offered. ``"exposure"`` (the default) returns the scene-referred image
``rgb * middle_grey / adapted`` so that bloom, grading and tone mapping can follow, as in the
library's pipeline ``AutoExposure -> Bloom -> ColorGrade -> ToneMap``. ``"reinhard"`` is the
document's operator, Reinhard et al. 2002 "Photographic Tone Reproduction", Eq. 4 with the
white point ``max_luminance``: it returns a display-referred image in which luminance
``max_luminance`` maps to 1 (brighter luminances exceed 1 and are not clipped here).

Pixels go through the library's non-finite policy (:func:`torchgrade.core.sanitize`) before
metering and before the operator, and outputs are bounded to ±65504, so one NaN or Inf pixel
changes neither the metered value nor any other pixel. float16/bfloat16 images are computed in
float32 and returned in their own dtype; the adapted luminance is float32 for them.
"""

from __future__ import annotations

from typing import Hashable, Optional

import torch
import torch.nn.functional as F

from .color import luminance
from .core import HALF_MAX, Param, check_choice, check_image, check_range, is_tracing, sanitize, scalar_param, to_input_dtype, working_dtype
from .stage import Control, Stage

__all__ = [
    "AutoExposure",
    "auto_exposure",
    "meter_luminance",
    "adapt_luminance",
    "exposure_operator",
    "area_resize",
    "halving_average",
    "METERING_MODES",
    "OPERATORS",
]

METERING_SIZE = 64
"""Side of the square grid the frame is resampled to before the 2x2 averaging (a power of two)."""

LOG_DELTA = 1e-4
"""Reinhard's δ in the log-average ``exp(mean(log(δ + L))) - δ``: keeps black pixels finite."""

MIN_LUMINANCE = 1e-3
"""Default lower bound of the adapted luminance: the largest exposure gain is ``middle_grey / 1e-3``."""

MAX_ADAPTED = HALF_MAX
"""Default upper bound of the adapted luminance: the non-finite policy's bound, so no limit in practice."""

# Positive luminances stop at 1e-6 and middle grey at 100 (the largest gain is then 1e8), max_luminance at 0.01
# (Reinhard divides by its square): Reinhard's operator and its gradients stay finite in float32 on 65504.
SMALLEST, MAX_MIDDLE_GREY, MIN_WHITE = 1e-6, 100.0, 0.01

METERING_MODES = ("mean", "log")
OPERATORS = ("exposure", "reinhard")


def _check_bounds(min_luminance, max_adapted) -> None:
    low, high = (torch.as_tensor(v, dtype=torch.float64).detach() for v in (min_luminance, max_adapted))
    if bool((low > high).any()):
        raise ValueError(f"min_luminance ({low.tolist()}) must not exceed max_adapted ({high.tolist()})")


def _checked_control(name: str, value):
    """Control ``name`` of :attr:`AutoExposure.controls`, checked (a list made a tensor): the table's
    choices or range, and a positive control (range from :data:`SMALLEST`) named as such."""
    value = _from_list(value)
    control = AutoExposure.controls[name]
    if control.kind == "choice":
        check_choice(name, value, control.range)
    elif value is not None:
        t = value.detach() if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=torch.float64)
        if control.range[0] > 0 and not bool((t > 0).all()):
            raise ValueError(f"{name} must be a number > 0, got {t.tolist()}")
        check_range(value, name, *control.range)
    return value


def _check_controls(controls: dict) -> None:
    """Validate :func:`auto_exposure`'s controls against :attr:`AutoExposure.controls` and order the bounds."""
    for name, value in controls.items():
        _checked_control(name, value)
    _check_bounds(controls["min_luminance"], controls["max_adapted"])


def _from_list(value):
    """A per-sample control written as a list (as :meth:`AutoExposure.to_config` writes it) as a tensor."""
    return torch.tensor(value, dtype=torch.get_default_dtype()) if isinstance(value, (list, tuple)) else value


def _area_weights(size_in, size_out: int, like: torch.Tensor) -> torch.Tensor:
    """``(size_out, size_in)`` box-filter matrix: row ``i`` averages the input pixels under output cell ``i``.

    Output cell ``i`` spans ``[i, i + 1) * size_in / size_out`` in input pixels; each weight is the
    overlap of an input pixel with that span divided by the span, so every row sums to 1 and the
    mean of the output equals the mean of the input exactly, whether it shrinks or enlarges.
    """
    # Positions counted in 1/size_out pixels are integers: in floating point an exported graph run at
    # reduced precision (OpenVINO's bfloat16 default) rounds positions above 256 by whole pixels.
    edges = torch.arange(size_out + 1, device=like.device) * size_in
    pixels = torch.arange(size_in, device=like.device) * size_out
    right = torch.minimum(pixels + size_out, edges[1:, None])
    left = torch.maximum(pixels, edges[:-1, None])
    return (right - left).clamp_min(0).to(like.dtype) / size_in


def area_resize(image: torch.Tensor, size: int) -> torch.Tensor:
    """Resample ``(..., H, W)`` to ``(..., size, size)`` with an exact box (area) filter.

    Two matrix products (rows, then columns), so any ``H, W`` (including 1x1) works and the sizes
    stay symbolic under ONNX export; kornia's antialiased ``resize`` derives its blur kernel from
    the input size with Python numbers, which fixes it to the exported resolution.

    Examples:
        >>> area_resize(torch.arange(6.0).reshape(1, 2, 3), 1).tolist()  # one cell: the mean
        [[[2.5]]]
    """
    rows = _area_weights(image.shape[-2], size, image)
    columns = _area_weights(image.shape[-1], size, image)
    return rows @ image @ columns.transpose(0, 1)


def halving_average(grid: torch.Tensor) -> torch.Tensor:
    """Average 2x2 blocks of a ``(N, C, 2^k, 2^k)`` grid until it is 1x1, as a mip chain does.

    Examples:
        >>> halving_average(torch.arange(16.0).reshape(1, 1, 4, 4)).flatten().tolist()
        [7.5]
    """
    while grid.shape[-1] > 1:
        grid = F.avg_pool2d(grid, 2)
    return grid


def meter_luminance(image: torch.Tensor, metering: str = "log") -> torch.Tensor:
    """Scene luminance of each image of ``(..., 3, H, W)``, shaped ``image.shape[:-3]``.

    The Rec.709 luminance ``L`` (negative values clipped to 0, non-finite pixels sanitized) is
    resampled to ``METERING_SIZE`` squared (:func:`area_resize`) and averaged down to one value
    (:func:`halving_average`). ``"mean"`` gives the arithmetic mean of ``L``; ``"log"`` the
    log-average ``exp(mean(log(δ + L))) - δ`` (Reinhard et al. 2002, Eq. 1, "the key"), taken per
    pixel before any averaging so that a few very bright pixels barely move it. Unlike Reinhard's
    form, δ is subtracted again, so a uniform frame meters exactly its luminance.

    Examples:
        >>> [round(v, 4) for v in meter_luminance(torch.full((2, 3, 8, 8), 0.5), 'mean').tolist()]
        [0.5, 0.5]
    """
    check_image(image)
    check_choice("metering", metering, METERING_MODES)
    lum = luminance(sanitize(image)).clamp_min(0).reshape(-1, 1, image.shape[-2], image.shape[-1])
    if metering == "log":
        lum = torch.log(lum + LOG_DELTA)
    average = halving_average(area_resize(lum, METERING_SIZE))
    if metering == "log":
        average = torch.exp(average) - LOG_DELTA
    return average.reshape(image.shape[:-3])


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
        to_light, to_dark = (torch.as_tensor(s, dtype=metered.dtype, device=metered.device) for s in (to_light, to_dark))
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
    2. ``new = adapt_luminance(adapted, metered, dt, speed, ...)``; where ``adapted`` is ``None``
       or ``<= 0`` (no history: a first frame) ``new = metered``, so a server starts a sequence
       by feeding zeros;
    3. the image is exposed with ``new`` by :func:`exposure_operator`.

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
    x = working_dtype(image)
    numbers = {name: value for name, value in controls.items() if name not in ("metering", "operator")}
    c = {name: None if value is None else scalar_param(value, x, name) for name, value in numbers.items()}
    metered = meter_luminance(x, metering).reshape(x.shape[:-3] + (1, 1, 1))
    metered = torch.minimum(torch.maximum(metered, c["min_luminance"]), c["max_adapted"])
    if adapted is None:
        new = metered
    else:
        previous = _previous_state(adapted, x)
        dt = scalar_param(dt, x, "dt")
        moved = adapt_luminance(previous, metered, dt, c["speed"], c["speed_to_light"], c["speed_to_dark"])
        new = torch.where(previous > 0, moved, metered)
    exposed = exposure_operator(sanitize(x), new, c["middle_grey"], c["max_luminance"], operator)
    return to_input_dtype(sanitize(exposed), image), new.reshape(x.shape[:-3])


class AutoExposure(Stage):
    """Eye adaptation for stills and video, keeping the adapted luminance per sample.

    ``forward(image, dt=None)``: with ``dt`` in seconds since the previous frame, the state
    ``adapted_luminance`` (shape ``image.shape[:-3]``) moves towards the frame's metered luminance
    (see :func:`auto_exposure`); with ``dt=None`` (stills, training batches) or on the first
    frame after construction or :meth:`reset`, it adapts instantly. Changing the batch size in a
    sequence raises ``ValueError``; call :meth:`reset` between sequences. :meth:`frame` is one
    frame without state, for serving.

    ``forward(image, dt, stream=key)`` keeps one state per hashable ``key`` in :attr:`streams` (``None``,
    the default, is :attr:`adapted_luminance`): threads serving one stream each never mix; two threads
    on one key interleave into one adaptation (use a key each, or :meth:`frame`).

    ``operator="exposure"`` (default) returns the scene-referred image scaled by
    ``middle_grey / adapted`` for the rest of the pipeline; ``operator="reinhard"`` returns the
    document's display-referred operator, which uses ``max_luminance``. The stored state is
    detached (gradients flow within a frame, not across frames); use :func:`auto_exposure` to
    backpropagate through time. An ``nn.Parameter`` control is registered as a module parameter.
    ``to_config()`` returns every constructor argument as plain values (per-sample tensors as
    lists, which the constructor accepts): ``AutoExposure(**module.to_config())``.

    Examples:
        >>> layer = AutoExposure(metering="mean")
        >>> out = layer(torch.full((1, 3, 4, 4), 0.72))
        >>> round(out.mean().item(), 4), [round(v, 4) for v in layer.adapted_luminance.tolist()]
        (0.18, [0.72])
        >>> _ = layer(torch.full((1, 3, 2, 2), 0.09), dt=0.1, stream="left")  # a new stream adapts instantly
        >>> round(layer.streams["left"].item(), 4), [round(v, 4) for v in layer.adapted_luminance.tolist()]
        (0.09, [0.72])
        >>> AutoExposure(middle_grey=0.0)
        Traceback (most recent call last):
        ...
        ValueError: middle_grey must be a number > 0, got 0.0
    """

    controls = {
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
    always_in_config = tuple(controls)

    adapted_luminance: torch.Tensor

    def __init__(
        self,
        middle_grey: Param = 0.18,
        max_luminance: Param = 16.0,
        speed: Param = 1.0,
        metering: str = "log",
        *,
        operator: str = "exposure",
        speed_to_light: Optional[Param] = None,
        speed_to_dark: Optional[Param] = None,
        min_luminance: Param = MIN_LUMINANCE,
        max_adapted: Param = MAX_ADAPTED,
    ) -> None:
        super().__init__()
        self.init_controls(
            middle_grey=middle_grey, max_luminance=max_luminance, speed=speed, metering=metering, operator=operator,
            speed_to_light=speed_to_light, speed_to_dark=speed_to_dark, min_luminance=min_luminance, max_adapted=max_adapted,
        )
        self.register_buffer("adapted_luminance", torch.empty(0))
        self.streams: dict = {}

    def check_control(self, name: str, value):
        return _checked_control(name, value)

    def check_together(self) -> None:
        _check_bounds(self.min_luminance, self.max_adapted)

    @property
    def is_identity(self) -> bool:
        """Never: the stage exposes every frame, whatever its controls."""
        return False

    def reset(self, stream: Optional[Hashable] = None) -> None:
        """Forget ``stream``'s adapted luminance, or with no argument every one: the next frame adapts instantly."""
        if stream is None:
            self.adapted_luminance = self.adapted_luminance.new_empty(0)
            self.streams.clear()
        else:
            self.streams.pop(stream, None)

    def _history(self, state: torch.Tensor, image: torch.Tensor, dt) -> Optional[torch.Tensor]:
        """The state to adapt from, or ``None`` to adapt instantly."""
        if dt is None or state.numel() == 0:
            return None
        if state.shape != image.shape[:-3]:
            raise ValueError(
                f"batch changed mid-sequence: adapted_luminance has shape {tuple(state.shape)} but the "
                f"image has shape {tuple(image.shape)}; call reset() before starting a new sequence"
            )
        return state

    def frame(self, image: torch.Tensor, adapted: Optional[torch.Tensor], dt: Param) -> tuple[torch.Tensor, torch.Tensor]:
        """One frame with these controls, stateless: ``(image, adapted, dt) -> (exposed, new adapted)``.

        ``adapted`` has one value per image (``image.shape[:-3]``); ``None`` or ``<= 0`` starts a
        sequence (the frame adapts instantly). The stored :attr:`adapted_luminance` is left alone.

        Examples:
            >>> layer = AutoExposure(metering="mean")
            >>> exposed, adapted = layer.frame(torch.full((2, 3, 4, 4), 0.36), torch.zeros(2), 0.0)
            >>> [round(v, 4) for v in adapted.tolist()], layer.adapted_luminance.numel()
            ([0.36, 0.36], 0)
        """
        self.check_learnable()
        return auto_exposure(image, adapted, dt, **self.params())

    def forward(self, image: torch.Tensor, dt: Optional[Param] = None, stream: Optional[Hashable] = None) -> torch.Tensor:
        check_image(image)
        # One dict read and one dict write per frame: atomic in CPython, so threads on distinct keys never mix.
        state = self.adapted_luminance if stream is None else self.streams.get(stream, self.adapted_luminance.new_empty(0))
        exposed, adapted = self.frame(image, self._history(state, image, dt), 0.0 if dt is None else dt)
        if stream is None:
            self.adapted_luminance = adapted.detach()
        else:
            self.streams[stream] = adapted.detach()
        return exposed
