"""The CPU lookup, the operator ``torchgrade::lut_lookup``, against the torch form that runs off the CPU and under
``torch.func`` (:func:`~torchgrade.lut.apply.lookup`, the gather form), in both of the operator's CPU kernels (the C
loop built with the package, and its torch form where the package was built without a compiler): the same values to
float rounding over shapers, domains, output encodings and clamps, dtypes, lattice sizes and non-finite or huge
inputs, its torch form bit for bit; the whole-frame form off the CPU against the gather form."""

import dataclasses
import warnings

import pytest
import torch

from torchgrade.lut import KERNELS, LUT3D, identity_table, lattice, layer, operator
from torchgrade.lut.apply import lookup
from torchgrade.lut.lattice import planar_table

MAX_SIZE = KERNELS["tetrahedral"].eager.max_size


@pytest.fixture(params=["native", "torch"])
def cpu_form(request, monkeypatch):
    """Each CPU kernel of the operator in turn: the C loop (which the package's build must have made here: CI builds
    it with the C compiler ``torch.compile`` needs) or, with the extension taken away, the torch form (its warning
    silenced)."""
    if request.param == "native":
        assert operator.NATIVE is not None, "torchgrade.lut._lookup was not built: see setup.py"
        yield request.param
        return
    monkeypatch.setattr(operator, "NATIVE", None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield request.param


def coordinate_rounding(size: int, dtype: torch.dtype, table_step: float) -> float:
    """The output error one rounding of a lattice coordinate can make: the C loop forms ``(x - low) * ((S - 1) /
    span)`` where the gather form divides, so a coordinate may differ by an ulp of ``S - 1``, which moves the output by
    that much times the table's largest step between neighbours."""
    return torch.finfo(dtype).eps * (size - 1) * table_step


def hostile_image(dtype=torch.float32) -> torch.Tensor:
    """Random pixels inside and outside [0, 1], plus NaN, ±Inf, huge, negative zero and exact lattice coordinates."""
    image = (torch.rand(2, 3, 23, 31, dtype=torch.float64) * 1.6 - 0.3).to(dtype)
    specials = [float("nan"), float("inf"), -float("inf"), 1e30, -1e30, 7e4, 65504.0, -0.0, 0.0, 1.0, 0.5]
    if dtype == torch.float16:
        specials = [v for v in specials if abs(v) <= 65504 or v != v or abs(v) == float("inf")]
    for k, value in enumerate(specials):
        image[0, k % 3, 1, k] = value
        image[1, :, 2, k] = value
    for row, (a, b) in enumerate(((0, 1), (1, 2), (0, 2)), start=5):  # ties between two fractions
        image[1, b, row] = image[1, a, row]
    return image


def curve_settings():
    ramp = torch.linspace(0.0, 1.0, 9).unsqueeze(1).repeat(1, 3) ** torch.tensor([1.0, 0.5, 2.0])
    return {"curve": ramp, "curve_range": (-0.1, 2.0)}


SHAPED = [
    ("linear", None, {}),
    ("linear", (-0.25, (1.0, 2.0, 4.0)), {}),  # per-channel domain: shifted and scaled
    ("linear", (0.0, 1e6), {}),  # a domain past the half-float range: sanitize's clamp matters
    ("logc", None, {}),
    ("logc_hdr", None, {}),
    ("curve", None, curve_settings()),
]


@pytest.mark.parametrize("shaper, domain, extra", SHAPED)
@pytest.mark.parametrize("encoding, output_range", [("linear", None), ("srgb", None), ("linear", (0.0, 0.9))])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64, torch.float16])
@pytest.mark.parametrize("interpolation", ["tetrahedral", "trilinear"])
def test_eager_lookup_matches_the_gather_form(shaper, domain, extra, encoding, output_range, dtype, interpolation, cpu_form):
    size = 9
    table = torch.rand(size, size, size, 3, dtype=torch.float64) * 3 - 1
    lut = LUT3D(table.to(torch.float64 if dtype == torch.float64 else torch.float32), shaper=shaper, domain=domain,
                output_range=output_range, output_encoding=encoding, **extra)
    image = hostile_image(dtype)
    with torch.no_grad():
        eager = lut(image, interpolation)
        one_pass = lookup(image, lut.rows(lut.table.dtype), size, lut.shaper, lut.domain_min, lut.domain_max, interpolation,
                          lut.output_range, lut.curve, lut.curve_range, lut.output_encoding)
    assert eager.dtype == one_pass.dtype == dtype and torch.isfinite(eager).all()
    # a few roundings of values up to 2, and the C loop's coordinate rounding (entries in [-1, 2]: steps up
    # to 3); sRGB decoding has slope up to ~2.4 over these entries
    work = torch.float32 if dtype == torch.float16 else dtype
    eps = torch.finfo(work).eps
    if cpu_form == "torch":  # the same operations as the torch form
        assert torch.equal(eager, one_pass)
        return
    atol = max(2.4 * (8 * 2 * eps + coordinate_rounding(size, work, 3.0)), torch.finfo(dtype).eps * 2 if dtype == torch.float16 else 0.0)
    torch.testing.assert_close(eager, one_pass, atol=atol, rtol=0)


