"""Constants kept on the device (:mod:`torchgrade.runtime.constants`): a public function hands out a copy, which a
caller may change in place without changing a later result."""

import torch

import torchgrade as tg
from torchgrade.color import MATRICES


def test_changing_a_colour_matrix_in_place_leaves_later_conversions_alone():
    image = torch.ones(1, 3, 1, 1, dtype=torch.float64)
    expected = (MATRICES["srgb_to_ap1"] @ torch.ones(3, dtype=torch.float64)).reshape(1, 3, 1, 1)
    tg.color.matrix("srgb_to_ap1", image).mul_(2.0)
    torch.testing.assert_close(tg.color.convert(image, "srgb_to_ap1"), expected)
    torch.testing.assert_close(tg.color.matrix("srgb_to_ap1", image), MATRICES["srgb_to_ap1"])
