"""Grade a shot on a Ray cluster with Ray Data: read -> ``map_batches`` -> write, frame by frame, with
the same per-frame function as ``torchgrade grade`` (:func:`torchgrade.shots.frames.render_frame`).

Needs the ``ray`` extra (``pip install torchgrade[ray]``); Ray is imported only when called.

**Eye adaptation across a cluster.** Adaptation is a recurrence: frame ``i``'s exposure depends on
the adapted luminance left by frame ``i - 1``. It depends on the frames only through one metered
number each, so a look with an exposure stage is graded in three steps: (1) meter every frame in
parallel (one float per frame); (2) run the recurrence on those floats on the driver, in frame order,
which costs microseconds per frame; (3) grade every frame in parallel from the adapted luminance it
starts from. Step 2 feeds each metered value to the stage's own stateless :meth:`AutoExposure.frame`
as a one-pixel frame of that luminance, so the recurrence is the stage's own code; the frames then
match a sequential run to float rounding (about 1e-7 relative) rather than bit for bit.

Examples:
    >>> from torchgrade import PostFX
    >>> look = PostFX(exposure={"metering": "mean"}, tonemap="aces")
    >>> [round(v, 3) for v in adaptation_schedule(look, [0.5, 2.0, 2.0], dt=0.5)]
    [0.0, 0.5, 1.09]
"""

from __future__ import annotations

from pathlib import Path

import torch

from ..shots.frames import output_paths, render_frame, shot_frames
from ..shots.outputs import check_output, write_frame
from ..exposure import AutoExposure
from ..io import read_exr
from ..look.postfx import PostFX

__all__ = ["adaptation_schedule", "grade_rows", "grade_shot_on_ray"]


def adaptation_schedule(look: PostFX, metered: list, dt: float) -> list:
    """The adapted luminance each frame starts from (0 for the first: it adapts instantly), from the frames' metered luminances."""
    before, adapted = [], torch.zeros(1)
    for value in metered:
        before.append(float(adapted))
        _, adapted = _exposure(look).frame(torch.full((1, 3, 1, 1), float(value)), adapted, dt)
    return before


def _exposure(look: PostFX) -> AutoExposure:
    """The look's exposure stage, which the adaptation steps run; ``ValueError`` for a look without one."""
    if look.exposure is None:
        raise ValueError("the look has no exposure stage to adapt")
    return look.exposure


def _read(path: str, read_options: dict) -> torch.Tensor:
    return read_exr(path, window="display", **read_options)[:3]


def _meter_rows(batch: dict, look: PostFX, read_options: dict) -> dict:
    """Step 1: each frame's metered luminance, what its exposure stage adapts to at once on a first frame."""
    metered = [_exposure(look).frame(_read(path, read_options).unsqueeze(0), None, 0.0)[1].item() for path in batch["path"]]
    return {"index": batch["index"], "metered": metered}


def grade_rows(batch: dict, look: PostFX, read_options: dict, depth: str, dt: float, scene_referred: bool) -> dict:
    """Step 3, a ``map_batches`` function: read, grade from each row's ``adapted`` and write each frame of ``batch``."""
    for path, output, adapted in zip(batch["path"], batch["output"], batch["adapted"]):
        image = _read(path, read_options)
        graded, _ = render_frame(look, image, torch.tensor([float(adapted)]), dt, scene_referred)
        write_frame(output, graded, depth)
    return {"output": batch["output"]}


def grade_shot_on_ray(look: PostFX, inputs, output: str, bit_depth: str | None = None, fps: float = 24.0,
                      scene_referred: bool = False, read_options: dict | None = None) -> list:
    """Grade the frames ``inputs`` names (as ``torchgrade grade`` reads them) on the running Ray cluster
    (``ray.init()`` first); the paths written, in frame order."""
    import ray.data

    depth = check_output(output, bit_depth, scene_referred)
    frames = shot_frames(inputs)
    outputs = output_paths(output, frames)
    read_options, dt = read_options or {}, 1.0 / fps
    rows = [{"index": i, "path": str(path), "output": str(out)} for i, (path, out) in enumerate(zip(frames, outputs))]
    adapted = [0.0] * len(rows)
    if look.exposure is not None:
        metered = ray.data.from_items(rows).map_batches(_meter_rows,  # type: ignore[arg-type]  # Ray's fn type leaves out fn_kwargs
                                                        fn_kwargs={"look": look, "read_options": read_options})
        by_index = sorted(metered.take_all(), key=lambda row: row["index"])
        adapted = adaptation_schedule(look, [row["metered"] for row in by_index], dt)
    shot = ray.data.from_items([{**row, "adapted": value} for row, value in zip(rows, adapted)])
    arguments = {"look": look, "read_options": read_options, "depth": depth, "dt": dt, "scene_referred": scene_referred}
    shot.map_batches(grade_rows, batch_size=1, fn_kwargs=arguments).materialize()  # type: ignore[arg-type]  # as above: fn_kwargs
    return [Path(out) for out in outputs]
