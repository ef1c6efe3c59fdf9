"""Every sample image through the shipped look, judged by one stated rule (``benchmarks/exposure_samples.py``):
no frame washed out (its darkest twentieth above one stop over the look's middle grey) or crushed (its brightest
twentieth below one stop under it). A new sample image or a new default is judged the same way."""

import json
import sys
from pathlib import Path

import pytest
import torch

import torchgrade as tg

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from benchmarks.exposure_samples import (LOOK, display_statistics, middle_grey_display, read_sample, sample_paths,  # noqa: E402
                                         through_look, verdict)

CINEMATIC = tg.PostFX.from_config(json.loads(LOOK.read_text())).eval()
GREY = middle_grey_display(CINEMATIC)


def test_there_are_sample_images_to_judge():
    assert len(sample_paths()) >= 20


@pytest.mark.parametrize("path", sample_paths(), ids=lambda path: path.name)
def test_the_cinematic_look_neither_washes_out_nor_crushes_a_sample(path):
    image = read_sample(path)
    if isinstance(image, str):
        assert path.name == "deep_Balls.exr"  # a deep file holds samples per pixel, no flat image
        return
    with torch.no_grad():
        display, stops = through_look(CINEMATIC, image)
    statistics = display_statistics(display)
    assert verdict(statistics, GREY) == "ok", (statistics, stops)


def test_the_rule_finds_the_washed_out_candle_of_whole_frame_log_metering():
    """The look as it was (log-average over the whole frame, no limit): CandleGlass exposed +7.5 stops, washed out."""
    old = json.loads(LOOK.read_text())
    old["exposure"] = {"middle_grey": 0.18, "speed": 1.5, "metering": "log"}
    old["bloom"].pop("clamp")
    look = tg.PostFX.from_config(old).eval()
    with torch.no_grad():
        display, stops = through_look(look, read_sample(LOOK.parents[2].parent / "shared" / "data" / "exr" / "CandleGlass.exr"))
    assert stops > 7
    assert verdict(display_statistics(display), middle_grey_display(look)) == "washed out"


def test_the_rule_finds_a_frame_crushed_by_a_fixed_exposure():
    look = tg.PostFX.from_config({**json.loads(LOOK.read_text()), "exposure": {"fixed_exposure": -6.0}}).eval()
    with torch.no_grad():
        display, stops = through_look(look, read_sample(LOOK.parents[2].parent / "shared" / "data" / "exr" / "Carrots.exr"))
    assert stops == pytest.approx(-6.0)
    assert verdict(display_statistics(display), GREY) == "crushed"
