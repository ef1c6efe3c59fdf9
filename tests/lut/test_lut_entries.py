"""Fitted LUT entries (torchgrade.lut.entries, ``bake_lut(entries="fitted")``): the objective against the displayed
error, the optimum against a linear program (SciPy's HiGHS), and what the fit buys on real images."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from torchgrade.color import linear_to_srgb
from torchgrade.lut import KERNELS, bake_lut, code_errors, fit_entries, validation_colours
from torchgrade.lut.apply import decode_output
from torchgrade.lut.entries import display_miss, fitting_colours
from torchgrade.lut.entries import _inside_lattice, _lattice_coords

STRONG_LOOK = dict(contrast=30.0, saturation=20.0, temperature=20.0)


def quiet_bake(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return bake_lut(*args, report_tolerance=float("inf"), **kwargs)


def strong_look():
    from torchgrade import ColorGrade, ToneMap

    return torch.nn.Sequential(ColorGrade(**STRONG_LOOK), ToneMap("aces"))


def test_entries_must_be_sampled_or_fitted_and_are_checked_before_the_transform_runs():
    def transform(image):
        raise AssertionError("evaluated")

    with pytest.raises(ValueError, match="entries"):
        bake_lut(transform, size=5, entries="optimal")


def test_the_objective_is_the_displayed_error_of_an_srgb_table_inside_the_display_range():
    generator = torch.Generator().manual_seed(0)
    reference = torch.rand(3, 1000, dtype=torch.float64, generator=generator) * 0.98 + 0.01
    values = torch.rand(3, 1000, dtype=torch.float64, generator=generator)
    target = linear_to_srgb(reference)
    no = torch.zeros_like(values, dtype=torch.bool)
    displayed = code_errors(reference, decode_output(values, "srgb"))
    assert torch.allclose(display_miss(values, target, torch.full_like(values, 255.0), no, no), displayed, atol=1e-9)


def test_a_lookup_past_the_clip_costs_nothing_and_one_short_of_it_does():
    target = torch.tensor([0.0, 1.0], dtype=torch.float64)
    slope = torch.full((2,), 255.0, dtype=torch.float64)
    below, above = torch.tensor([True, False]), torch.tensor([False, True])
    assert display_miss(torch.tensor([-0.3, 1.4], dtype=torch.float64), target, slope, below, above).tolist() == [0.0, 0.0]
    short = display_miss(torch.tensor([0.1, 0.9], dtype=torch.float64), target, slope, below, above)
    assert torch.allclose(short, torch.tensor([25.5, 25.5], dtype=torch.float64))


def test_a_table_the_lookup_reproduces_exactly_is_left_as_it_is():
    matrix = torch.tensor([[0.6, 0.3, 0.1], [0.2, 0.7, 0.1], [0.1, 0.2, 0.7]], dtype=torch.float64)

    def affine(image):  # interpolation of an affine map is exact, so the sampled table is already optimal
        return torch.einsum("ij,njhw->nihw", matrix.to(image.dtype), image) * 0.5 + 0.1

    lut = quiet_bake(affine, size=5, shaper="linear")
    fitted = fit_entries(lut, affine, hdr=False)
    assert torch.allclose(fitted.table, lut.table, atol=1e-6)


def test_the_fit_reaches_the_linear_programs_smallest_max_error():
    """Anchors off, so the fit's target is the pure max: HiGHS solves the same problem exactly, per channel."""
    from scipy.optimize import linprog
    from scipy.sparse import csr_matrix, hstack, vstack

    look = strong_look()
    size = 5
    lut = quiet_bake(look, size=size, shaper="linear", output_encoding="srgb")
    fitted = fit_entries(lut, look, hdr=False, anchor_weight=0.0)
    points, reference, _ = fitting_colours(lut, look, None, hdr=False)
    coords = _lattice_coords(lut, points)
    basis = torch.eye(size**3, dtype=torch.float64)
    columns = [KERNELS["tetrahedral"](coords, basis[j].expand(3, -1), size)[0] for j in range(size**3)]
    lookup = csr_matrix(torch.stack(columns, dim=1).numpy())  # (P, S³): value = lookup @ entries
    codes = (255.0 * linear_to_srgb(reference.clamp(0.0, 1.0))).numpy()
    optimum = 0.0
    for code in codes:  # variables: entries (S³), then t; minimise t
        inside, black, white = (code > 0) & (code < 255), code <= 0, code >= 255
        t_column = csr_matrix(-np.ones((lookup.shape[0], 1)))
        rows = [hstack([255.0 * lookup[inside], t_column[inside]]), hstack([-255.0 * lookup[inside], t_column[inside]]),
                hstack([255.0 * lookup[black], t_column[black]]), hstack([-255.0 * lookup[white], t_column[white]])]
        limits = np.concatenate([code[inside], -code[inside], code[black], -code[white]])
        cost = np.zeros(size**3 + 1)
        cost[-1] = 1.0
        result = linprog(cost, A_ub=vstack(rows).tocsr(), b_ub=limits, bounds=[(-1.0, 2.0)] * size**3 + [(0.0, None)],
                         method="highs")
        assert result.status == 0, result.message
        optimum = max(optimum, result.x[-1])
    with torch.no_grad():
        reached = float(code_errors(reference, fitted(points.reshape(1, 3, 1, -1).float()).double().reshape(3, -1)).max())
        sampled = float(code_errors(reference, lut(points.reshape(1, 3, 1, -1).float()).double().reshape(3, -1)).max())
    assert optimum < sampled
    assert reached <= 1.05 * optimum + 0.05, (reached, optimum, sampled)


def test_fitted_entries_miss_colours_the_fit_did_not_see_by_less():
    """The error report is measured on colours the fit did not see (realistic ones): at p99.9 it falls; the
    largest error within the lattice falls too (outside it, the face's entries serve colours clamped onto them)."""
    look = strong_look()
    sampled, fitted = (quiet_bake(look, size=17, entries=entries) for entries in ("sampled", "fitted"))
    assert fitted.error_report.p99_9 < 0.9 * sampled.error_report.p99_9
    colours = validation_colours()
    colours = colours[:, _inside_lattice(sampled, colours)].reshape(1, 3, 1, -1)  # outside, the lattice's face decides
    with torch.no_grad():
        reference = look(colours)
        inside_max = [float(code_errors(reference, lut(colours.float())).max()) for lut in (sampled, fitted)]
    assert inside_max[1] < inside_max[0], inside_max


def test_fitted_entries_bake_inside_no_grad():
    """The fit needs gradients (a scene-fitted shaper's rounds fit entries too); a caller's ``torch.no_grad()`` must
    not break it or change what it finds."""
    look = strong_look()
    scene = torch.rand(1, 3, 8, 8, generator=torch.Generator().manual_seed(0)) * 4
    outside = quiet_bake(look, size=5, shaper="logc", scene=scene, entries="fitted")
    with torch.no_grad():
        inside = quiet_bake(look, size=5, shaper="logc", scene=scene, entries="fitted")
    assert torch.equal(inside.table, outside.table)
