"""``Stage``: the one base of every torchgrade layer, built on its table of controls (:mod:`torchgrade.base.controls`).

A stage declares its controls once, as a table ``{name: Control(default, range)}``. From that table
the base stores each value (an ``nn.Parameter`` as a parameter, a tensor as a buffer, anything else
as a plain attribute), validates it at construction, on assignment (``grade.contrast = 500`` raises)
and, for values an optimiser moves, at forward (:meth:`Stage.check_learnable`), serialises it
(:meth:`Stage.to_config` / :meth:`Stage.from_config`) and decides whether the stage can change an
image at all (:attr:`Stage.is_identity`). :class:`~torchgrade.RandomPostFX` and the CLI read ranges
from the same tables, so a range is written in exactly one place.

Examples:
    >>> import torch
    >>> from torchgrade.base.controls import Control
    >>> class Gain(Stage):
    ...     controls = {"gain": Control(1.0, (0.0, 10.0))}
    ...     def __init__(self, gain=1.0):
    ...         super().__init__()
    ...         self.init_controls(gain=gain)
    ...     def forward(self, image):
    ...         return image * self.gain
    >>> Gain(2.0).to_config()
    {'gain': 2.0}
    >>> Gain().is_identity
    True
    >>> Gain(20.0)
    Traceback (most recent call last):
    ...
    ValueError: gain must lie in [0.0, 10.0], got 20.0
"""

from __future__ import annotations

import inspect
from typing import ClassVar, TypeVar

import torch
from torch import nn

from .config import config_value
from .controls import digit_count, in_state_check, plain, refuse_unknown
from .images import check_image, full_precision, with_alpha
from .params import is_constant
from ..runtime.checks import DeferredCheck, warn_if_eight_bit

__all__ = ["Stage"]

S = TypeVar("S", bound="Stage")


