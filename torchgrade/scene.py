"""A procedural HDR test scene, made by the package itself so the demo needs no data files.

A dim room lit by one ceiling lamp (radiance 200) with inverse-square falloff: a plastered back wall
carrying a colour chart of saturated patches, a wooden floor, emissive objects around 8 (a neon
tube, a glowing orb, a lamp shade) and a few single-pixel specular glints of 1000. Values are
scene-referred linear Rec.709. (The images every stage must survive: :mod:`torchgrade.testing.extremes`.)
"""

from __future__ import annotations

import torch

from .base.budget import check_pixels
from .color import srgb_to_linear

__all__ = ["CHART_SRGB", "demo_scene"]

# sRGB values of the ColorChecker Classic patches (X-Rite, 2009 formulation), row by row.
CHART_SRGB = (
    (115, 82, 68), (194, 150, 130), (98, 122, 157), (87, 108, 67), (133, 128, 177), (103, 189, 170),
    (214, 126, 44), (80, 91, 166), (193, 90, 99), (94, 60, 108), (157, 188, 64), (224, 163, 46),
    (56, 61, 150), (70, 148, 73), (175, 54, 60), (231, 199, 31), (187, 86, 149), (8, 133, 161),
    (243, 243, 242), (200, 200, 200), (160, 160, 160), (122, 122, 121), (85, 85, 85), (52, 52, 52),
)


def _rgb(values, like: torch.Tensor) -> torch.Tensor:
    return torch.tensor(values, dtype=like.dtype, device=like.device).reshape(3, 1, 1)


def _disc(u: torch.Tensor, v: torch.Tensor, cu: float, cv: float, radius: float) -> torch.Tensor:
    return (((u - cu) ** 2 + (v - cv) ** 2) <= radius**2).to(u.dtype)


def _box(u: torch.Tensor, v: torch.Tensor, u0: float, v0: float, u1: float, v1: float) -> torch.Tensor:
    return ((u >= u0) & (u < u1) & (v >= v0) & (v < v1)).to(u.dtype)


def _lamp_irradiance(u: torch.Tensor, v: torch.Tensor, lamp_u: float, lamp_v: float, height: float) -> torch.Tensor:
    """Irradiance from a point lamp at distance ``height`` from the surface plane: ``h / d³`` (cosine law)."""
    distance_sq = (u - lamp_u) ** 2 + (v - lamp_v) ** 2 + height**2
    return height / distance_sq**1.5


def _chart(u: torch.Tensor, v: torch.Tensor, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Albedo of the colour chart (6×4 patches with dark gaps) and its mask."""
    u0, v0, patch, gap = 0.52, 0.26, 0.055, 0.008
    albedo = torch.zeros((3,) + u.shape, dtype=like.dtype, device=like.device)
    mask = torch.zeros_like(u)
    for index, srgb in enumerate(CHART_SRGB):
        row, col = divmod(index, 6)
        pu, pv = u0 + col * (patch + gap), v0 + row * (patch + gap)
        inside = _box(u, v, pu, pv, pu + patch, pv + patch)
        albedo = albedo + inside * srgb_to_linear(_rgb(srgb, like) / 255.0)
        mask = torch.maximum(mask, inside)
    frame = _box(u, v, u0 - gap, v0 - gap, u0 + 6 * (patch + gap), v0 + 4 * (patch + gap))
    return albedo, torch.maximum(mask, frame)


def demo_scene(height: int = 360, width: int = 640, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """Render the demo room as a ``(1, 3, height, width)`` scene-referred linear Rec.709 tensor.

    Examples:
        >>> scene = demo_scene(16, 24)
        >>> scene.shape, bool(scene.max() > 1.0)  # scene-referred: brighter than white
        (torch.Size([1, 3, 16, 24]), True)
    """
    if height < 8 or width < 8:
        raise ValueError(f"demo scene needs at least 8x8 pixels, got {height}x{width}")
    check_pixels(height, width, "the demo scene")
    like = torch.empty(0, dtype=dtype)
    v, u = torch.meshgrid(
        (torch.arange(height, dtype=dtype) + 0.5) / height,
        (torch.arange(width, dtype=dtype) + 0.5) / width * (width / height),
        indexing="ij",
    )
    aspect = width / height
    lamp_u = 0.42 * aspect
    floor = (v > 0.72).to(dtype)

    lamp_v = 0.16
    wall_light = 0.12 * _lamp_irradiance(u, v, lamp_u, lamp_v, 0.3) + 0.01
    floor_light = 0.5 * _lamp_irradiance(u, (v - 0.72) * 4.0, lamp_u, -0.3, 0.45) + 0.01
    plaster = _rgb((0.62, 0.55, 0.47), like) * (1.0 + 0.03 * torch.sin(u * 91.0) * torch.sin(v * 67.0))
    board = torch.floor(u * 9.0 / (0.2 + v))
    board_tint = 0.8 + 0.2 * torch.frac(torch.sin(board * 12.9898) * 43758.5453)
    grain = 0.9 + 0.1 * torch.sin(v * 300.0 + 4.0 * torch.sin(u * 23.0 + board))
    wood = _rgb((0.30, 0.17, 0.08), like) * board_tint * grain
    image = (1.0 - floor) * plaster * wall_light + floor * wood * floor_light

    chart_albedo, chart_mask = _chart(u, v, like)
    image = torch.where(chart_mask.bool(), chart_albedo * wall_light * 0.9, image)

    cord = _box(u, v, lamp_u - 0.002, 0.0, lamp_u + 0.002, lamp_v - 0.05)
    image = image * (1.0 - cord)
    shade = _box(u, v, lamp_u - 0.07, lamp_v - 0.05, lamp_u + 0.07, lamp_v)
    image = torch.where(shade.bool(), _rgb((8.0, 5.2, 2.4), like) * (0.6 + 0.4 * (v - lamp_v + 0.05) / 0.05), image)
    bulb = _disc(u, v, lamp_u, lamp_v + 0.008, 0.014)
    image = torch.where(bulb.bool(), _rgb((200.0, 190.0, 170.0), like), image)

    neon = _box(u, v, 0.10 * aspect, 0.30, 0.10 * aspect + 0.012, 0.62)
    image = torch.where(neon.bool(), _rgb((8.0, 0.6, 6.5), like), image)
    orb_u, orb_v, orb_r = 0.30 * aspect, 0.66, 0.05
    orb = _disc(u, v, orb_u, orb_v, orb_r)
    orb_falloff = (1.0 - ((u - orb_u) ** 2 + (v - orb_v) ** 2) / orb_r**2).clamp_min(0.0)
    image = torch.where(orb.bool(), _rgb((0.5, 5.0, 8.0), like) * (0.4 + 0.6 * orb_falloff), image)

    glints = ((0.74, 0.80), (0.79, 0.83), (0.83, 0.79), (0.37, 0.88))
    for gu, gv in glints:
        row, col = min(int(gv * height), height - 1), min(int(gu * width), width - 1)
        image[:, row, col] = 1000.0
    return image.unsqueeze(0)

