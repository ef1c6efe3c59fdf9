"""The module paths from before the packages' layout keep working for a release, each import warning with its new path,
and looks saved with the old class paths load with ``weights_only=True``."""

import importlib
import io
import sys
import warnings

import pytest
import torch

import torchgrade as tg
from torchgrade._moved import MOVED, OLD_CLASS_PATHS

# a name each old module had, and the object it must still give
OLD_NAMES = {
    "torchgrade.core": "check_image", "torchgrade.stage": "Stage", "torchgrade.config": "load_config",
    "torchgrade.grade": "ColorGrade", "torchgrade.grade_steps": "white_balance", "torchgrade.primary": "PrimaryGrade",
    "torchgrade.curves": "evaluate_curve", "torchgrade.dither": "Dither", "torchgrade.display": "encode_display",
    "torchgrade.pipeline": "PostFX", "torchgrade.augment_ranges": "checked_range", "torchgrade.augment_saved": "SAVED_NAME",
    "torchgrade.distributed": "grade_shot_on_ray", "torchgrade.catalog": "STAGE_KINDS", "torchgrade.lut.lut3d": "LUT3D",
    "torchgrade.cli.shot": "render_frame", "torchgrade.cli.outputs": "write_frame",
    "torchgrade.tonemap.aces_rrt": "smoothstep_hue_weight", "torchgrade.tonemap.aces_fits": "aces_hill",
    "torchgrade.tonemap.aces1_reference": "aces_reference", "torchgrade.tonemap.aces2_curves": "aces2_sdr",
    "torchgrade.base.core": "apply_matrix", "torchgrade.output.look": "look_lut",
}


def test_every_moved_module_is_checked():
    assert set(OLD_NAMES) == set(MOVED)


@pytest.mark.parametrize("old", sorted(OLD_NAMES))
def test_an_old_path_imports_with_a_warning_naming_the_new_one(old):
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=MOVED[old][0].replace(".", r"\.")):
        module = importlib.import_module(old)
    name = OLD_NAMES[old]
    new = next(importlib.import_module(m) for m in MOVED[old] if hasattr(importlib.import_module(m), name))
    assert getattr(module, name) is getattr(new, name)
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        _ = module.no_such_name


def test_old_attribute_paths_of_the_package_and_functional_warn():
    with pytest.warns(DeprecationWarning):
        assert tg.functional.log_contrast is tg.functional.primary_log_contrast
    with pytest.warns(DeprecationWarning):
        from torchgrade.scene import extreme_inputs  # noqa: F401


def test_a_look_saved_with_the_old_class_paths_loads_with_weights_only(monkeypatch):
    look = tg.PostFX(grade={"contrast": 20}, tonemap="aces", dither={"seed": 3})
    classes = {path: type(stage) for path, stage in [("torchgrade.pipeline.PostFX", look), ("torchgrade.grade.ColorGrade", look.grade),
                                                      ("torchgrade.dither.Dither", look.dither)]}
    for old, cls in classes.items():
        assert OLD_CLASS_PATHS[old] == f"{cls.__module__}.{cls.__qualname__}"
        monkeypatch.setattr(cls, "__module__", old.rpartition(".")[0])  # as the file was written before the move
    saved = io.BytesIO()
    torch.save(look, saved)
    monkeypatch.undo()
    assert b"torchgrade.pipeline" in saved.getvalue()
    saved.seek(0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        loaded = torch.load(saved, weights_only=True)
    image = torch.rand(1, 3, 8, 8) * 4
    with torch.no_grad():
        assert torch.equal(loaded(image), look(image))
