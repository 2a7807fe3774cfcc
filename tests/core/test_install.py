"""What `make install` sets up, so that rendering installs and imports on Python 3.11-3.13 on a
headless machine (issue 45, item 5).

pyrender 0.1.45 (its last release) pins ``PyOpenGL==3.1.0``, which fails on Python 3.12+ ("No
array-type handler for type _ctypes.type"; fixed in PyOpenGL 3.1.7). A requirement
``PyOpenGL>=3.1.7`` in ``pyproject.toml`` would make pip's resolver refuse the whole install
(ResolutionImpossible against pyrender's pin), so the Makefile installs it as its own step after
everything else, as pip installs it anyway then (with a warning about pyrender's pin).
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PYOPENGL_FLOOR = (3, 1, 7)


def makefile() -> str:
    return (ROOT / "Makefile").read_text()


def install_recipe() -> list[str]:
    """The recipe lines of ``$(VENV)/.installed``."""
    lines = makefile().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("$(VENV)/.installed:"))
    recipe = []
    for line in lines[start + 1 :]:
        if not line.startswith("\t"):
            break
        recipe.append(line.strip())
    return recipe


def test_the_install_ends_with_a_pyopengl_that_works_on_python_3_12():
    recipe = install_recipe()
    pip_lines = [i for i, line in enumerate(recipe) if "$(PIP) install" in line]
    spec = next(i for i, line in enumerate(recipe) if '"$(PYOPENGL_SPEC)"' in line)
    assert spec == pip_lines[-1], "installed last: a later pip install would put pyrender's pin back"
    assert re.search(r'^PYOPENGL_SPEC \?= PyOpenGL>=3\.1\.7$', makefile(), re.M)


def test_the_installed_pyopengl_works_on_python_3_12():
    import OpenGL

    version = tuple(int(part) for part in OpenGL.__version__.split(".")[:3])
    assert version >= PYOPENGL_FLOOR, f"PyOpenGL {OpenGL.__version__}: run make install again"


def test_pyproject_declares_python_3_11_to_3_13_and_does_not_pin_pyopengl_against_pyrender():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["requires-python"] == ">=3.11"
    versions = {c for c in project["classifiers"] if c.startswith("Programming Language :: Python :: 3.")}
    assert versions == {f"Programming Language :: Python :: 3.{minor}" for minor in (11, 12, 13)}
    # pip cannot resolve PyOpenGL>=3.1.7 together with pyrender's PyOpenGL==3.1.0 pin.
    assert not any(dep.lower().startswith("pyopengl") for dep in project["dependencies"])


def test_the_makefile_installs_libgl_for_a_headless_pyglet_and_checks_for_it():
    text = makefile()
    packages = re.search(r"^EGL_PACKAGES := (.*)$", text, re.M).group(1).split()
    assert {"libegl1", "libegl-mesa0", "libgl1-mesa-dri", "libgl1", "libglx0"} <= set(packages)
    logical = text.replace("\\\n", " ").splitlines()  # recipe lines continued with a backslash
    check = next(line for line in logical if "ldconfig -p" in line)
    for library in ("libEGL_mesa.so", "libGL.so.1", "libGLX.so.0"):  # libgl1, libglx0
        assert library in check, f"installed only when missing: check for {library}"
    assert re.search(r"^export PYGLET_HEADLESS \?= 1$", text, re.M)
    assert re.search(r"^export PYOPENGL_PLATFORM \?= egl$", text, re.M)
