"""Ray Data grades a shot as the single-machine ``torchgrade grade`` does, on a local one-CPU Ray instance."""

import json

import pytest
import ray  # in the test extra, so CI runs this rather than skipping it
import torch

import torchgrade as tg
from torchgrade.cli import main
from torchgrade.integrations.ray import grade_shot_on_ray

pytestmark = pytest.mark.xdist_group("ray")  # one Ray cluster at a time: these run in one worker, in turn


LOOKS = {
    "flat": {"grade": {"contrast": 20}, "tonemap": "neutral"},
    "adapting": {"exposure": {"metering": "mean", "speed_to_light": 2.0, "speed_to_dark": 1.0}, "tonemap": "aces"},
}


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


@pytest.mark.parametrize("name", LOOKS)
def test_ray_frames_equal_the_cli_frames(local_ray, tmp_path, name):
    plates = tmp_path / "plates"
    plates.mkdir()
    generator = torch.Generator().manual_seed(0)
    for number in range(1, 5):
        tg.io.write_exr(plates / f"plate.{number:03d}.exr", torch.rand(3, 6, 8, generator=generator) * number**2, half=False)
    config = tmp_path / "look.json"
    config.write_text(json.dumps(LOOKS[name]))
    assert main(["grade", str(plates), "-o", str(tmp_path / "cli.%03d.exr"), "--config", str(config), "--bit-depth", "float", "-q"]) == 0
    written = grade_shot_on_ray(tg.PostFX.from_config(LOOKS[name]), [str(plates)], str(tmp_path / "ray.%03d.exr"), bit_depth="float")
    assert [path.name for path in written] == [f"ray.{n:03d}.exr" for n in range(1, 5)]
    for number in range(1, 5):
        single, cluster = (tg.io.read_exr(tmp_path / f"{kind}.{number:03d}.exr") for kind in ("cli", "ray"))
        if name == "flat":
            assert torch.equal(single, cluster)
        else:  # the adaptation recurrence runs on one-pixel frames: float rounding only
            torch.testing.assert_close(single, cluster, rtol=1e-5, atol=1e-6)