class Stage(nn.Module):
    """Base of every stage: controls stored, validated and serialised from one table.

    Subclasses set :attr:`controls` (or override :meth:`control_table` when the table depends on a
    setting, as a tone mapper's on its mode), call :meth:`init_controls` in ``__init__`` and read
    their controls as attributes. Cross-control rules (a zone's start below its end) go in
    :meth:`check_together`; checks of a ``"value"`` control in :meth:`check_control`.

    Every stage takes linear light ``(..., 3, H, W)`` or ``(..., 4, H, W)``: the fourth channel, alpha, comes back
    unchanged, bit for bit, as OpenColorIO and compositors grade RGBA, so ``tg.io.read_exr`` of a file with alpha goes
    through any stage or look as it is; ``forward`` sees the colour alone (:meth:`__call__`). An sRGB-encoded picture
    (PNG, JPEG, 0..255 codes) is decoded first, ``tg.color.srgb_to_linear(codes.float() / 255)``: taken as linear it
    would be graded as other light than it shows, and floats that look like 0..255 data warn.

    Examples:
        >>> import torchgrade as tg
        >>> grade = tg.ColorGrade(contrast=20)
        >>> grade.to_config()
        {'contrast': 20}
        >>> grade.contrast = 500
        Traceback (most recent call last):
        ...
        ValueError: contrast must lie in [-100.0, 100.0], got 500.0
    """

    controls: ClassVar[dict] = {}
    """``{name: Control(default, range)}``, in the order the stage documents them."""

    display_referred: ClassVar[bool] = False
    """True for stages whose output is display-referred (tone mappers): a LUT baked through one clamps to [0, 1]."""

    per_pixel: ClassVar[bool] = False
    """True for stages whose every output pixel depends on its input pixel alone (grades, tone mappers, LUTs): their
    ``forward`` is :func:`~torchgrade.runtime.strips.pixelwise`, and an ONNX export runs them on strips of rows
    (:mod:`torchgrade.onnx.strips`)."""

    takes_nan_free: ClassVar[bool] = True
    """Every stage's ``forward`` takes ``nan_free=True`` from a caller that knows its image holds no NaN (a look, for each
    stage after one that made a new frame), and then only bounds it (:func:`~torchgrade.base.images.sanitize`). A module
    that is not a stage (an export form) says so with this attribute of its own."""

    @property
    def always_in_config(self) -> tuple:
        """Controls written by :meth:`to_config` even at their defaults (a stage's defining settings): a class's tuple,
        or a property where they depend on a setting (a tone mapper's on its mode); none by default."""
        return ()

    __signature__: ClassVar[inspect.Signature]
    """What ``help()`` and :func:`inspect.signature` show of a stage taking ``**controls``
    (:func:`~torchgrade.base.controls.controls_signature`)."""

    def __init__(self):
        super().__init__()
        self._control_names: list[str] = []
        self._deferred_check = DeferredCheck()

    # ------------------------------------------------------------------ the table

    def control_table(self) -> dict:
        """This stage's controls, ``{name: Control}``; the class's :attr:`controls` unless overridden."""
        return type(self).controls

    def init_controls(self, **values) -> None:
        """Check and store every control of the table: ``values[name]`` if given, else its default.

        Raises ``ValueError`` for a name the table does not have, naming the known ones.
        """
        table = self.control_table()
        refuse_unknown(table, values, type(self).__name__)
        for name, control in table.items():
            self._store(name, self._checked(name, values.get(name, control.default)))
        self.check_together()

    def _checked(self, name: str, value):
        try:
            return self.control_table()[name].check(name, self.check_control(name, value))
        except OverflowError:  # a Python int beyond float range (JSON allows any number of digits)
            raise ValueError(f"{name} must be a number a float can hold, got one of {digit_count(value)} digits") from None

    def check_control(self, name: str, value):
        """Check (and return, possibly normalised) a control before its kind's check; the base accepts anything.

        The checks of ``"value"`` controls live here, and a stage's own rule for any control (stated
        in its own words, or a list normalised to a tensor) runs before the table's range check.
        """
        return value

    def check_together(self) -> None:
        """Rules between controls, run after construction and after every assignment; none by default."""

    def _store(self, name: str, value) -> None:
        for registry in (self._parameters, self._buffers):
            registry.pop(name, None)
        self.__dict__.pop(name, None)
        if isinstance(value, nn.Parameter):
            self.register_parameter(name, value)
        elif isinstance(value, torch.Tensor):
            self.register_buffer(name, value)
        else:
            object.__setattr__(self, name, value)
        if name not in self._control_names:
            self._control_names.append(name)

    def set_param(self, name: str, value) -> None:
        """Check and store control ``name`` (also what ``stage.name = value`` does)."""
        self._store(name, self._checked(name, value))
        self.check_together()

    def __setattr__(self, name: str, value) -> None:
        if name != "_control_names" and name in self.__dict__.get("_control_names", ()):
            self.set_param(name, value)
        else:
            super().__setattr__(name, value)

    def params(self) -> dict:
        """The controls as stored (numbers, tensors or parameters), by name."""
        return {name: getattr(self, name) for name in self._control_names}

    # ------------------------------------------------------------------ checks at run time

    def __call__(self, image, *args, **kwargs):
        """Check the learnable controls and the whole image, then run ``forward`` with autocast off (see
        :func:`~torchgrade.base.images.full_precision`) on its colour channels (and ``nan_free``,
        :attr:`takes_nan_free`).

        Every stage goes through here, so the range, precision and input policies hold for all of them without each
        ``forward`` repeating them:

        * ``image`` is scene-referred linear light ``(..., 3, H, W)``, or ``(..., 4, H, W)`` whose fourth channel (alpha)
          comes back unchanged, bit for bit, as OpenColorIO and compositors grade RGBA
          (:func:`~torchgrade.base.images.with_alpha`);
        * display-referred pictures are decoded first: ``tg.color.srgb_to_linear(png.float() / 255)``; floats that look
          like 0..255 data warn (:func:`~torchgrade.runtime.checks.warn_if_eight_bit`, on the CPU);
        * errors name the caller's shape, not a strip's.
        """
        self.check_learnable()
        check_image(image, alpha=True)
        if not kwargs.get("nan_free"):  # a frame a stage made is light, not 8-bit codes
            warn_if_eight_bit(image)
        with full_precision():
            return with_alpha(super().__call__, image, *args, **kwargs)

    def check_learnable(self) -> None:
        """Raise ``ValueError`` naming a learnable control an optimiser moved outside its range (or to NaN).

        Called before every ``forward`` (:meth:`__call__`); nothing while tracing or compiling (the graph carries no
        checks). On CUDA without waiting for the device, so the error comes at a later forward
        (:class:`~torchgrade.runtime.DeferredCheck`).
        """
        table = self.control_table()
        learnable = {name: value for name, value in self._parameters.items()
                     if value is not None and name in table and table[name].kind == "number"}
        if learnable:
            self.deferred_check()(learnable, lambda name, value: table[name].check(name, value))

    def deferred_check(self) -> DeferredCheck:
        """This stage's :class:`~torchgrade.runtime.DeferredCheck` of learnable values (made with the stage, so that no
        graph a compiler records makes one)."""
        return self._deferred_check

    def __getstate__(self):
        """A saved or copied stage leaves its pending checks behind (they hold CUDA events)."""
        state = dict(super().__getstate__())
        state.pop("_deferred_check", None)
        return state

    # ------------------------------------------------------------------ saved stages are untrusted

    def check_state(self) -> None:
        """Check every stored control (and a subclass's tables) as construction does; ``ValueError`` naming the first
        one that fails. A saved file is untrusted: :meth:`__setstate__` (``torch.load``) and ``load_state_dict`` run this.

        Learnable values (``nn.Parameter``) are left to :meth:`check_learnable`, which checks them at every forward:
        a copy of a stage whose value an optimiser moved out of range (``copy.deepcopy``,
        ``torch.optim.swa_utils.AveragedModel``) copies it as it is. Tensors on ``meta`` hold no values to check
        (:func:`in_state_check`).

        Examples:
            >>> import torchgrade as tg
            >>> tonemap = tg.ToneMap("reinhard_extended")
            >>> tonemap.__dict__["white_point"] = 0.0  # as a tampered file would hold it
            >>> tonemap.check_state()
            Traceback (most recent call last):
            ...
            ValueError: white_point must lie in [0.001, 10000.0], got 0.0
        """
        for name in self._control_names:
            value = getattr(self, name)
            if in_state_check(value):
                self._checked(name, value)
        self.check_together()

    def __setstate__(self, state) -> None:
        super().__setstate__(state)
        self._deferred_check = DeferredCheck()
        self.check_state()

    def _load_from_state_dict(self, state_dict, prefix, local_metadata, strict, missing_keys, unexpected_keys, error_msgs) -> None:
        """Load, then :meth:`check_state`. A state refused, by the check or by the load itself (a shape, a value assigned
        with ``assign=True``, which ``load_state_dict`` reports), leaves the stage as it was."""
        kept, errors = self._kept_values(), len(error_msgs)
        try:
            super()._load_from_state_dict(state_dict, prefix, local_metadata, strict, missing_keys, unexpected_keys, error_msgs)
            if len(error_msgs) == errors:
                self.check_state()
        except ValueError:
            self._restore(kept)
            raise
        if len(error_msgs) > errors:
            self._restore(kept)

    def _kept_values(self) -> tuple:
        """What a load can change: the parameters, buffers and control attributes, and a copy of every tensor's data
        (a load copies into the tensors it finds)."""
        attributes = {name: self.__dict__[name] for name in self._control_names if name in self.__dict__}
        tensors = [*self._parameters.values(), *self._buffers.values()]
        return dict(self._parameters), dict(self._buffers), attributes, [(t, t.detach().clone()) for t in tensors if t is not None]

    def _restore(self, kept: tuple) -> None:
        parameters, buffers, attributes, data = kept
        with torch.no_grad():
            for tensor, values in data:
                tensor.copy_(values)
        for registry, saved in ((self._parameters, parameters), (self._buffers, buffers)):
            registry.clear()
            registry.update(saved)
        for name in self._control_names:
            self.__dict__.pop(name, None)
        self.__dict__.update(attributes)

    # ------------------------------------------------------------------ identity and configs

    def is_default(self, name: str) -> bool:
        """True when control ``name`` is a plain value equal to its default (learnable values never are)."""
        value, default = getattr(self, name), self.control_table()[name].default
        if default is None or isinstance(default, (bool, str)):
            return not isinstance(value, torch.Tensor) and value == default
        return value is not None and is_constant(value, default)

    @property
    def is_identity(self) -> bool:
        """True when the stage cannot change any image (it is then skipped and not exported).

        The base: every control at its default. Stages whose default is not identity override it.
        """
        return all(self.is_default(name) for name in self._control_names)

    def to_config(self) -> dict:
        """The controls that differ from their defaults (and :attr:`always_in_config`), as plain values.

        ``type(stage).from_config(stage.to_config())`` builds an equal stage.
        """
        return {
            name: plain(getattr(self, name))
            for name in self._control_names
            if name in self.always_in_config or not self.is_default(name)
        }

    def state_config(self) -> dict:
        """What a saved look's state (``state_dict()``'s extra state) records of this stage to rebuild it before its
        tensors load: :meth:`to_config`, unless the stage's config names something the state dict already holds."""
        return self.to_config()

    @classmethod
    def config_table(cls, config: dict) -> dict:
        """The controls a ``config`` of this stage can set: :attr:`controls` unless a setting adds others (a tone mapper's mode)."""
        return cls.controls

    @classmethod
    def from_config(cls: type[S], config: dict) -> S:
        """Build the stage from a dict of its constructor arguments (what :meth:`to_config` returns).

        A JSON list where the stage keeps a per-sample tensor comes back as that tensor
        (:func:`~torchgrade.base.config.config_value`), so ``to_config`` -> JSON -> ``from_config`` rebuilds it.

        Examples:
            >>> import json
            >>> import torchgrade as tg
            >>> grade = tg.ColorGrade(contrast=torch.tensor([10.0, 20.0]))
            >>> tg.ColorGrade.from_config(json.loads(json.dumps(grade.to_config()))).contrast
            tensor([10., 20.])
        """
        if not isinstance(config, dict):
            raise ValueError(f"a {cls.__name__} config must be a dict, got {type(config).__name__}")
        table = cls.config_table(config)
        return cls(**{key: config_value(key, value, table[key]) if key in table else value for key, value in config.items()})

    def export_form(self) -> nn.Module:
        """The module an ONNX export traces for this stage; the stage itself unless it needs another form."""
        return self

    def extra_repr(self) -> str:
        return ", ".join(f"{key}={value!r}" for key, value in self.to_config().items())
