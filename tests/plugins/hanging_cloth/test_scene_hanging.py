"""The hanging cloth's scene settings: fabric size and fan level reach its simulator."""

import pytest

from physinfer.errors import UserInputError
from physinfer.plugins import load_registry
from physinfer.scene import bind_scene, resolve_scene


@pytest.fixture(scope="module")
def cloth():
    return load_registry()[0].phenomenon("hanging_cloth")


def test_a_scene_sets_the_fabric_size_and_the_fan(cloth):
    scene = resolve_scene(cloth, {"cloth_width": "1.0", "fan": "W3"})
    config = bind_scene(cloth, scene).make_simulator(()).config
    assert (config.width, config.height, config.fan_level) == (1.0, 0.8, "W3")
    assert config.grid == (26, 21)  # the 4 cm spacing is kept
    default = bind_scene(cloth, resolve_scene(cloth, {"fan": "W2"})).make_simulator(()).config
    assert default == cloth.make_simulator(()).config


def test_a_fan_level_typo_names_the_levels(cloth):
    with pytest.raises(UserInputError, match="--scene-set fan=W4: choose one of W1, W2, W3"):
        resolve_scene(cloth, {"fan": "W4"})