@pytest.mark.parametrize("size", [2, 3, 33, MAX_SIZE])
def test_tetrahedral_is_exact_on_lattice_points_and_close_to_the_gather_form_at_every_size(size, cpu_form):
    points = lattice(size, torch.float32).reshape(1, -1, 1, 3).permute(0, 3, 1, 2)
    assert torch.equal(LUT3D(identity_table(size))(points), points)
    table = torch.rand(size, size, size, 3) * 2 - 1
    rows = planar_table(table)
    image = hostile_image()
    image[..., :4, :] = 1.0  # the top face of the lattice, where the corner is not clamped to S - 2
    image[0, 1, :4, :] = torch.rand(4, image.shape[-1])
    settings = (size, "linear", 0.0, 1.0, "tetrahedral", None, None, (0.0, 1.0), "linear")
    with torch.no_grad():
        got, expected = LUT3D(table)(image), lookup(image, rows, *settings)
    if cpu_form == "torch":
        assert torch.equal(got, expected)
    else:
        torch.testing.assert_close(got, expected, atol=8 * 2.0 ** -24 + coordinate_rounding(size, torch.float32, 2.0), rtol=0)
    assert torch.equal(LUT3D(table)(points), planar_table(table).t().reshape(1, -1, 1, 3).permute(0, 3, 1, 2))


def test_a_constant_table_gives_its_constant_exactly(cpu_form):
    lut = LUT3D(torch.full((5, 5, 5, 3), 0.3))
    with torch.no_grad():
        assert torch.equal(lut(hostile_image()), torch.full((2, 3, 23, 31), 0.3))


@pytest.mark.parametrize("requires_grad", ["image", "table"])
def test_the_autograd_path_and_the_eager_path_give_the_same_values(requires_grad, cpu_form):
    table = torch.rand(9, 9, 9, 3)
    lut = LUT3D(table.clone(), learnable=requires_grad == "table")
    image = hostile_image().requires_grad_(requires_grad == "image")
    with_grad = lut(image)
    assert with_grad.requires_grad
    with torch.no_grad():
        eager = lut(image)
    torch.testing.assert_close(with_grad.detach(), eager, atol=4 * 2.0 ** -24, rtol=0)
    with_grad.sum().backward()  # the gradient still flows
    assert (image.grad if requires_grad == "image" else lut.table.grad) is not None


