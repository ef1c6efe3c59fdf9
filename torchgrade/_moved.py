"""Import paths from before the packages were laid out as they are now, kept working for one release.

``import torchgrade.pipeline`` (and every module in :data:`MOVED`) still works and warns
(``DeprecationWarning``) with the new path; its names are looked up in the modules it became. Files saved with
``torch.save`` hold class paths, so the old paths of the classes a saved look is made of stay registered for
``torch.load(path, weights_only=True)`` (:data:`OLD_CLASS_PATHS`).

Examples:
    >>> import sys, warnings
    >>> _ = sys.modules.pop("torchgrade.pipeline", None)  # as in a process that has not imported it yet
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     from torchgrade.pipeline import PostFX
    >>> PostFX.__module__, caught[0].category.__name__
    ('torchgrade.look.postfx', 'DeprecationWarning')
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

__all__ = ["MOVED", "OLD_CLASS_PATHS", "install"]

MOVED = {
    "torchgrade.core": ("torchgrade.base.images", "torchgrade.base.params", "torchgrade.base.planes", "torchgrade.runtime.policy",
                        "torchgrade.runtime.recording"),
    "torchgrade.stage": ("torchgrade.base.stage",),
    "torchgrade.config": ("torchgrade.base.config",),
    "torchgrade.grade": ("torchgrade.grading.grade", "torchgrade.grading.layer", "torchgrade.grading.steps"),
    "torchgrade.grade_steps": ("torchgrade.grading.steps",),
    "torchgrade.primary": ("torchgrade.grading.primary", "torchgrade.grading.layer"),
    "torchgrade.curves": ("torchgrade.grading.curves",),
    "torchgrade.dither": ("torchgrade.output.dither", "torchgrade.output.layer"),
    "torchgrade.display": ("torchgrade.output.display", "torchgrade.output.layer"),
    "torchgrade.pipeline": ("torchgrade.look.postfx", "torchgrade.look.slots"),
    "torchgrade.augment_ranges": ("torchgrade.augment.ranges",),
    "torchgrade.augment_saved": ("torchgrade.augment.saved",),
    "torchgrade.distributed": ("torchgrade.integrations.ray",),
    "torchgrade.catalog": ("torchgrade.testing.catalog",),
    "torchgrade.lut.lut3d": ("torchgrade.lut.apply", "torchgrade.lut.layer"),
    "torchgrade.cli.shot": ("torchgrade.shots.frames",),
    "torchgrade.cli.outputs": ("torchgrade.shots.outputs",),
    "torchgrade.output.look": ("torchgrade.output.look_lut",),
    "torchgrade.tonemap.aces_rrt": ("torchgrade.tonemap.aces1.rrt",),
    "torchgrade.tonemap.aces_fits": ("torchgrade.tonemap.aces1.fits",),
    "torchgrade.tonemap.aces1_reference": ("torchgrade.tonemap.aces1.reference",),
    "torchgrade.tonemap.aces2_curves": ("torchgrade.tonemap.aces2.curves",),
    "torchgrade.base.core": ("torchgrade.base.images", "torchgrade.base.params", "torchgrade.base.planes", "torchgrade.runtime.policy",
                             "torchgrade.runtime.recording"),
}
"""Each old module path and the modules its names now live in, searched in order."""

OLD_CLASS_PATHS = {
    "torchgrade.pipeline.PostFX": "torchgrade.look.postfx.PostFX",
    "torchgrade.lut.lut3d.LUT3D": "torchgrade.lut.layer.LUT3D",
    "torchgrade.grade.ColorGrade": "torchgrade.grading.layer.ColorGrade",
    "torchgrade.primary.PrimaryGrade": "torchgrade.grading.layer.PrimaryGrade",
    "torchgrade.dither.Dither": "torchgrade.output.layer.Dither",
    "torchgrade.display.Display": "torchgrade.output.layer.Display",
}
"""Class paths files saved before the move hold, and the classes they name now."""


class _MovedModule(types.ModuleType):
    """An old module path: its names, looked up in the modules it became."""

    def __getattr__(self, name: str):
        for new in MOVED[self.__name__]:
            module = importlib.import_module(new)
            if hasattr(module, name):
                return getattr(module, name)
        raise AttributeError(f"module {self.__name__!r} (now {', '.join(MOVED[self.__name__])}) has no attribute {name!r}")


class _MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old module paths of :data:`MOVED` and makes each a :class:`_MovedModule`, with a warning."""

    def find_spec(self, fullname, path=None, target=None):
        return importlib.util.spec_from_loader(fullname, self) if fullname in MOVED else None

    def create_module(self, spec):
        return _MovedModule(spec.name)

    def exec_module(self, module) -> None:
        warnings.warn(f"{module.__name__} moved to {' and '.join(MOVED[module.__name__])}; the old path goes in the next release",
                      DeprecationWarning, stacklevel=2)


def install() -> None:
    """Put the finder of old paths on ``sys.meta_path`` (once)."""
    if not any(isinstance(finder, _MovedFinder) for finder in sys.meta_path):
        sys.meta_path.append(_MovedFinder())
