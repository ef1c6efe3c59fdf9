"""The GPU path, measured on the CPU: what a frame would cost a GPU, counted where no GPU is needed.

* **Launches.** Every operation PyTorch dispatches on a device that is not the CPU is a kernel launch on CUDA.
  On the ``meta`` device (shapes, no data) the execution policy is that of a GPU (whole frames, no reads), so
  the operations a 4K frame dispatches there are the launches it would make: held under :data:`LAUNCH_BUDGET`.
* **No host synchronisation.** After the first frame (which may build constants and tables), a forward reads
  no value back (``_local_scalar_dense``: ``.item()``, ``bool()``, ``.tolist()``) and makes no tensor from host
  data (``lift_fresh``, a CPU-to-device copy): on CUDA each is a wait or a pageable copy. Checked for every case
  of ``tests/runtime/test_device.py``, in inference and in training.
* **Fused, compiled.** Inductor on the CPU compiles the cinematic look with no matrix-library call (a 3x3
  colour matrix as ``mm``/``bmm`` is a cuBLAS ``gemv`` on CUDA that nothing fuses) and in few kernels; every
  stage and look is captured as one graph (``fullgraph=True``).
"""

from __future__ import annotations

import contextlib
import json
import re
from pathlib import Path

import pytest
import torch

import torchgrade as tg
from test_device import CASES
from torchgrade.testing.dispatch import DispatchCount

FOUR_K = (1, 3, 2160, 3840)
AUGMENTED = (256, 3, 224, 224)

CINEMATIC = json.loads((Path(__file__).resolve().parents[2] / "export" / "looks" / "cinematic.json").read_text())

LAUNCH_BUDGET = {"cinematic": 419, "exposure": 51, "bloom": 229, "grade": 48, "tonemap": 94}
"""Operations dispatched for one 3840x2160 frame of ``export/looks/cinematic.json`` (no_grad), per stage and whole:
each a kernel launch on CUDA (arithmetic on 0-d CPU tensors alone launches nothing). Measured 419 (exposure 51, bloom
229, grade 48, tone map 94) since each formula has one form, eager, under autograd, compiled and exported: bloom halves
an even level by four strided views (four launches where ``avg_pool2d`` was one), resamples its odd levels by their
steps (nine launches a side where a matrix product was one), and blurs through its operator's convolutions off the
CPU (four launches); the tone mapper's RRT reads its three planes and its hue's distance from red without ``atan2``,
the grade blends split toning's planes and joins them, and guards that keep gradients finite cost an operation each
(``relu``). 287 (exposure 51, bloom 106, grade 47, tone map 86) with the eager forms of a GPU's policy (library
kernels, in-place forms without guards); 292 (bloom 111)
before bloom's levels held means (no division by a block's pixel count)
and its odd levels (135x240, 17x30, 9x15, 5x8) were resampled by a matrix a side; log contrast's slope on the host (``runtime.scalar``) took 2. The histogram counted per
column (then ``ExecutionPolicy.histogram_tables``) took 3 of them and an H200's 4K exposure from 13.2 to 1.7 ms; 300
before the ACES fit and sigmoid took a product and a sum by numbers as one operation (``runtime.affine``) and the dim
surround's planes went into the last matrix without a concatenation; 401 before the grade's split toning, the ACES
fit's sigmoid and the bloom's knee were written in fewer operations, the small pyramid levels blurred by one
convolution, constants of plain-number controls folded and each stage after the first told that its input holds no
NaN. An H200 counted 303 launches for 291 of them and 370 for 351 (``benchmarks/results/gpu.md``), where the look made
16,875 in strips and 1,060 in whole frames before (``../shared/measurements/gpu-h200``)."""

FRAME_PASS_BUDGET = {"cinematic": 119.5, "exposure": 10.4, "bloom": 15.7, "grade": 40.4, "tonemap": 56.2}
"""Bytes those operations move, in copies of the frame (read and written): what an eager frame's time on a GPU follows
(``benchmarks/gpu_proxy.py``). Measured 119.5 (exposure 10.3, bloom 15.6, grade 40.3, tone map 56.2) with one form a
formula; 116.8 (exposure 10.4, bloom 14.5, grade 40.7, tone map 54.2) with a GPU's eager forms; 118.2 (bloom 16.0)
before bloom's pyramid spanned the frame at every size; 117.5 (exposure
9.7) before the histogram per column, 123.2 and 149.0 before the changes of the two sentences above."""