def test_whole_frame_tables_are_cached_and_follow_the_table(monkeypatch):
    """Off the CPU (the CPU taken for another device) the whole-frame form's tables are derived once per table."""
    monkeypatch.setattr(layer, "runs_operator", lambda image, table: False)
    lut = LUT3D(torch.rand(5, 5, 5, 3))
    image = torch.rand(1, 3, 6, 7)
    before = lut(image)
    tables = lut._tables_cache[2]
    lut(image)
    assert lut._tables_cache[2] is tables  # one derivation per table
    with torch.no_grad():
        lut.table.mul_(0.5)
    torch.testing.assert_close(lut(image), 0.5 * before, atol=1e-7, rtol=0)
    assert lut._tables_cache[2] is not tables


def test_strided_and_channels_last_images_give_the_contiguous_result_bit_for_bit(cpu_form):
    lut = LUT3D(torch.rand(9, 9, 9, 3))
    image = hostile_image()
    with torch.no_grad():
        expected = lut(image)
        assert torch.equal(lut(image.to(memory_format=torch.channels_last)), expected)
        wide = torch.zeros(2, 3, 23, 62)
        wide[..., ::2] = image
        assert torch.equal(lut(wide[..., ::2]), expected)


def hostile_coordinates(size: int) -> torch.Tensor:
    """Lattice coordinates ``(3, P)``: random, on lattice points, on the top faces, and with ties between fractions."""
    coords = torch.rand(3, 4000, dtype=torch.float64) * (size - 1)
    coords[:, :500] = coords[:, :500].round()
    for k, (a, b) in enumerate(((0, 1), (1, 2), (0, 2)), start=1):
        coords[b, 500 * k:500 * (k + 1)] = coords[a, 500 * k:500 * (k + 1)]
    coords[:, 2000:2500] = coords[:, 2000:2500].clamp_min(size - 1.5)
    coords[torch.rand(3, 4000) < 0.1] = size - 1
    return coords.float()


@pytest.mark.parametrize("size", [2, 3, 33, MAX_SIZE])
def test_the_whole_frame_form_matches_the_gather_form(size):
    table = torch.rand(size, size, size, 3) * 2 - 1
    rows = planar_table(table)
    kernel, coords = KERNELS["tetrahedral"], hostile_coordinates(size)
    tables = kernel.eager.tables(rows, size)
    expected = kernel(coords.double(), rows.double(), size)  # the gather form in float64
    torch.testing.assert_close(kernel.eager.frame(coords, tables, size).double(), expected, atol=4 * 2.0 ** -24 * 2, rtol=0)
    on_points = coords.round()
    assert torch.equal(kernel.eager.frame(on_points, tables, size), kernel(on_points, rows, size))


@pytest.mark.parametrize("shaper, domain, extra", SHAPED)
def test_off_the_cpu_a_frame_goes_through_the_whole_frame_form(shaper, domain, extra, monkeypatch):
    """The CPU taken for another device: LUT3D's eager no-grad lookup takes the whole-frame form, with the gather form's values."""
    lut = LUT3D(torch.rand(9, 9, 9, 3) * 3 - 1, shaper=shaper, domain=domain, **extra)
    image = hostile_image()
    with torch.no_grad():
        gather = lookup(image, lut.rows(torch.float32), 9, lut.shaper, lut.domain_min, lut.domain_max, "tetrahedral",
                        lut.output_range, lut.curve, lut.curve_range, lut.output_encoding)
        monkeypatch.setattr(layer, "runs_operator", lambda image, table: False)
        frames, kernel = [], KERNELS["tetrahedral"]
        recorded = dataclasses.replace(kernel.eager, frame=_recorded(kernel.eager.frame, frames))
        monkeypatch.setitem(KERNELS, "tetrahedral", dataclasses.replace(kernel, eager=recorded))
        got = lut(image)
    assert len(frames) == 1
    torch.testing.assert_close(got, gather, atol=8 * 3 * 2.0 ** -24, rtol=0)


def _recorded(function, calls: list):
    def call(*arguments):
        calls.append(arguments)
        return function(*arguments)
    return call
