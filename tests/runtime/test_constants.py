"""Constants kept on the device (:mod:`torchgrade.runtime.constants`): what a caller is handed and changes in place
changes no later result."""

import math

import torch

import torchgrade as tg
from torchgrade.color import MATRICES
from torchgrade.base.params import color_param, scalar_param


def test_changing_a_colour_matrix_in_place_leaves_later_conversions_alone():
    image = torch.ones(1, 3, 1, 1, dtype=torch.float64)
    expected = (MATRICES["srgb_to_ap1"] @ torch.ones(3, dtype=torch.float64)).reshape(1, 3, 1, 1)
    tg.color.matrix("srgb_to_ap1", image).mul_(2.0)
    torch.testing.assert_close(tg.color.convert(image, "srgb_to_ap1"), expected)
    torch.testing.assert_close(tg.color.matrix("srgb_to_ap1", image), MATRICES["srgb_to_ap1"])


def test_changing_a_broadcast_control_in_place_leaves_later_grades_alone():
    image = torch.ones(1, 3, 2, 2)
    scalar_param(0.5, image, "post_exposure").fill_(3.0)
    color_param((1.0, 0.5, 0.25), image, "color_filter").zero_()
    torch.testing.assert_close(tg.functional.post_exposure(image, 0.5), image * math.sqrt(2.0))
    assert color_param((1.0, 0.5, 0.25), image, "color_filter").flatten().tolist() == [1.0, 0.5, 0.25]
