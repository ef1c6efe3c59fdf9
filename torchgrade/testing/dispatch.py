"""What a forward would cost a GPU, counted on any device: the operations dispatched and the bytes they move.

On CUDA every operation PyTorch dispatches (views and allocations aside) is a kernel launch, a value read back
(``_local_scalar_dense``: ``.item()``, ``bool()``, ``.tolist()``) waits for the device, and a tensor made from host
data (``lift_fresh``, a CPU-to-device copy) is a pageable copy. A gather of whole rows, a multiple of :data:`ROW_GATHER_BYTES`
each (``table[index]``), runs as CUDA's vectorised gather, a block of threads per index (its cost for a 4K frame's rows
of 8 floats on an H200: ``benchmarks/results/gpu.md``, run D), where gathering each column (``index_select`` on dimension 1) is an
elementwise pass. PyTorch's CUDA elementwise kernels are vectorised only where every operand is contiguous and of
the result's size (a 0-d CPU operand is passed as an argument): an operand broadcast to the frame (a 0-d or per-channel
tensor on the device) or strided takes the unvectorised loop, counted as ``unvectorised``. An elementwise kernel on a frame runs at the memory's
speed, so the bytes its operands and result hold (read and written once) predict its time: counted in *frame
passes*, the bytes over those of one copy of the frame (read and written). On a CPU, where a fused chain is not the
eager form, what matters is what goes to memory and comes back: the results of a plane of the frame or more (*frames
written*: full-frame passes and temporaries, in frames). On the ``meta`` device (shapes, no data) all of this is
counted without computing anything.

Examples:
    >>> import torch
    >>> image = torch.empty(1, 3, 8, 8, device="meta")
    >>> with DispatchCount(frame=image) as counted:
    ...     _ = (image * 2).clamp_(0, 1)
    >>> counted.launches, counted.frame_passes, counted.frames_written
    (2, 2.0, 2.0)
"""

from __future__ import annotations

import collections
from typing import Optional

import torch
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_flatten

__all__ = ["DispatchCount", "VIEWS", "ALLOCATIONS", "ROW_GATHER_BYTES", "UNVECTORISED_FROM"]

VIEWS = {"view", "_unsafe_view", "t", "expand", "unsqueeze", "squeeze", "split", "unbind", "slice", "select", "reshape",
         "alias", "permute", "detach", "as_strided", "transpose", "split_with_sizes", "_reshape_alias"}
"""Operations that make a view: metadata only, no kernel."""

ALLOCATIONS = {"empty", "empty_like", "new_empty", "empty_strided", "new_empty_strided"}
"""Operations that allocate without writing: the caching allocator's work, no kernel."""

UNVECTORISED_FROM = 1 << 16
"""Elements of a result from which an elementwise launch is counted as ``unvectorised``: a smaller one costs its launch."""

ROW_GATHER_BYTES = 16
"""CUDA gathers ``table[index]`` with its vectorised kernel (16-byte loads, one block an index) where a row is a
multiple of this many bytes."""

_HOST_DATA = (torch.ops.aten.lift_fresh.default, torch.ops.aten.lift_fresh_copy.default)
_COPIES = (torch.ops.aten._to_copy.default, torch.ops.aten.copy_.default)


