"""Speed of the ACES 2.0 SDR output (``ToneMap("aces2")``, BT.1886-encoded) on a 1920×1080 float32 frame on CPU,
side by side with OpenColorIO's CPU processor applying the same view.

OpenColorIO 2.6's builtin ``studio-config-v4.0.0_aces-v2.0_ocio-v2.5``: "Linear Rec.709 (sRGB)" to the
"Rec.1886 Rec.709 - Display" with view "ACES 2.0 - SDR 100 nits (Rec.709)". torchgrade runs
:func:`~torchgrade.tonemap.aces2.aces2_output` with ``encoding="bt1886"`` eagerly and through
``torch.compile`` (compile time is its first call, reported apart). Every round runs each method once
(interleaved, so machine load hits all alike); medians of the rounds in ms, ms per megapixel, and the ratio
to OpenColorIO. The frame is the Desk sample exposed to a median luminance of 0.18, tiled to 1920×1080;
the outputs' largest difference in 8-bit codes is reported too.

Run: ``.venv/bin/python -m benchmarks aces2 [--out DIR]`` (writes aces2.json and aces2.md to ``--out``,
default benchmarks/out; the committed ones with ``--out benchmarks/results``).
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np
import torch

from benchmarks.common import argument_parser, median_ms, packed_rgb, sample_exr, write_results
from torchgrade.tonemap.aces2 import aces2_output
from torchgrade.tonemap.aces2.transform import prepare_output

ROOT = Path(__file__).resolve().parents[1]

COMMAND = ".venv/bin/python -m benchmarks aces2"
HEIGHT, WIDTH, RUNS = 1080, 1920, 5
CONFIG, SOURCE = "studio-config-v4.0.0_aces-v2.0_ocio-v2.5", "Linear Rec.709 (sRGB)"
DISPLAY, VIEW = "Rec.1886 Rec.709 - Display", "ACES 2.0 - SDR 100 nits (Rec.709)"


def frame() -> torch.Tensor:
    """Desk, exposed so its median Rec.709 luminance is 0.18, tiled to ``(1, 3, HEIGHT, WIDTH)``."""
    image = sample_exr("Desk", to_rec709=True)
    y = (image * torch.tensor([0.2126729, 0.7151522, 0.0721750]).reshape(1, 3, 1, 1)).sum(1)
    image = image * (0.18 / y[y > 0].median())
    reps = (1, 1, -(-HEIGHT // image.shape[2]), -(-WIDTH // image.shape[3]))
    return image.repeat(*reps)[:, :, :HEIGHT, :WIDTH].contiguous()


def ocio_view():
    import PyOpenColorIO as OCIO

    config = OCIO.Config.CreateFromBuiltinConfig(CONFIG)
    return config.getProcessor(SOURCE, DISPLAY, VIEW, OCIO.TRANSFORM_DIR_FORWARD).getDefaultCPUProcessor()


def measure() -> dict:
    image = frame()
    processor, packed = ocio_view(), packed_rgb(image)
    buffer = packed.copy()
    eager = lambda: aces2_output(image, encoding="bt1886")  # noqa: E731
    prepare_output(100.0, "rec709")  # the tables, built before compiling as a stage builds them: the graph finds them
    compiled_fn = torch.compile(aces2_output, dynamic=False, fullgraph=True)
    start = time.perf_counter()
    with torch.no_grad():
        compiled_out = compiled_fn(image, encoding="bt1886")
    compile_s = time.perf_counter() - start
    calls = {
        "opencolorio": ((lambda: processor.applyRGB(buffer)), (lambda: np.copyto(buffer, packed))),
        "torchgrade eager": eager,
        "torchgrade compiled": lambda: compiled_fn(image, encoding="bt1886"),
    }
    ms = median_ms(calls, RUNS)
    with torch.no_grad():
        ours = eager()[0].permute(1, 2, 0).reshape(-1, 3).numpy()
    reference = packed.copy()
    processor.applyRGB(reference)
    reference = np.clip(reference.reshape(-1, 3), 0.0, 1.0)
    codes = lambda a: float(np.abs(a - reference).max() * 255)  # noqa: E731
    mp = HEIGHT * WIDTH / 1e6
    return {
        "frame": f"{WIDTH}x{HEIGHT} float32", "threads": torch.get_num_threads(), "torch": torch.__version__,
        "machine": platform.processor() or platform.machine(), "compile_s": round(compile_s, 1),
        "ms": {k: round(v, 1) for k, v in ms.items()},
        "ms_per_mp": {k: round(v / mp, 1) for k, v in ms.items()},
        "ratio_to_opencolorio": {k: round(v / ms["opencolorio"], 2) for k, v in ms.items()},
        "max_8bit_code_difference": {"eager": round(codes(ours), 3),
                                     "compiled": round(codes(compiled_out[0].permute(1, 2, 0).reshape(-1, 3).numpy()), 3)},
    }


def markdown(result: dict) -> str:
    lines = [f"ACES 2.0 SDR (BT.1886) on a {result['frame']} frame, CPU, {result['threads']} threads, torch {result['torch']}, "
             f"median of {RUNS} interleaved rounds (`{COMMAND}`).", "",
             "| method | ms | ms / MP | × OpenColorIO |", "| --- | --- | --- | --- |"]
    for name, ms in result["ms"].items():
        lines.append(f"| {name} | {ms} | {result['ms_per_mp'][name]} | {result['ratio_to_opencolorio'][name]} |")
    lines += ["", f"torch.compile's first call: {result['compile_s']} s. Largest difference from OpenColorIO: "
              f"{result['max_8bit_code_difference']['eager']} (eager), {result['max_8bit_code_difference']['compiled']} (compiled) 8-bit codes."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    args = argument_parser(__doc__).parse_args(argv)
    result = measure()
    write_results(args.out, "aces2", result, markdown(result).splitlines(), COMMAND)


if __name__ == "__main__":
    main()
