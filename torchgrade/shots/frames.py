"""A shot: the frames ``grade`` reads (files, folders, globs, ``name.%04d.exr`` patterns) in frame order,
where each one is written, and the per-frame function that grades them with the look's eye adaptation
carried from frame to frame.

Examples:
    >>> import tempfile, pathlib, torch
    >>> from torchgrade.io import write_exr
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> for number in (10, 9, 11):
    ...     write_exr(folder / f"plate.{number:04d}.exr", torch.full((3, 2, 2), 0.18))
    >>> [path.name for path in shot_frames([str(folder / "plate.%04d.exr")])]
    ['plate.0009.exr', 'plate.0010.exr', 'plate.0011.exr']
    >>> output_paths("out/graded.%04d.png", shot_frames([str(folder)]))[0]
    PosixPath('out/graded.0009.png')
"""

from __future__ import annotations

import glob
import re
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import torch
from tqdm import tqdm

from ..base.budget import MAX_FRAME_DIGITS
from ..look.postfx import PostFX

__all__ = ["shot_frames", "frame_number", "output_paths", "render_frame", "grade_shot"]

PRINTF_FRAME = re.compile(r"%(0?\d*)d")
"""A frame number in a file name, as ffmpeg, Nuke and OpenImageIO write it: ``%04d``, ``%d``; at most
:data:`~torchgrade.base.budget.MAX_FRAME_DIGITS` wide (:func:`frame_width`)."""


def frame_width(name: str) -> int:
    """The width a file name's frame pattern asks for (0 for ``%d``), or ``ValueError`` past
    :data:`~torchgrade.base.budget.MAX_FRAME_DIGITS` (``%0900000000d`` named a 900-million-character file).

    Examples:
        >>> frame_width("plate.%04d.exr"), frame_width("plate.%d.exr")
        (4, 0)
    """
    pattern = PRINTF_FRAME.search(name)
    if pattern is None:
        raise ValueError(f"{name}: no frame number pattern such as %04d")
    digits = pattern.group(1)
    width = int(digits) if digits.lstrip("0") else 0
    if len(digits) > 4 or width > MAX_FRAME_DIGITS:
        raise ValueError(f"{name}: a frame number of {digits[:12]} digits; at most {MAX_FRAME_DIGITS}")
    return width


def _frame_key(path: Path) -> tuple:
    """Frame order: the name without its trailing digits, then the number (so 9 before 10).

    Examples:
        >>> [p.name for p in sorted([Path("a.10.exr"), Path("a.9.exr"), Path("a.exr")], key=_frame_key)]
        ['a.exr', 'a.9.exr', 'a.10.exr']
    """
    match = re.search(r"(\d+)$", path.stem)
    return (path.stem[: match.start()] if match else path.stem, int(match.group(1)) if match else -1, path.name)


def _pattern_frames(path: Path) -> list:
    width = frame_width(path.name)
    digits = rf"\d{{{width}}}" if next(PRINTF_FRAME.finditer(path.name)).group(1).startswith("0") else r"\d+"
    parts = PRINTF_FRAME.split(path.name)
    name = re.compile("".join(re.escape(part) if i % 2 == 0 else digits for i, part in enumerate(parts)) + "$")
    folder = path.parent
    found = [child for child in folder.iterdir() if name.match(child.name)] if folder.is_dir() else []
    if not found:
        raise FileNotFoundError(f"no frames match {path}")
    return found


def _expand(text: str) -> list:
    path = Path(text)
    if PRINTF_FRAME.search(path.name):
        return sorted(_pattern_frames(path), key=_frame_key)
    if path.is_dir():  # hidden files left out: an interrupted write's temporary (".name.1a2b3c4d.exr") among them
        found = [child for child in path.iterdir()
                 if child.suffix.lower() == ".exr" and not child.name.startswith(".") and child.is_file()]
        if not found:
            raise FileNotFoundError(f"no EXR files in folder {path}")
        return sorted(found, key=_frame_key)
    if glob.has_magic(text):
        found = [Path(name) for name in glob.glob(text) if Path(name).is_file()]
        if not found:
            raise FileNotFoundError(f"no files match {text}")
        return sorted(found, key=_frame_key)
    if not path.is_file():
        raise FileNotFoundError(f"no such EXR file: {path}")
    return [path]


