"""Test images and the pixel-list form the references work on (float64 numpy rows of RGB)."""

import numpy as np
import torch

LUM709 = np.array([0.2126729, 0.7151522, 0.0721750])
"""Rec.709 luminance weights, as Unity's ``Luminance`` and colour-science state them."""

EXTREMES = [0.0, 1e-8, 0.18, 1.0, 60.0, 65504.0, 1e30]


def pixels(values, dtype=torch.float64, device=None):
    """A (1, 3, 1, N) image whose N pixels are the rows of ``values`` (N x 3)."""
    return torch.as_tensor(np.asarray(values, dtype=np.float64), dtype=dtype, device=device).T.reshape(1, 3, 1, -1)


def rows(image):
    return image.reshape(3, -1).T.detach().cpu().double().numpy()


def random_rgb(n=300, high=4.0, seed=1):
    return np.random.default_rng(seed).uniform(0.0, high, size=(n, 3))