UNVECTORISED_BUDGET = {"cinematic": 62, "exposure": 2, "bloom": 32, "grade": 12, "tonemap": 16}
"""Those of the operations that CUDA runs in its unvectorised loop (``DispatchCount.unvectorised``: an operand
broadcast to the frame or strided), a third of the look's kernel time on an H200 (53 launches, 3.2 of 8.3 ms,
``benchmarks/results/gpu.md``). Measured 62 (exposure 2, bloom 32: the strided views of its halving, grade 12, tone
map 16) with one form a formula; 48 (exposure 2, bloom 17, grade 12, tone map 17) with a GPU's eager forms; 54 (bloom 23) before bloom's
levels held means; 69 (1, 27, 16, 25) before
plain numbers went to two-operand kernels as 0-d CPU operands (``runtime.scalar``): ``runtime.affine``, the soft knee,
log contrast's slope, ``safe_pow``'s floor and the ACES glow's division."""


def _cinematic_stages() -> dict:
    look = tg.PostFX.from_config(CINEMATIC).eval()
    return {"cinematic": look, **{name: stage for name, stage in look.stages().items()}}


def _second_frame(module, image: torch.Tensor, train: bool = False) -> DispatchCount:
    """What the second frame through ``module`` dispatches (the first builds constants and tables)."""
    for _ in range(2):
        counted = DispatchCount(frame=image)
        with torch.set_grad_enabled(train), counted:
            out = module(image)
            if train:
                out.sum().backward()
    return counted


@pytest.mark.parametrize("name", list(LAUNCH_BUDGET))
def test_a_4k_frame_of_the_cinematic_look_launches_and_moves_within_its_budget(name):
    module = _cinematic_stages()[name].to("meta")
    counted = _second_frame(module, torch.empty(FOUR_K, device="meta"))
    assert counted.launches <= LAUNCH_BUDGET[name], f"{name}: {counted.launches} operations a 4K frame"
    assert counted.frame_passes <= FRAME_PASS_BUDGET[name], f"{name}: {counted.frame_passes:.1f} frame passes"
    assert counted.unvectorised <= UNVECTORISED_BUDGET[name], f"{name}: {counted.unvectorised} unvectorised"
    assert not counted.row_gathers


STAGE_BUDGETS = {
    "ToneMap('aces2')": (lambda: tg.ToneMap("aces2"), FOUR_K, 329, 162.8, 35),
    "LUT3D 33³ logc_hdr": (lambda: tg.LUT3D(torch.rand(33, 33, 33, 3), shaper="logc_hdr"), FOUR_K, 30, 35.1, 7),
    "RandomPostFX": (lambda: tg.RandomPostFX(contrast=30, saturation=30, hue_shift=20, post_exposure=0.5, input_space="srgb"),
                     AUGMENTED, 99, 52.1, 22),
}
"""Stages outside the look: ``(make, image shape, operations, passes over that image, unvectorised)``, no_grad.
ACES 2.0 at 4K measured 329, 162.8 and 35 with one form a formula (its polar coordinates' guards, the sign of a
cone's response as a product, where ONNX has no ``copysign``, and its hue tables read by a binned lookup); 316, 155.2 and 37 with a GPU's eager forms (414 and 204.4 before each run of its matrices was folded into one, its hue
tables were read a segment at a time, its chroma normaliser became a polynomial and its achromatic lightness and
luminance took their constants into one product and sum each; 85 unvectorised before its segments were gathered by
column and ``runtime.scalar``). A 33³ ``logc_hdr`` LUT (as ``benchmarks/gpu_proxy.py`` bakes the cinematic look) at
4K measured 30, 35.0 and 7 (96 and 58.9 before the eager lookup off the CPU took the whole-frame form, the shaper's
tail took two operations a segment and LogC's products and sums by numbers one each). ``RandomPostFX`` as
``benchmarks/bench_gpu.py`` sets it against kornia's ``ColorJiggle`` measured 99, 52.0 and 22 with one form a formula
(its saturation folded into the grade's last matrix, per sample as it is; LogC contrast as one power, its per-sample
gain a product and the offset a difference by a number, where CUDA's ``addcmul`` takes no 0-d CPU first operand);
100, 52.0 and 22 with a GPU's eager forms (102, 54.7 and 21 before
the hue shift kept HSV as three planes instead of stacking and joining a frame and took the dominant channel by
comparison instead of argmax's 8-byte indices, two comparisons of a batch's strided channels; 109 and 63.2 before HSV
to RGB, sRGB and LogC contrast took their products and sums by numbers as one operation; 26 unvectorised)."""


