"""A compiled look in one word: :func:`compile` wraps a module in ``torch.compile`` with the mode that suits the
device of the frames it gets, and says when it compiles.

* **CUDA**: ``mode="reduce-overhead"``: Inductor's fused kernels replayed as a CUDA graph, one launch per frame
  size instead of one per kernel. A graph's outputs are its own buffers, overwritten by the next call of the
  same size: clone an output you keep across calls.
* **CPU**: Inductor's default mode (fused C++ loops over the pixels) without its layout optimisation
  (:data:`CPU_OPTIONS`).
* **Other devices**: Inductor's default mode.

``fullgraph=True`` always: a look is one graph, so a graph break is an error here rather than a silent slowdown.
The batch is symbolic from the first frame, the frame's sides fixed (``dynamic="batch"``, the default): the last,
smaller batch of an epoch runs the graph the first batch compiled (a batch of 1, which PyTorch specialises, compiles its
own). It is asked through PyTorch's public ``torch.compiler.config.dynamic_sources`` (:func:`batch_sources`: the first
dimension of every tensor the module's forward is handed and of the state a stage declares batch-sized, none of the
module's parameters and other buffers) while a call may compile. A frame of new sides compiles once more, and PyTorch then makes the sizes that changed symbolic.
``dynamic=True`` makes every size symbolic from the first frame; its index arithmetic is what Inductor spends a compile
on: a bloom's pyramid of symbolic sides compiled in 326 s on a 64x96 frame where its sides fixed took 28 s (the
cinematic look's bloom stage, 2 CPU threads), and at 1080p the whole look did not finish in 15 minutes. PyTorch also
ties sizes equal at the first frame (its duck sizing: a batch of 16 on 16x16 frames ties the batch to the sides) and
traces twice where AOTAutograd runs (the module's float constants become inputs). ``dynamic=None`` is PyTorch's default
(the first size fixed; at the first new size one graph with the changed sizes symbolic); ``dynamic=False`` compiles
every size as it comes, and the ninth size stops with ``FailOnRecompileLimitHit`` (Dynamo's ``recompile_limit`` is 8
and ``fullgraph=True`` makes hitting it an error).

**A compile says so.** Compiling takes time (:data:`COMPILE_SECONDS`), paid at the first frame of each kind (shape,
gradients, autocast), and a run that waits on it should not look like a hang: the wrapper writes a line on stderr
when a compile starts, with what it compiles, why (the module's first frame, or the guard of its last graph that this
frame failed) and what such a compile costs, and a line when it ends, with its time; a training call's backward
compiles at its first ``backward()`` and says so too. The lines are records of the ``torchgrade.compile`` logger
(:data:`LOG`, INFO), written on stderr unless the program has configured logging (then its handlers take them):
``tg.compile(module, verbose=False)``, ``LOG.setLevel(logging.WARNING)`` or a handler of one's own quiet them.

Whether a call compiles is asked of PyTorch through its public stance: a frame of a kind the wrapper has not run is
first called under ``torch.compiler.set_stance("fail_on_recompile")``, which runs a graph whose guards hold and raises,
naming the guards that failed, where a compile would start. The stance is the process's: such calls hold a lock, so
they take turns, and a ``torch.compile`` of other code that compiles on another thread during one of them raises.
:meth:`CompiledModule.warm_up` pays a compile before a run starts; ``benchmarks/bench_compile.py`` measures compiles
cold (an empty Inductor cache), warm (Inductor's on-disk cache from an earlier process) and from saved cache artifacts
(:func:`torchgrade.io.save_compile_cache`, :func:`torchgrade.io.load_compile_cache`).

A training graph is partitioned as PyTorch partitions it: only private settings choose what its forward keeps for the
backward (the activation memory budget of ``torch._functorch.config``), so ``tg.compile`` sets none.

The compiled graph carries no range checks (they read values), so the wrapper checks every stage's learnable
controls (:meth:`~torchgrade.Stage.check_learnable`) before each call, as an eager forward does. A module with
state to shape before its first frame (``AutoExposure``, a ``PostFX`` with one) says so with a ``compiled_frame``
context the wrapper enters around each call (:meth:`~torchgrade.AutoExposure.compiled_frame`), so the second frame
runs the first frame's graph; a module with work to do before the graph (``RandomPostFX``'s draw from a
``generator=``, which cannot enter a graph) says so with ``compiled_arguments``, which turns a call's arguments into
the graph's (:meth:`~torchgrade.RandomPostFX.compiled_arguments`).

Examples:
    >>> import torch
    >>> import torchgrade as tg
    >>> fast = tg.compile(tg.ToneMap("reinhard"))
    >>> compile_mode(torch.device("cuda")), compile_mode(torch.device("cpu"))
    ('reduce-overhead', 'default')
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from typing import Literal, Union

import torch
from torch import nn

__all__ = ["compile", "compile_mode", "CompiledModule", "CPU_OPTIONS", "COMPILE_SECONDS", "FRAME_SOURCES", "batch_sources", "LOG"]

LOG = logging.getLogger("torchgrade.compile")
"""Where a :func:`compile`'d module says that a compile starts, why and what it usually costs, and how long it took
(level INFO; the logger's level is INFO, and its handler writes on stderr unless the program has configured logging)."""


class _UnlessConfigured(logging.StreamHandler):
    """stderr, for a record no handler of an enclosing logger takes: a program that has configured logging gets the
    compile lines where it sends the rest, and one that has not sees them anyway."""

    def emit(self, record: logging.LogRecord) -> None:
        if not (LOG.propagate and LOG.parent is not None and LOG.parent.hasHandlers()):
            super().emit(record)


_STDERR = _UnlessConfigured()
_STDERR.setFormatter(logging.Formatter("torchgrade: %(message)s"))
LOG.addHandler(_STDERR)
LOG.setLevel(logging.INFO)


CPU_OPTIONS = {"layout_optimization": False}
"""Inductor's settings on the CPU. Its layout optimisation gives the outputs of a graph's convolutions (the bloom
pyramid's blurs, when they compiled as convolutions; an anamorphic bloom's) channels-last buffers; a per-pixel loop
that reads such a frame as planes is then not vectorised (the compiled cinematic look with and without it:
``benchmarks/results/cpu_paths.md``)."""


COMPILE_SECONDS = {("PostFX", False): (46.6, 7.0), ("PostFX", True): (93.4, 8.6),
                   ("RandomPostFX", False): (16.3, 4.7), ("RandomPostFX", True): (25.5, 4.6)}
"""``(module, training) -> (cold, warm)``: the seconds of a first call that compiled, with an empty Inductor cache
and with the cache of an earlier process, measured on 2 CPU threads (``benchmarks/results/compile.md``: the cinematic
look on 1x3x1080x1920 and in training on 16x3x128x128, ``RandomPostFX`` on 64x3x224x224 and in training on
16x3x128x128). A compile announces its module's figure, a whole look's for other modules."""


FRAME_SOURCES = r"L\['[^']+'\](\[[^\]]+\])?$:0"
"""The first dimension of every tensor a compiled forward gets by argument, as ``torch.compiler.config.dynamic_sources``
reads it: a local (``L['image']``) or an item of one (``L['args'][0]``, a drawn look's ``L['params']['hue_shift']``),
and nothing reached through an attribute (``L['self']._modules['grade'].contrast``, the module's controls, parameters
and buffers, which an entry that matched them would make symbolic too)."""


def batch_sources(module: nn.Module) -> str:
    """What ``dynamic="batch"`` makes symbolic in ``module``'s graph, as ``torch.compiler.config.dynamic_sources``
    reads it: :data:`FRAME_SOURCES`, and the first dimension of each buffer a stage of ``module`` names in its
    ``batch_state`` (state of the batch's shape, such as an exposure stage's adapted luminance).

    Examples:
        >>> import torchgrade as tg
        >>> batch_sources(tg.ToneMap("aces")) == FRAME_SOURCES
        True
        >>> print(batch_sources(tg.AutoExposure()).split(",")[1])
        .*\\['adapted_luminance'\\]:0
    """
    names = dict.fromkeys(name for stage in module.modules() for name in getattr(stage, "batch_state", ()))
    return ",".join([FRAME_SOURCES, *(rf".*\['{name}'\]:0" for name in names)])


_STANCE = threading.Lock()
"""Held while a call runs under the ``"fail_on_recompile"`` stance, which is the process's."""


def _describe(module: nn.Module, image: torch.Tensor) -> str:
    """What a call compiles: the module, the frame and how it is called (gradients, autocast)."""
    autocast = [f"{device} {torch.get_autocast_dtype(device)}".replace("torch.", "") for device in ("cpu", "cuda")
                if torch.is_autocast_enabled(device)]
    return (f"{type(module).__name__} for a {tuple(image.shape)} {str(image.dtype).replace('torch.', '')} frame on "
            f"{image.device.type}, gradients {'on' if torch.is_grad_enabled() else 'off'}"
            + (f", autocast {' and '.join(autocast)}" if autocast else ""))


def _usual_cost(module: nn.Module) -> str:
    """What a compile of ``module`` usually costs, from :data:`COMPILE_SECONDS`."""
    name = type(module).__name__ if (type(module).__name__, False) in COMPILE_SECONDS else "PostFX"
    training = torch.is_grad_enabled() and (name, True) in COMPILE_SECONDS
    cold, warm = COMPILE_SECONDS[(name, training)]
    what = f"{'a whole look' if name == 'PostFX' else name}{' in training' if training else ''}"
    return f"{what} took {cold} s cold, {warm} s from Inductor's cache, on 2 CPU threads (benchmarks/results/compile.md)"


def _failed_guards(error: RuntimeError) -> list:
    """The guards PyTorch names in the error the ``"fail_on_recompile"`` stance raises (none for a first compile)."""
    return [line.strip()[2:] for line in str(error).splitlines() if line.strip().startswith("- ")]


def _call_kind(args: tuple, kwargs: dict) -> tuple:
    """What a call's graph depends on that changes from call to call: its tensors' devices, dtypes, shapes and
    gradients, and the gradient and autocast modes."""
    values = [item for value in (*args, *kwargs.values()) for item in (value.values() if isinstance(value, dict) else (value,))]
    tensors = [value for value in values if isinstance(value, torch.Tensor)]  # a drawn look's parameters are a dict
    autocast = tuple(torch.is_autocast_enabled(device) and torch.get_autocast_dtype(device) for device in ("cpu", "cuda"))
    return (tuple((t.device, t.dtype, tuple(t.shape), t.requires_grad) for t in tensors), torch.is_grad_enabled(), autocast)


def compile_mode(device: torch.device, cuda_graphs: bool = True) -> str:
    """The ``torch.compile`` mode for frames on ``device``: CUDA graphs on CUDA (unless ``cuda_graphs=False``)."""
    return "reduce-overhead" if device.type == "cuda" and cuda_graphs else "default"


class CompiledModule(nn.Module):
    """``module`` compiled per device type at its first frame there (see :func:`compile`); ``module`` is
    :attr:`module`, so its controls, state and ``to_config`` stay reachable."""

    def __init__(self, module: nn.Module, cuda_graphs: bool = True, dynamic: Union[bool, None, Literal["batch"]] = "batch",
                 verbose: bool = True):
        super().__init__()
        self.module = module
        self.cuda_graphs = cuda_graphs
        self.dynamic = dynamic
        self.verbose = bool(verbose)
        self._compiled: dict = {}
        self._ran: set = set()  # the kinds of call (_call_kind) that ran a graph

    def compiled_for(self, device: torch.device):
        """The compiled callable for frames on ``device`` (compiled lazily: the first frame pays the compile time)."""
        call = self._compiled.get(device.type)
        if call is None:
            # torch.compile takes a mode or options: on the CPU, the options of the default mode (CPU_OPTIONS)
            settings = {"options": CPU_OPTIONS} if device.type == "cpu" else {"mode": compile_mode(device, self.cuda_graphs)}
            dynamic = None if self.dynamic == "batch" else self.dynamic  # the batch: marked while compiling
            call = torch.compile(self.module, fullgraph=True, dynamic=dynamic, **settings)
            self._compiled[device.type] = call
        return call

    def forward(self, image: torch.Tensor, *args, **kwargs):
        """Check the learnable controls of every stage (``check_learnable``, which the graph skips), then run the graph
        inside the module's ``compiled_frame`` where it has one.

        A call that compiles and fails calls the module eagerly on the frame: a frame the module refuses (an image of 2
        channels, integer values, which Dynamo reports as an error of its own while it traces) raises the module's own
        error, as an uncompiled module would; a frame the module takes raises the compile's error."""
        if not isinstance(image, torch.Tensor):
            return self.module(image, *args, **kwargs)  # the module's own TypeError
        for stage in self.module.modules():
            check_learnable = getattr(stage, "check_learnable", None)
            if check_learnable is not None:
                check_learnable()
        prepare = getattr(self.module, "compiled_arguments", None)
        if prepare is not None:  # what must happen before the graph: a random draw from a generator
            (image, *args), kwargs = prepare(image, *args, **kwargs)
        frame = getattr(self.module, "compiled_frame", None)
        with frame(image, *args, **kwargs) if frame is not None else contextlib.nullcontext():
            return self._graph_call(image, args, kwargs)

    def _graph_call(self, image: torch.Tensor, args: tuple, kwargs: dict):
        """The graph of this kind of call, compiled first (and said so) where PyTorch has none whose guards hold."""
        call, kind = self.compiled_for(image.device), _call_kind((image, *args), kwargs)
        if kind in self._ran:
            return call(image, *args, **kwargs)
        with self._symbolic_sizes():
            return self._first_call(call, kind, image, args, kwargs)

    def _symbolic_sizes(self):
        """What a call that may compile runs under: with ``dynamic="batch"``, :func:`batch_sources` symbolic."""
        if self.dynamic != "batch":
            return contextlib.nullcontext()
        return torch.compiler.config.patch(dynamic_sources=batch_sources(self.module))

    def _first_call(self, call, kind: tuple, image: torch.Tensor, args: tuple, kwargs: dict):
        """The first call of a kind: the graph whose guards hold, or a compile (said so)."""
        with _STANCE, torch.compiler.set_stance("fail_on_recompile"):
            try:
                out = call(image, *args, **kwargs)
            except RuntimeError as error:  # where a compile would start
                failed = _failed_guards(error)
            else:
                self._ran.add(kind)
                return out
        out = self._compiling_call(call, failed, image, args, kwargs)
        self._ran.add(kind)
        return out

    def _compiling_call(self, call, failed: list, image: torch.Tensor, args: tuple, kwargs: dict):
        label = _describe(self.module, image)
        why = f"a guard of its last graph failed: {'; '.join(failed)}" if failed else "its first frame"
        self._announce("compiling the forward of %s (%s); a compile of %s", label, why, _usual_cost(self.module))
        started = time.perf_counter()
        try:
            out = call(image, *args, **kwargs)
        except Exception as error:
            refused = error
        else:
            self._announce("compiled the forward of %s in %.1f s", label, time.perf_counter() - started)
            self._announce_backward(out, label)
            return out
        self.module(image, *args, **kwargs)  # raises the module's own error (outside the handler: that error alone)
        raise refused  # the compile's own failure

    def _announce(self, message: str, *values) -> None:
        if self.verbose:
            LOG.info(message, *values)

    def _announce_backward(self, out, label: str) -> None:
        """Say when the backward of a graph just compiled compiles, at its first ``backward()``, and how long it took:
        hooks on the output's node (``torch.autograd.graph.Node``), before and after it runs."""
        node = next((value.grad_fn for value in (out if isinstance(out, tuple) else (out,))
                     if isinstance(value, torch.Tensor) and value.grad_fn is not None), None)
        if node is None or not self.verbose:
            return
        started = []

        def before(grad_outputs):
            started.append(time.perf_counter())
            self._announce("compiling the backward of %s", label)

        def after(grad_inputs, grad_outputs):
            self._announce("compiled the backward of %s in %.1f s", label, time.perf_counter() - started[0])

        node.register_prehook(before)
        node.register_hook(after)

    def warm_up(self, example: torch.Tensor, *args, training: bool = False, **kwargs) -> float:
        """Compile for frames like ``example`` now (one call, and its backward with ``training``), not at the first
        frame of a run: the seconds it took. Later frames of other batch sizes run the same graph. Without ``training``
        the call keeps the caller's gradient mode, which the graph is compiled for: warm up inside ``torch.no_grad()``
        what will run inside it.

        Examples:
            >>> import torch
            >>> import torchgrade as tg
            >>> seconds = tg.compile(tg.ToneMap("reinhard")).warm_up(torch.rand(2, 3, 8, 8))  # doctest: +SKIP
        """
        started = time.perf_counter()
        with torch.set_grad_enabled(training or torch.is_grad_enabled()):
            example = example.detach().requires_grad_(training)
            out = self(example, *args, **kwargs)
            if training:
                out.sum().backward()
        return time.perf_counter() - started


def compile(module: nn.Module, *, cuda_graphs: bool = True, dynamic: Union[bool, None, Literal["batch"]] = "batch",
            verbose: bool = True) -> CompiledModule:
    """``module`` (a stage, a :class:`~torchgrade.PostFX`, a :class:`~torchgrade.RandomPostFX`, a LUT) through
    ``torch.compile`` with one graph and the device's mode (:func:`compile_mode`).

    ``dynamic``: ``"batch"`` (default) the batch symbolic from the first frame and the sides fixed, so that every batch
    size (but 1) runs the first graph and a frame of new sides compiles once more with its sides symbolic; the rest is
    passed to ``torch.compile``: ``True`` every size symbolic from the first frame (minutes to compile a look with
    bloom: see the module's docstring); ``None`` the first size fixed and, at the first new size, one graph with the
    changed sizes symbolic; ``False`` one graph per size, at most eight sizes (Dynamo's ``recompile_limit``: the ninth
    raises ``FailOnRecompileLimitHit``). ``verbose=False`` keeps the compile's lines
    (on the ``torchgrade.compile`` logger, :data:`LOG`) to itself.

    Examples:
        >>> import torchgrade as tg
        >>> tg.compile(tg.ToneMap("aces"), verbose=False).verbose
        False
    """
    if not isinstance(module, nn.Module):
        raise TypeError(f"compile takes an nn.Module, got {type(module).__name__}")
    if dynamic not in ("batch", True, False, None):
        raise ValueError(f"dynamic is 'batch', True, False or None, got {dynamic!r}")
    return CompiledModule(module, cuda_graphs=cuda_graphs, dynamic=dynamic, verbose=verbose)
