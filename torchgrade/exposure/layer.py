"""``AutoExposure``: eye adaptation as a stage that keeps the adapted luminance per sample and per stream."""

from __future__ import annotations

import contextlib
import inspect
from typing import Hashable, Optional

import torch

from ..base.images import check_image, working_dtype
from ..base.params import Param, scalar_param
from ..base.controls import controls_signature
from ..base.stage import Stage
from .adaptation import (
    BOUNDS,
    CONTROLS,
    NOT_NUMBERS,
    check_bounds,
    check_step,
    checked_control,
    exposed_frame,
    exposure_key,
)

__all__ = ["AutoExposure"]


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

    Metering (:func:`auto_exposure`): ``metering`` ``"log"`` (default), ``"mean"`` or ``"histogram"`` (the
    ``[low_percent, high_percent]`` band, HDRP's default 40-90 %, counted a value for each square of ``histogram_block``
    pixels, 2 by default, 1 for every pixel), weighted by ``metering_mask`` (``"average"``,
    ``"center"``, ``"spot"`` or a 2-D tensor of weights); limits ``min_ev``/``max_ev`` and ``compensation`` in
    stops around middle grey; a ``compensation_curve`` of the metered stops; ``fixed_exposure`` (stops) meters
    nothing.

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

    controls = CONTROLS
    always_in_config = tuple(controls)

    adapted_luminance: torch.Tensor
    batch_state = ("adapted_luminance",)
    """The buffers of the batch's shape, which :func:`torchgrade.compile` makes symbolic with the frame's batch."""

    POSITIONAL = ("middle_grey", "max_luminance", "speed", "metering")
    """The controls that may be given in order, before the others by name (defaults: :data:`CONTROLS`)."""

    def __init__(self, *values, **controls) -> None:
        if len(values) > len(self.POSITIONAL):
            raise TypeError(f"AutoExposure takes at most {len(self.POSITIONAL)} controls in order "
                            f"({', '.join(self.POSITIONAL)}), got {len(values)}")
        twice = [name for name in self.POSITIONAL[:len(values)] if name in controls]
        if twice:
            raise TypeError(f"AutoExposure got {twice[0]!r} both in order and by name")
        super().__init__()
        self.init_controls(**dict(zip(self.POSITIONAL, values)), **controls)
        self.register_buffer("adapted_luminance", torch.empty(0))
        self.streams: dict = {}

    def check_control(self, name: str, value):
        return checked_control(name, value)

    def check_together(self) -> None:
        check_bounds(**{name: getattr(self, name) for name in BOUNDS})

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

    @contextlib.contextmanager
    def compiled_frame(self, image: torch.Tensor, dt: Optional[Param] = None, stream: Optional[Hashable] = None):
        """Around a compiled frame (:func:`torchgrade.compile` enters it), the state the graph sees, the same for every
        frame of a kind, so that one graph serves them: for a frame that adapts instantly (``dt=None``, which reads
        no state) an empty :attr:`adapted_luminance`, whatever the last frame's batch was; for the first frame of a
        sequence (an empty state) zeros of ``image``'s batch shape (a state that is not positive starts a sequence as
        an empty one does: the same values, and a learnable ``speed`` gets a zero gradient where there is none), as
        the second frame's state will be. The frame's state is kept if it runs; the state before it comes back if it
        raises. A ``stream``'s state is left alone.

        Examples:
            >>> layer = AutoExposure()
            >>> with layer.compiled_frame(torch.ones(2, 3, 4, 4), dt=1 / 24):
            ...     layer.adapted_luminance.tolist()
            [0.0, 0.0]
        """
        if stream is not None or (dt is not None and self.adapted_luminance.numel() != 0):
            yield
            return
        kept = self.adapted_luminance
        dtype = working_dtype(image.new_empty(0)).dtype  # the state's dtype after a frame
        shape = (0,) if dt is None else image.shape[:-3]
        self.adapted_luminance = torch.zeros(shape, dtype=dtype, device=image.device)
        try:
            yield
        except BaseException:
            self.adapted_luminance = kept
            raise

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

    def frame(self, image: torch.Tensor, adapted: Optional[torch.Tensor], dt: Param, *,
              nan_free: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """One frame with these controls, stateless: ``(image, adapted, dt) -> (exposed, new adapted)``.

        ``adapted`` has one value per image (``image.shape[:-3]``); ``None`` or ``<= 0`` starts a
        sequence (the frame adapts instantly). The stored :attr:`adapted_luminance` is left alone. ``nan_free``:
        ``image`` holds no NaN (:func:`~torchgrade.base.images.sanitize`).

        Examples:
            >>> layer = AutoExposure(metering="mean")
            >>> exposed, adapted = layer.frame(torch.full((2, 3, 4, 4), 0.36), torch.zeros(2), 0.0)
            >>> [round(v, 4) for v in adapted.tolist()], layer.adapted_luminance.numel()
            ([0.36, 0.36], 0)
        """
        self.check_learnable()
        check_image(image)
        check_step(dt)
        return exposed_frame(image, adapted, dt, nan_free=nan_free, **self.params())

    def exposure_stops(self, adapted: torch.Tensor) -> torch.Tensor:
        """The exposure this stage applies from the adapted luminance ``adapted`` (``(B,)``, as :meth:`frame` returns
        it), in stops: ``log2(key / adapted)`` with the key of :func:`~torchgrade.exposure.adaptation.exposure_key`
        (middle grey, compensation and the curve); what HDRP's exposure debug view shows.

        Examples:
            >>> layer = AutoExposure(metering="mean", compensation=0.5)
            >>> _, adapted = layer.frame(torch.full((1, 3, 4, 4), 0.72), None, 0.0)
            >>> [round(v, 3) for v in layer.exposure_stops(adapted).tolist()]  # 2 stops down, half a stop back
            [-1.5]
        """
        like = adapted.reshape(-1, 1, 1, 1)
        c = {name: None if value is None else scalar_param(value, like, name) for name, value in self.params().items() if name not in NOT_NUMBERS}
        return torch.log2(exposure_key(like, c, self.compensation_curve) / like).reshape(adapted.shape)

    def forward(self, image: torch.Tensor, dt: Optional[Param] = None, stream: Optional[Hashable] = None, *,
                nan_free: bool = False) -> torch.Tensor:
        check_image(image)
        # A frame without dt adapts instantly and reads no state: a compiled graph then holds no guard on the state's
        # shape, which is the last batch's, and runs for a batch of another size. One dict read and one dict write
        # per frame: atomic in CPython, so threads on distinct keys never mix.
        history = None if dt is None else self._history(
            self.adapted_luminance if stream is None else self.streams.get(stream, self.adapted_luminance.new_empty(0)), image, dt)
        exposed, adapted = self.frame(image, history, 0.0 if dt is None else dt, nan_free=nan_free)
        if stream is None:
            self.adapted_luminance = adapted.detach()
        else:
            self.streams[stream] = adapted.detach()
        return exposed


AutoExposure.__signature__ = controls_signature(
    {name: control for name, control in CONTROLS.items() if name not in AutoExposure.POSITIONAL},
    leading=tuple(inspect.Parameter(name, inspect.Parameter.POSITIONAL_OR_KEYWORD, default=CONTROLS[name].default)
                  for name in AutoExposure.POSITIONAL),
)