class DispatchCount(TorchDispatchMode):
    """Counts, while active, the operations dispatched (views and allocations aside), the bytes they move, the values read back and
    the tensors made from host data.

    Args:
        frame: the image whose copy is one frame pass (``frame_passes``); ``None`` counts bytes only.

    Attributes:
        moved: the bytes of each launch's tensor operands and results, in the order dispatched.
        reads, host_data: ``Counter`` of values read back from a device (not the CPU) and of tensors made from (or
            copied from) host data.
        row_gathers: gathers of whole rows, a multiple of :data:`ROW_GATHER_BYTES` each: a block of threads an index on
            CUDA.
        unvectorised: elementwise launches of :data:`UNVECTORISED_FROM` elements or more with an operand on the device
            broadcast to the result or strided: CUDA's unvectorised loop.
        by_operation: ``Counter`` of launches per operation name.
        frame_writes: ``Counter`` of the launches per operation name whose result holds a plane of ``frame`` or more.
    """

    def __init__(self, frame: Optional[torch.Tensor] = None):
        super().__init__()
        self.frame_bytes = 2 * frame.numel() * frame.element_size() if frame is not None else None
        self.plane = frame.numel() // frame.shape[-3] if frame is not None else None  # a channel of every image
        self.written: list[int] = []  # bytes of each launch's results of a plane or more
        self.frame_writes: collections.Counter[str] = collections.Counter()
        self.moved: list[int] = []  # bytes each copy moved
        self.reads: collections.Counter[str] = collections.Counter()
        self.host_data: collections.Counter[str] = collections.Counter()
        self.by_operation: collections.Counter[str] = collections.Counter()
        self.row_gathers = 0
        self.unvectorised = 0

    @property
    def launches(self) -> int:
        """Operations dispatched, views and allocations aside: kernel launches on CUDA."""
        return len(self.moved)

    @property
    def frame_passes(self) -> float:
        """The bytes every launch moved over the bytes one copy of the frame reads and writes."""
        return sum(self.moved) / self._frame_bytes("frame_passes")

    @property
    def frames_written(self) -> float:
        """The bytes of the results of a plane of the frame or more, over those of the frame: the full-frame passes and
        temporaries a forward writes (a plane a third of a frame).

        Examples:
            >>> DispatchCount().frames_written
            Traceback (most recent call last):
            ...
            ValueError: frames_written needs the frame: DispatchCount(frame=image)
        """
        return 2 * sum(self.written) / self._frame_bytes("frames_written")

    def _frame_bytes(self, count: str) -> int:
        """The bytes one copy of the frame reads and writes; ``ValueError`` naming ``count`` where no frame was given."""
        if self.frame_bytes is None:
            raise ValueError(f"{count} needs the frame: DispatchCount(frame=image)")
        return self.frame_bytes

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        kernel = _library_kernel(func, args)
        if kernel is not None:  # counted by what its kernel for the device dispatches
            with self:
                return kernel(*args, **kwargs)
        name = func.overloadpacket.__name__
        out = func(*args, **kwargs)
        if func is torch.ops.aten._local_scalar_dense.default:
            if args[0].device.type != "cpu":  # a device waits for its queue; the host's memory is read at once
                self.reads[name] += 1
        elif func in _HOST_DATA:
            self.host_data[name] += 1
        elif func in _COPIES and _from_host(args, kwargs):
            self.host_data[f"{name} from the CPU"] += 1
        elif name not in VIEWS and name not in ALLOCATIONS:
            inputs = {key: value for key, value in kwargs.items() if key != "out"}  # an out= result is counted as the result
            tensors = [t for t in tree_flatten((args, inputs, out))[0] if isinstance(t, torch.Tensor)]
            if all(t.dim() == 0 and t.device.type == "cpu" for t in tensors):
                return out  # a number's arithmetic in the host's memory: no launch
            self.row_gathers += _gathers_rows(func, args)
            self.unvectorised += torch.Tag.pointwise in func.tags and _unvectorised(tensors)
            self.moved.append(sum(t.numel() * t.element_size() for t in tensors))
            self.by_operation[name] += 1
            large = [t for t in tree_flatten(out)[0] if isinstance(t, torch.Tensor) and self.plane and t.numel() >= self.plane]
            if large:
                self.written.append(sum(t.numel() * t.element_size() for t in large))
                self.frame_writes[name] += 1
        return out


def _library_kernel(func, args):
    """The Python kernel a torchgrade operator (``torch.library``) runs off the CPU, for its operations to be counted as
    they dispatch (the operator itself is one call on the host); ``None`` for any other operation."""
    if func.namespace != "torchgrade" or any(isinstance(a, torch.Tensor) and a.device.type == "cpu" for a in args):
        return None
    from ..bloom.blur import _mirror_filter_by_convolution

    return {"mirror_filter": _mirror_filter_by_convolution}.get(func.overloadpacket.__name__)


def _gathers_rows(func, args) -> bool:
    """Whether ``func`` is ``table[index]`` picking whole rows of ``table``, each a multiple of :data:`ROW_GATHER_BYTES`."""
    if func is not torch.ops.aten.index.Tensor:
        return False
    source, indices = args[:2]
    if len(indices) != 1 or indices[0] is None or source.dim() < 2 or source.shape[0] == 0:
        return False
    row = source[0].numel() * source.element_size()
    return row % ROW_GATHER_BYTES == 0


def _unvectorised(operands: list) -> bool:
    """Whether the operands and result of an elementwise launch of :data:`UNVECTORISED_FROM` elements or more hold one,
    off the CPU, that is not a contiguous tensor of the result's size."""
    size = max(t.numel() for t in operands)
    on_device = [t for t in operands if t.dim() > 0 or t.device.type != "cpu"]
    return size >= UNVECTORISED_FROM and any(t.numel() != size or not t.is_contiguous() for t in on_device)


def _from_host(args, kwargs) -> bool:
    devices = {a.device.type for a in args if isinstance(a, torch.Tensor)}
    if kwargs.get("device") is not None:
        devices.add(torch.device(kwargs["device"]).type)
    return "cpu" in devices and len(devices) > 1
