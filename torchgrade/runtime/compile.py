"""A compiled look in one word: :func:`compile` wraps a module in ``torch.compile`` with the mode that suits the
device of the frames it gets.

* **CUDA**: ``mode="reduce-overhead"``: Inductor's fused kernels replayed as a CUDA graph, one launch per frame
  size instead of one per kernel. A graph's outputs are its own buffers, overwritten by the next call of the
  same size: clone an output you keep across calls.
* **CPU**: Inductor's default mode (fused C++ loops over the pixels) without its layout optimisation
  (:data:`CPU_OPTIONS`).
* **Other devices**: Inductor's default mode.

``fullgraph=True`` always: a look is one graph, so a graph break is an error here rather than a silent slowdown.
Each device type compiles at its first frame, with the batch's size symbolic from the start (a last, smaller batch of
an epoch runs the same graph; a batch of 1, a size PyTorch specialises, compiles its own); the first new frame size compiles again, with the sizes that changed made symbolic
(``dynamic=None``, PyTorch's default), so every later size runs that graph. (``dynamic=False``
compiles every size as it comes, and the ninth size stops with ``FailOnRecompileLimitHit``: Dynamo's
``recompile_limit`` is 8 and ``fullgraph=True`` makes hitting it an error.)

**Compiling takes time**, paid at the first frame of each kind (shape, gradients, autocast), and said on the
``torchgrade.compile`` logger (:data:`LOG`, INFO): "compiling the forward of PostFX for a (1, 3, 1080, 1920) float32
frame on cpu, gradients off" and how long it took. ``benchmarks/bench_compile.py`` measures it cold (an empty Inductor
cache), warm (Inductor's on-disk cache from an earlier process) and with saved cache artifacts
(:func:`torchgrade.io.save_compile_cache`, :func:`torchgrade.io.load_compile_cache`: a file to carry to another machine
or container), and the frames a compile takes to repay. :meth:`CompiledModule.warm_up` pays it before a run starts.

In training the forward keeps less for the backward than PyTorch would by default (its activation memory budget,
:data:`ACTIVATION_MEMORY_BUDGET`) and the backward recomputes the rest: a look's steps are per-pixel arithmetic, which
on the CPU cost less to compute again than to write to memory and read back (not yet measured on a GPU).

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
import numbers
import threading
import time
import warnings
from typing import Optional

import torch
from torch import nn

__all__ = ["compile", "compile_mode", "CompiledModule", "CPU_OPTIONS", "ACTIVATION_MEMORY_BUDGET", "LOG"]

LOG = logging.getLogger("torchgrade.compile")
"""Where a compile of a :func:`compile`'d module says that it starts and how long it took (level INFO):
``logging.basicConfig(level=logging.INFO)`` shows it."""


CPU_OPTIONS = {"layout_optimization": False}
"""Inductor's settings on the CPU. Its layout optimisation gives the outputs of a graph's convolutions (the bloom
pyramid's blurs) channels-last buffers; a per-pixel loop that reads such a frame as planes is then not vectorised
(the compiled cinematic look with and without it: ``benchmarks/results/cpu_paths.md``)."""


ACTIVATION_MEMORY_BUDGET = 0.5
"""PyTorch's activation memory budget for a compiled training forward (``torch._functorch.config.activation_memory_budget``):
between 0, what recomputing everything in the backward keeps (the inputs), and 1, what AOTAutograd's min-cut
partitioner keeps by default; the partitioner recomputes the least that holds its estimate of the saved memory there. The frames the compiled look's
forward and backward write at each budget: ``benchmarks/results/inductor_proxy.md``; its training step on the CPU at
0.25, 0.5 and 1.0: ``benchmarks/results/cpu_paths.md``. On a GPU, ``benchmarks/bench_gpu.py``'s ``training_budget``
section times it against 1.0."""


_calling = threading.local()
"""``.label``: what the compiled module running on this thread compiles (:func:`_describe`), while its call runs."""
_compiles: dict = {}
"""Compile id -> ``[label, start time]``: a forward's label names its backward, which compiles later with the same id."""


def _describe(module: nn.Module, image: torch.Tensor) -> str:
    """What a call compiles: the module, the frame and how it is called (gradients, autocast)."""
    autocast = [f"{device} {torch.get_autocast_dtype(device)}".replace("torch.", "") for device in ("cpu", "cuda")
                if torch.is_autocast_enabled(device)]
    return (f"{type(module).__name__} for a {tuple(image.shape)} {str(image.dtype).replace('torch.', '')} frame on "
            f"{image.device.type}, gradients {'on' if torch.is_grad_enabled() else 'off'}"
            + (f", autocast {' and '.join(autocast)}" if autocast else ""))


def _compile_started(event) -> None:
    backward = event.callback_trigger.name == "LAZY_BACKWARD"
    label = _compiles.get(event.compile_id, [None])[0] if backward else getattr(_calling, "label", None)
    if label is None or event.callback_trigger.name not in ("DYNAMO", "LAZY_BACKWARD"):
        return
    _compiles[event.compile_id] = [label, time.perf_counter()]
    LOG.info("compiling the %s of %s (tens of seconds on a cold cache, less from Inductor's or a loaded cache)",
             "backward" if backward else "forward", label)


def _compile_ended(event) -> None:
    if event.callback_trigger.name not in ("DYNAMO", "LAZY_BACKWARD") or event.compile_id not in _compiles:
        return
    label, started = _compiles[event.compile_id]
    LOG.info("compiled the %s of %s in %.1f s", "backward" if event.callback_trigger.name == "LAZY_BACKWARD" else "forward",
             label, time.perf_counter() - started)


def _watch_compiles() -> None:
    """Follow Dynamo's compile events: :func:`_compile_started` and :func:`_compile_ended`, registered once and again
    after ``torch._dynamo.reset()``, which forgets them."""
    from torch._dynamo import callback

    if _compile_started not in callback.callback_handler.start_callbacks:
        callback.on_compile_start(_compile_started)
        callback.on_compile_end(_compile_ended)


def compile_mode(device: torch.device, cuda_graphs: bool = True) -> str:
    """The ``torch.compile`` mode for frames on ``device``: CUDA graphs on CUDA (unless ``cuda_graphs=False``)."""
    return "reduce-overhead" if device.type == "cuda" and cuda_graphs else "default"


class CompiledModule(nn.Module):
    """``module`` compiled per device type at its first frame there (see :func:`compile`); ``module`` is
    :attr:`module`, so its controls, state and ``to_config`` stay reachable."""

    def __init__(self, module: nn.Module, cuda_graphs: bool = True, dynamic: Optional[bool] = None,
                 activation_memory_budget: float = ACTIVATION_MEMORY_BUDGET):
        super().__init__()
        if isinstance(activation_memory_budget, bool) or not isinstance(activation_memory_budget, numbers.Real):
            raise TypeError(f"activation_memory_budget must be a number, got {type(activation_memory_budget).__name__}")
        if not 0.0 <= activation_memory_budget <= 1.0:
            raise ValueError(f"activation_memory_budget must lie in [0, 1], got {activation_memory_budget}")
        self.module = module
        self.cuda_graphs = cuda_graphs
        self.dynamic = dynamic
        self.activation_memory_budget = float(activation_memory_budget)
        self._compiled: dict = {}

    def compiled_for(self, device: torch.device):
        """The compiled callable for frames on ``device`` (compiled lazily: the first frame pays the compile time)."""
        call = self._compiled.get(device.type)
        if call is None:
            # torch.compile takes a mode or options: on the CPU, the options of the default mode (CPU_OPTIONS)
            settings = {"options": CPU_OPTIONS} if device.type == "cpu" else {"mode": compile_mode(device, self.cuda_graphs)}
            call = torch.compile(self.module, fullgraph=True, dynamic=self.dynamic, **settings)
            self._compiled[device.type] = call
        return call

    def forward(self, image: torch.Tensor, *args, **kwargs):
        """Check the learnable controls of every stage (``check_learnable``, which the graph skips), then run the graph
        inside the module's ``compiled_frame`` where it has one.

        A frame the module refuses (an image of 2 channels, integer values, not a tensor) raises while Dynamo traces
        it, which reports that as an ``Unsupported`` error of its own; the module is then called eagerly on the frame,
        to raise its own error, as an uncompiled module would (should the eager call not raise, its output is returned,
        with a ``RuntimeWarning``: the frame ran once, eagerly)."""
        if not isinstance(image, torch.Tensor):
            return self.module(image, *args, **kwargs)  # the module's own TypeError
        for stage in self.module.modules():
            if hasattr(stage, "check_learnable"):
                stage.check_learnable()
        try:
            return self._graph_call(image, *args, **kwargs)
        except Exception as error:
            if not _raised_while_traced(error):
                raise
            refused = error
        out = self.module(image, *args, **kwargs)  # raises the module's own error (outside the handler: that error alone)
        warnings.warn(f"the compiled graph of {type(self.module).__name__} raised where eager mode does not: this frame "
                      f"ran eagerly ({str(refused).splitlines()[0]})", RuntimeWarning, stacklevel=2)
        return out

    def _graph_call(self, image: torch.Tensor, *args, **kwargs):
        prepare = getattr(self.module, "compiled_arguments", None)
        if prepare is not None:  # what must happen before the graph: a random draw from a generator
            (image, *args), kwargs = prepare(image, *args, **kwargs)
        if self.dynamic is None:
            _batch_may_change(image, *args, *kwargs.values())
        _watch_compiles()
        _calling.label = _describe(self.module, image)
        frame = getattr(self.module, "compiled_frame", None)
        try:
            with frame(image, *args, **kwargs) if frame is not None else contextlib.nullcontext(), self._budget():
                return self.compiled_for(image.device)(image, *args, **kwargs)
        finally:
            _calling.label = None

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

    def _budget(self):
        """The activation memory budget, set for a call that records gradients (where a training graph may compile; the
        partitioner reads it then). PyTorch's setting is the process's: another thread's compile meanwhile sees it too."""
        if not torch.is_grad_enabled():
            return contextlib.nullcontext()
        from torch._functorch import config

        if not hasattr(config, "activation_memory_budget"):
            warnings.warn("this torch has no activation memory budget: a compiled training forward keeps what PyTorch "
                          "keeps by default", RuntimeWarning, stacklevel=4)
            return contextlib.nullcontext()
        return config.patch(activation_memory_budget=self.activation_memory_budget)


def _batch_may_change(*values) -> None:
    """Tell Dynamo that the first size of every tensor given (the batch, and a batch of drawn parameters) may change
    from call to call, so that the first graph already serves every batch size; a batch of 1 it may still specialise."""
    from torch._dynamo import maybe_mark_dynamic

    for value in values:
        tensors = value.values() if isinstance(value, dict) else (value,)
        for tensor in tensors:
            if isinstance(tensor, torch.Tensor) and tensor.dim() > 0:
                maybe_mark_dynamic(tensor, 0)


def _raised_while_traced(error: Exception) -> bool:
    """Whether ``error`` is Dynamo's report of an exception that the traced code raised (its cause: an exception Dynamo
    observed). Imported here: ``import torchgrade`` does not load ``torch._dynamo``."""
    from torch._dynamo import exc

    return isinstance(error, exc.Unsupported) and isinstance(error.__cause__, getattr(exc, "ObservedException", ()))


def compile(module: nn.Module, *, cuda_graphs: bool = True, dynamic: Optional[bool] = None,
            activation_memory_budget: float = ACTIVATION_MEMORY_BUDGET) -> CompiledModule:
    """``module`` (a stage, a :class:`~torchgrade.PostFX`, a :class:`~torchgrade.RandomPostFX`, a LUT) through
    ``torch.compile`` with one graph and the device's mode (:func:`compile_mode`).

    ``dynamic`` is passed to ``torch.compile``: ``None`` (default) compiles the first size with fixed sizes and, at
    the first new size, one graph with the changed sizes symbolic, which every later size runs; ``True`` symbolic
    sizes from the start; ``False`` one graph per size, at most eight sizes (Dynamo's ``recompile_limit``: the
    ninth raises ``FailOnRecompileLimitHit``). ``activation_memory_budget`` (0 to 1): what a training forward keeps
    for the backward, between recomputing everything (0) and PyTorch's default (1; :data:`ACTIVATION_MEMORY_BUDGET`).
    It is read where a training graph compiles, and Dynamo does not guard on it: a module of the same structure
    compiled earlier in the process runs the graph compiled then, with the budget it had (``torch._dynamo.reset()``
    forgets it).
    """
    if not isinstance(module, nn.Module):
        raise TypeError(f"compile takes an nn.Module, got {type(module).__name__}")
    return CompiledModule(module, cuda_graphs=cuda_graphs, dynamic=dynamic, activation_memory_budget=activation_memory_budget)