@pytest.mark.parametrize("name", list(STAGE_BUDGETS))
def test_a_frame_through_a_stage_launches_and_moves_within_its_budget(name):
    make, shape, launches, passes, unvectorised = STAGE_BUDGETS[name]
    counted = _second_frame(make().to("meta"), torch.empty(shape, device="meta"))
    assert counted.launches <= launches and counted.frame_passes <= passes, (counted.launches, counted.frame_passes)
    assert counted.unvectorised <= unvectorised, counted.unvectorised
    assert not counted.row_gathers  # a block of threads a pixel on CUDA
    assert "mm" not in counted.by_operation and "bmm" not in counted.by_operation  # TF32 would round a LUT's indices


HOST_DRAWS = {name: "draws from the CPU generator the case passes, so that every device sees the same looks"
              for name in ("random-postfx", "random-postfx-tonemaps")}
"""Cases that copy from the host by the caller's choice, and why (without a generator a layer draws on the device:
:func:`test_a_random_layer_draws_on_the_images_device`)."""


@pytest.mark.parametrize("train", [False, True], ids=["inference", "training"])
@pytest.mark.parametrize("name", [name for name in CASES if name not in HOST_DRAWS])
def test_after_the_first_frame_nothing_is_read_back_or_copied_from_the_host(name, train):
    module = CASES[name]().to("meta")
    image = torch.empty(2, 3, 40, 56, device="meta", requires_grad=train)
    counted = _second_frame(module, image, train)
    assert not counted.reads and not counted.host_data, f"reads {dict(counted.reads)}, host data {dict(counted.host_data)}"


def test_a_random_layer_draws_on_the_images_device():
    layer = tg.RandomPostFX(contrast=30, saturation=20, bloom_intensity=(0.2, 0.6), tonemap=("aces", "neutral"))
    counted = _second_frame(layer, torch.empty(4, 3, 40, 56, device="meta"))
    assert not counted.reads and not counted.host_data, f"reads {dict(counted.reads)}, host data {dict(counted.host_data)}"
    assert all(value.device.type == "meta" for value in layer.last_params.values())


EXTERN_MATRIX_CALLS = re.compile(r"extern_kernels\.(mm|bmm|addmm|baddbmm)\b|aten\.(mm|bmm|addmm)\b")
FUSED_KERNEL_CALL = re.compile(r"^\s+cpp_fused_\w+\(", re.MULTILINE)
FUSED_KERNEL_BUDGET = 12
"""Fused kernels a frame of the compiled cinematic look calls on the CPU (measured 9: the bloom pyramid's levels,
the rest fused with them; beside them, the pyramid's depthwise convolutions, which kornia picks on the CPU)."""


def test_inductor_compiles_the_cinematic_look_without_matrix_calls_in_few_kernels():
    from torch._inductor import metrics
    from torch._inductor.utils import run_and_get_code

    torch.compiler.reset()
    look = tg.PostFX.from_config(CINEMATIC).eval()
    compiled = tg.compile(look)
    image = torch.rand(1, 3, 64, 96) * 8
    with torch.no_grad():
        out, code = run_and_get_code(compiled, image)
        expected = tg.PostFX.from_config(CINEMATIC).eval()(image)
    source = "\n".join(code)
    assert not EXTERN_MATRIX_CALLS.search(source), EXTERN_MATRIX_CALLS.findall(source)
    launched = FUSED_KERNEL_CALL.findall(source)
    assert len(launched) <= FUSED_KERNEL_BUDGET, f"{len(launched)} fused kernels a frame ({metrics.generated_kernel_count} generated)"
    torch.testing.assert_close(out, expected, rtol=1e-4, atol=1e-5)


FRAME_BUFFER = re.compile(r"empty_strided_\w+\(\(([\d, ]+)\)")


def frame_buffers(source: str, pixels: int) -> int:
    """The buffers of a frame's size or more that a compiled graph allocates: the frames its kernels write (a frame
    written by one kernel and read by the next is a pass over memory each way, and on a GPU two kernels)."""
    sizes = [[int(n) for n in shape.replace(" ", "").split(",") if n] for shape in FRAME_BUFFER.findall(source)]
    return sum(1 for size in sizes if torch.Size(size).numel() >= pixels)


