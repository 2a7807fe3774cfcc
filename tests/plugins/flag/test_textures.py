"""Tests of the procedural flag textures: enough designs, 2:3, distinct, oriented as documented."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer_flag.textures import FLAG_NAMES, flag_texture


def test_at_least_twelve_national_flags() -> None:
    assert len(FLAG_NAMES) >= 12
    assert len(set(FLAG_NAMES)) == len(FLAG_NAMES)


@pytest.mark.parametrize("height", [2, 64, 100, 256])
def test_every_texture_is_two_by_three_rgb_uint8(height: int) -> None:
    for name in FLAG_NAMES:
        image = flag_texture(name, height)
        assert image.shape == (height, round(1.5 * height), 3), name
        assert image.dtype == np.uint8


def test_textures_are_pairwise_distinct() -> None:
    images = {name: flag_texture(name, 32).astype(np.float32) for name in FLAG_NAMES}
    for a, b in itertools.combinations(FLAG_NAMES, 2):
        difference = np.abs(images[a] - images[b]).mean()
        assert difference > 15.0, f"{a} and {b} look alike (mean difference {difference:.1f})"


def test_textures_are_not_plain_and_have_few_colours() -> None:
    for name in FLAG_NAMES:
        image = flag_texture(name, 64)
        colours = np.unique(image.reshape(-1, 3), axis=0)
        assert len(colours) >= 2, name
        # Anti-aliased edges add blends, but the design itself is a handful of flat colours.
        values, counts = np.unique(image.reshape(-1, 3), axis=0, return_counts=True)
        assert np.sort(counts)[-4:].sum() > 0.8 * image.shape[0] * image.shape[1], name


def test_rows_run_top_to_bottom_and_columns_hoist_to_fly() -> None:
    netherlands = flag_texture("netherlands", 60).astype(int)
    top, bottom = netherlands[5, 45], netherlands[55, 45]
    assert top[0] > 150 and top[2] < 80, "red stripe on top"
    assert bottom[2] > 100 and bottom[0] < 80, "blue stripe at the bottom"
    france = flag_texture("france", 60).astype(int)
    assert france[30, 5, 2] > 100 and france[30, 5, 0] < 50, "blue at the hoist"
    assert france[30, 85, 0] > 200, "red at the fly"


def test_discs_are_round_and_placed_as_designed() -> None:
    japan = flag_texture("japan", 100).astype(int)
    red = (japan[..., 0] > 120) & (japan[..., 1] < 80)
    rows, cols = np.nonzero(red)
    assert abs(rows.mean() - 50) < 1 and abs(cols.mean() - 75) < 1
    assert abs(np.ptp(rows) - np.ptp(cols)) <= 2, "a circle, not an ellipse"
    assert abs(np.ptp(rows) + 1 - 60) <= 2, "diameter three fifths of the height"
    bangladesh = flag_texture("bangladesh", 100).astype(int)
    cols = np.nonzero(bangladesh[..., 0] > 150)[1]
    assert cols.mean() < 75 - 5, "Bangladesh's disc sits towards the hoist"


def test_names_are_case_insensitive_and_results_read_only() -> None:
    image = flag_texture("Sweden", 40)
    np.testing.assert_array_equal(image, flag_texture("sweden", 40))
    with pytest.raises(ValueError):
        image[0, 0, 0] = 1


def test_unknown_texture_lists_the_choices() -> None:
    with pytest.raises(UserInputError, match="narnia.*netherlands"):
        flag_texture("narnia")


def test_too_small_height_is_refused() -> None:
    with pytest.raises(UserInputError, match="height"):
        flag_texture("germany", 1)
