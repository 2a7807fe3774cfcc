"""Tests of the renderer's backgrounds: procedural ones, image files and folders."""

from __future__ import annotations

import itertools
import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from physinfer.errors import UserInputError
from physinfer_flag.backgrounds import BACKGROUND_NAMES, background_image, list_background_images


def test_procedural_backgrounds_have_the_size_asked_for() -> None:
    assert len(BACKGROUND_NAMES) >= 6
    for name in BACKGROUND_NAMES:
        image = background_image(name, (48, 80))
        assert image.shape == (48, 80, 3) and image.dtype == np.uint8, name
        assert image.std() > 3.0, f"{name} is a flat colour"


def test_procedural_backgrounds_are_distinct() -> None:
    images = {n: background_image(n, (64, 64)).astype(np.float32) for n in BACKGROUND_NAMES}
    for a, b in itertools.combinations(BACKGROUND_NAMES, 2):
        assert np.abs(images[a] - images[b]).mean() > 5.0, (a, b)


def test_procedural_backgrounds_are_deterministic() -> None:
    first = background_image("sky_cloudy", (40, 40)).copy()
    # A different size computes afresh; asking again must give the cached identical picture.
    background_image("sky_cloudy", (41, 41))
    np.testing.assert_array_equal(first, background_image("sky_cloudy", (40, 40)))
    # The sky is blue at the top.
    top = first[0].astype(int).mean(axis=0)
    assert top[2] > top[0] + 40


def test_image_file_is_centre_cropped_and_resized(tmp_path: Path) -> None:
    image = np.zeros((100, 300, 3), dtype=np.uint8)
    image[:, 100:200] = (0, 200, 0)  # green centre third; red margins are cropped away
    image[:, :100] = image[:, 200:] = (200, 0, 0)
    path = tmp_path / "field.png"
    Image.fromarray(image).save(path)
    out = background_image(path, (32, 32))
    assert out.shape == (32, 32, 3)
    assert out[..., 1].min() > 150 and out[..., 0].max() < 60


def test_edited_image_file_is_read_again(tmp_path: Path) -> None:
    path = tmp_path / "bg.png"
    Image.fromarray(np.full((20, 20, 3), 10, np.uint8)).save(path)
    assert background_image(path, (8, 8)).max() == 10
    Image.fromarray(np.full((20, 20, 3), 200, np.uint8)).save(path)
    os.utime(path, ns=(1, 1))  # make sure the modification time differs
    assert background_image(path, (8, 8)).min() == 200


def test_unknown_background_is_refused() -> None:
    with pytest.raises(UserInputError, match="neither a procedural background"):
        background_image("no_such_sky", (10, 10))


def test_unreadable_image_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "broken.png"
    path.write_bytes(b"not a png")
    with pytest.raises(UserInputError, match="cannot read"):
        background_image(path, (10, 10))


def test_folder_lists_images_sorted(tmp_path: Path) -> None:
    for name in ("b.jpg", "a.png", "notes.txt"):
        if name.endswith(".txt"):
            (tmp_path / name).write_text("x")
        else:
            Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(tmp_path / name)
    assert [Path(p).name for p in list_background_images(tmp_path)] == ["a.png", "b.jpg"]


def test_folder_errors(tmp_path: Path) -> None:
    with pytest.raises(UserInputError, match="does not exist"):
        list_background_images(tmp_path / "missing")
    with pytest.raises(UserInputError, match="holds no images"):
        list_background_images(tmp_path)