EVERY_PLANE_STEP = dict(post_exposure=0.4, temperature=20, contrast=30, split_shadows=(0.4, 0.5, 0.6), channel_mixer=((1.0, 0.05, 0.0), (0.0, 1.0, 0.05), (0.05, 0.0, 1.0)),
                        midtones=(1.05, 1.0, 0.95), lift=(0.95, 1.0, 1.0, 0.01), gamma=(1.0, 1.0, 0.9, 0.05), gain=(1.0, 0.95, 1.0, 0.1),
                        hue_shift=-30.0, saturation=-20.0, hue_vs_sat=((0.0, 0.5), (0.4, 0.6), (0.8, 0.45)),
                        lum_vs_sat=((0.0, 0.5), (0.5, 0.55), (1.0, 0.4)))
"""Every step of the grade a compiler gets on planes (its YRGB curves and tensor split-toning colours it gets joined)."""
PLANES_CHAINS = {"tonemap-aces": lambda: tg.ToneMap("aces"), "grade": lambda: tg.ColorGrade(**CINEMATIC["grade"]),
                 "grade-every-plane-step": lambda: tg.ColorGrade(**EVERY_PLANE_STEP)}
"""Per-pixel chains a compiler gets on planes (:func:`~torchgrade.runtime.strips.pixelwise`): the ACES curve, the look's grade, every
step of the grade that runs on planes."""


@pytest.mark.parametrize("name", list(PLANES_CHAINS))
def test_inductor_compiles_a_chain_on_planes_into_one_pass_that_writes_only_the_output(name):
    """As Inductor compiles it on the CPU: the only frame it writes is its output, each value read once and written
    once (on frames, ``ToneMap("aces")`` wrote 6 and the grade 5: ``benchmarks/results/inductor_proxy.md``)."""
    from torch._inductor.utils import run_and_get_code

    torch.compiler.reset()
    image = torch.rand(1, 3, 64, 96, generator=torch.Generator().manual_seed(0)) * 8
    with torch.no_grad():
        out, code = run_and_get_code(torch.compile(PLANES_CHAINS[name](), fullgraph=True), image)
        eager, exact = PLANES_CHAINS[name]()(image), PLANES_CHAINS[name]()(image.double())
    assert frame_buffers("\n".join(code), 64 * 96) == 1
    # float32 rounding in another order (eager, the grade's ACEScc contrast is one folded power): near float64 as eager is
    assert (out.double() - exact).abs().max() <= 3 * (eager.double() - exact).abs().max() + 1e-6


def test_inductor_compiles_the_augmentation_into_one_pass_that_writes_only_the_output():
    """``RandomPostFX`` as ``bench_gpu.py`` races it against kornia's ``ColorJiggle`` (sRGB in and out, a grade with a hue
    shift), with skipped samples: its grade's planes are finished plane by plane into the output, the one frame written
    (it wrote 2.33 frames an image when the grade joined its planes and the output was encoded as one frame)."""
    from torch._inductor.utils import run_and_get_code

    torch.compiler.reset()
    layer = tg.RandomPostFX(contrast=30, saturation=30, hue_shift=20, post_exposure=0.5, input_space="srgb", p=0.5)
    images = torch.rand(4, 3, 64, 96, generator=torch.Generator().manual_seed(0))
    layer(images, generator=torch.Generator().manual_seed(1))
    params = layer.last_params
    with torch.no_grad():
        out, code = run_and_get_code(torch.compile(lambda x: layer(x, params=params), fullgraph=True), images)
        eager = layer(images, params=params)
    assert frame_buffers("\n".join(code), 64 * 96) == 1
    torch.testing.assert_close(out, eager, rtol=1e-5, atol=1e-5)


def captured_graph(module: torch.nn.Module, image: torch.Tensor) -> torch.fx.GraphModule:
    """The graph Dynamo captures of ``module`` on ``image`` (no compiler runs it)."""
    graphs = []

    def keep(graph, inputs):
        graphs.append(graph)
        return graph.forward

    torch.compiler.reset()
    with torch.no_grad():
        torch.compile(module, fullgraph=True, backend=keep)(image)
    return graphs[0]


