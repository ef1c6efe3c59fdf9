"""One name per thing: the module paths, attribute names and export backend name from before the packages' layout are
gone, with no import hook or re-export keeping them, and the package installs nothing on ``sys.meta_path``."""

import importlib
import io
import sys
import types

import pytest
import torch

import torchgrade as tg

OLD_MODULES = ("torchgrade.core", "torchgrade.stage", "torchgrade.config", "torchgrade.grade", "torchgrade.grade_steps",
               "torchgrade.primary", "torchgrade.curves", "torchgrade.dither", "torchgrade.display", "torchgrade.pipeline",
               "torchgrade.augment_ranges", "torchgrade.augment_saved", "torchgrade.distributed", "torchgrade.catalog",
               "torchgrade.lut.lut3d", "torchgrade.cli.shot", "torchgrade.cli.outputs", "torchgrade.output.look",
               "torchgrade.tonemap.aces_rrt", "torchgrade.tonemap.aces_fits", "torchgrade.tonemap.aces1_reference",
               "torchgrade.tonemap.aces2_curves", "torchgrade.base.core", "torchgrade._moved")
"""The module paths of the layout before this one."""

OLD_ATTRIBUTES = {"torchgrade.functional": "log_contrast", "torchgrade.scene": "extreme_inputs",
                  "torchgrade.bloom.pyramid": "mirror_pad", "torchgrade.base.stage": "Control",
                  "torchgrade.augment.layer": "SRGB_TOLERANCE", "torchgrade.lut.kernels": "trilinear_strip_lookup"}
"""Names that modules kept for their former path or name, each now in one place only."""


@pytest.mark.parametrize("old", OLD_MODULES)
def test_an_old_module_path_is_not_importable(old):
    sys.modules.pop(old, None)
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)


@pytest.mark.parametrize("module, name", sorted(OLD_ATTRIBUTES.items()))
def test_an_old_name_is_gone(module, name):
    assert not hasattr(importlib.import_module(module), name)


def test_the_package_puts_no_finder_on_the_import_path():
    assert [finder for finder in sys.meta_path if type(finder).__module__.startswith("torchgrade")] == []


def test_the_former_lut_backend_name_is_refused():
    with pytest.raises(ValueError, match="lut_backend must be one of 'slices', 'gather', 'volume', got 'strip'"):
        tg.LUT3D(tg.lut.identity_table(3)).export_form("trilinear", "strip")


def test_a_look_saved_under_an_old_class_path_is_refused_by_weights_only(monkeypatch):
    look = tg.PostFX(grade={"contrast": 20})
    old = types.ModuleType("torchgrade.pipeline")  # the class path a file saved before the layout holds
    old.PostFX = tg.PostFX
    monkeypatch.setitem(sys.modules, old.__name__, old)
    monkeypatch.setattr(tg.PostFX, "__module__", old.__name__)
    saved = io.BytesIO()
    torch.save(look, saved)
    monkeypatch.undo()
    saved.seek(0)
    with pytest.raises(Exception, match="torchgrade.pipeline.PostFX"):
        torch.load(saved, weights_only=True)
