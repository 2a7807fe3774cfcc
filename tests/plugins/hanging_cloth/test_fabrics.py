"""Tests of physinfer_hanging_cloth.fabrics: procedural fabric textures."""

from __future__ import annotations

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer_hanging_cloth.fabrics import PATTERNS, fabric_texture


@pytest.mark.parametrize("pattern", PATTERNS)
def test_every_pattern_draws_its_colours(pattern):
    image = fabric_texture(pattern, (200, 30, 30), (20, 20, 220), repeats=4, size=64)
    assert image.shape == (64, 64, 3) and image.dtype == np.uint8
    reddish = image[..., 0] > image[..., 2]
    if pattern == "plain":
        assert reddish.all()
    else:
        assert 0.1 < reddish.mean() < 0.95  # both colours show


def test_pattern_scale_and_determinism():
    coarse = fabric_texture("stripes", (255, 255, 255), (0, 0, 0), repeats=2, size=64)
    fine = fabric_texture("stripes", (255, 255, 255), (0, 0, 0), repeats=8, size=64)
    changes = lambda img: int(np.count_nonzero(np.diff(img[0, :, 0].astype(int) > 128)))  # noqa: E731
    assert changes(fine) > changes(coarse)
    np.testing.assert_array_equal(coarse, fabric_texture("stripes", (255, 255, 255), (0, 0, 0), repeats=2, size=64))
    coarse[:] = 0  # a returned copy: the cache stays intact
    assert fabric_texture("stripes", (255, 255, 255), (0, 0, 0), repeats=2, size=64).max() > 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("tartan", (1, 2, 3), (4, 5, 6)), "unknown fabric pattern"),
        (("plain", (1, 2, 300), (4, 5, 6)), "colour"),
        (("plain", (1, 2), (4, 5, 6)), "colour"),
    ],
)
def test_bad_textures_are_refused(args, message):
    with pytest.raises(UserInputError, match=message):
        fabric_texture(*args)
    with pytest.raises(UserInputError, match="repeats"):
        fabric_texture("plain", (0, 0, 0), (0, 0, 0), repeats=100)