@pytest.mark.parametrize("name", ["tonemap-aces", "tonemap-aces2", "tonemap-aces2_hdr", "grade", "grade-every-plane-step"])
def test_a_compiled_chain_stays_on_planes_from_its_first_step_on_one_to_its_stack(name):
    """The graph Inductor is given (:func:`~torchgrade.runtime.strips.pixelwise`): once a step computes one value a pixel, no
    step computes more until the stack that makes the output (a frame's 3 values a pixel, or ACES 2.0's 8 table
    values, start another loop, and on a GPU another kernel). Their compiled form:
    ``test_inductor_compiles_a_chain_on_planes_into_one_pass_that_writes_only_the_output``."""
    module = PLANES_CHAINS[name]() if name in PLANES_CHAINS else tg.ToneMap(name.removeprefix("tonemap-"))
    image = torch.rand(1, 3, 8, 12)
    pixels = 8 * 12
    values_a_pixel = []
    for node in captured_graph(module, image).graph.nodes:
        value = node.meta.get("example_value")
        if node.op in ("call_function", "call_method") and isinstance(value, torch.Tensor) and value.shape[-2:] == image.shape[-2:]:
            values_a_pixel.append((value.numel() / pixels, str(node.target)))
    on_planes = values_a_pixel[[count for count, _ in values_a_pixel].index(1):]
    assert [count for count, _ in on_planes[:-1]] == [1] * (len(on_planes) - 1), [s for s in on_planes if s[0] != 1]
    assert on_planes[-1][0] == 3 and "stack" in on_planes[-1][1]


GRAPHS = {
    **{f"tonemap-{mode}": (lambda mode=mode: tg.ToneMap(mode)) for mode in tg.TONEMAP_MODES},
    "cinematic": lambda: tg.PostFX.from_config(CINEMATIC).eval(),
    "random-postfx": lambda: tg.RandomPostFX(contrast=30, saturation=20, bloom_intensity=(0.2, 0.6), tonemap="aces"),
    "lut": lambda: tg.LUT3D(tg.lut.identity_table(9) ** 1.5, shaper="logc"),
    "grade-curves": CASES["grade-curves"],
}


@pytest.mark.parametrize("eager_first", [False, True], ids=["compiled-first", "after-an-eager-frame"])
@pytest.mark.parametrize("name", list(GRAPHS))
def test_every_stage_and_look_is_captured_as_one_graph(name, eager_first):
    """Dynamo alone (backend "eager": the capture is what can break); ``fullgraph=True`` raises at a graph break.
    Captured fresh, and after an eager frame, as a user compiles a module after trying it: its caches are filled then."""
    torch.compiler.reset()
    module = GRAPHS[name]()
    image = torch.rand(2, 3, 24, 32) * 4
    with torch.no_grad():
        torch.manual_seed(1)
        eager = module(image) if eager_first else None
        torch.manual_seed(1)
        captured = torch.compile(module, fullgraph=True, backend="eager")(image)
        torch.manual_seed(1)
        eager = module(image) if eager is None else eager
    torch.testing.assert_close(captured, eager, rtol=1e-5, atol=1e-6)


def test_compile_picks_cuda_graphs_on_cuda_only():
    assert tg.runtime.compile_mode(torch.device("cuda")) == "reduce-overhead"
    assert tg.runtime.compile_mode(torch.device("cuda"), cuda_graphs=False) == "default"
    assert tg.runtime.compile_mode(torch.device("cpu")) == "default"
    with pytest.raises(TypeError, match="nn.Module"):
        tg.compile(lambda x: x)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="device-conditional: needs CUDA")
def test_on_cuda_a_learnable_control_out_of_range_raises_at_a_later_forward_without_a_sync():
    grade = tg.ColorGrade(contrast=torch.nn.Parameter(torch.tensor(20.0))).cuda()
    image = torch.rand(1, 3, 16, 16, device="cuda")
    grade(image)
    with torch.no_grad():
        grade.contrast.fill_(500.0)  # what an optimiser step could do
    counted = DispatchCount()
    with counted, contextlib.suppress(ValueError):  # on an idle GPU the copy may land before this forward checks
        grade(image)  # the step's forward: the value's copy is on its way
    assert not counted.reads
    torch.cuda.synchronize()
    with pytest.raises(ValueError, match=r"contrast must lie in \[-100.0, 100.0\], got 500.0"):
        grade(image)