def shot_frames(inputs) -> list:
    """The EXR files ``inputs`` name, each folder, glob or ``%04d`` pattern in frame order, in the order given.

    Raises ``FileNotFoundError`` naming an input that names no file (a folder without EXR files says so).

    Examples:
        >>> shot_frames(["/nonexistent/plate.%04d.exr"])
        Traceback (most recent call last):
        ...
        FileNotFoundError: no frames match /nonexistent/plate.%04d.exr
    """
    return [frame for text in inputs for frame in _expand(text)]


def frame_number(path: Path, index: int) -> int:
    """The number a frame's output carries: its file name's trailing digits, else its place in the shot from 1.

    Examples:
        >>> frame_number(Path("plate.0042.exr"), 0), frame_number(Path("desk.exr"), 2)
        (42, 3)
    """
    match = re.search(r"(\d+)$", path.stem)
    return int(match.group(1)) if match else index + 1


def output_paths(output: str, frames: list) -> list:
    """Where each frame is written: ``output`` for a single frame, else ``output``'s ``%04d`` filled with its number.

    Examples:
        >>> output_paths("graded.%03d.png", [Path("plate.0007.exr"), Path("plate.0008.exr")])
        [PosixPath('graded.007.png'), PosixPath('graded.008.png')]
    """
    if not PRINTF_FRAME.search(Path(output).name):
        if len(frames) > 1:
            raise ValueError(f"{len(frames)} frames need an output pattern with a frame number, such as out.%04d.png; got {output}")
        return [Path(output)]
    folder, name = Path(output).parent, Path(output).name
    frame_width(name)
    pattern = next(PRINTF_FRAME.finditer(name)).group(0)  # the first, "%04d": filled as printf fills it
    paths = [folder / name.replace(pattern, pattern % frame_number(frame, i), 1) for i, frame in enumerate(frames)]
    if len(set(paths)) < len(paths):
        raise ValueError(f"two frames carry the same number, so would both write one file of {output}")
    return paths


def render_frame(look: PostFX, image: torch.Tensor, adapted, dt: float, scene_referred: bool = False) -> tuple:
    """Grade one ``(3, H, W)`` frame: ``(image, adapted, dt) -> (output, adapted)``, stateless like ``PostFX.frame``.

    ``adapted`` is the eye adaptation of the previous frame (None starts a shot). ``scene_referred`` stops
    before tone mapping: exposure, bloom, grade and primary grade only.

    Examples:
        >>> look = PostFX(exposure={"metering": "mean"}, tonemap="aces")
        >>> out, adapted = render_frame(look, torch.full((3, 2, 2), 0.36), None, 1 / 24)
        >>> out.shape, round(adapted.item(), 2)
        (torch.Size([3, 2, 2]), 0.36)
    """
    batch = image.unsqueeze(0)
    with torch.no_grad():
        if look.exposure is not None:
            batch, adapted = look.exposure.frame(batch, adapted, dt)
        if scene_referred:
            for stage in (look.bloom, look.grade, look.primary):
                batch = batch if stage is None else stage(batch)
        else:
            batch = look.finish(batch)
    return batch[0], adapted


def grade_shot(look: PostFX, frames: list, read, write, dt: float, scene_referred=False, jobs=1, progress=True) -> None:
    """Read, grade and write every frame with a progress bar (frames, fps, ETA).

    Eye adaptation runs in frame order, one frame after the other; a look without it may grade ``jobs``
    frames at a time. An exception (a frame's error, Ctrl-C) stops the shot: the frames being written finish, no
    other begins.

    Examples:
        >>> frames, written = ["f1", "f2"], {}
        >>> grade_shot(PostFX(tonemap="aces"), frames, lambda name: torch.full((3, 1, 1), 0.18),
        ...            lambda index, image: written.update({frames[index]: image}), dt=1 / 24, progress=False)
        >>> sorted(written), tuple(written["f2"].shape)
        (['f1', 'f2'], (3, 1, 1))
    """
    if jobs > 1 and look.exposure is not None:
        raise ValueError("--jobs needs a look without eye adaptation: exposure carries from each frame to the next")
    bar = tqdm(total=len(frames), unit="frame", disable=not progress, dynamic_ncols=True)

    def one(index, adapted=None):
        output, adapted = render_frame(look, read(frames[index]), adapted, dt, scene_referred)
        write(index, output)
        bar.update()
        return adapted

    with bar:
        if jobs > 1:
            with ThreadPoolExecutor(jobs) as pool:
                try:
                    list(pool.map(one, range(len(frames))))
                except BaseException:  # Ctrl-C or a frame's error: the frames not begun are not graded
                    pool.shutdown(cancel_futures=True)
                    raise
        else:
            adapted = None
            for index in range(len(frames)):
                adapted = one(index, adapted)
