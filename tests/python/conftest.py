"""Shared scenes for the Python tests: tiny, so that the whole directory runs in seconds."""

import os
import pathlib
import shutil

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]

# Scratched glass (both scratch-coverage caches at work) over a diffuse floor: 70 x 40 pixels
# are 5 x 3 = 15 tiles of 16 x 16, the last column and row cut short.
SCENE = """
[render]
width = 70
height = 40
spp = 4
seed = 5
[camera]
position = [0, 1, 4]
look_at = [0, 0.5, 0]
fov = 40
[materials.floor]
type = "diffuse"
reflectance = 0.6
[materials.glass]
type = "scratched"
base = "glass"
[materials.glass.scratches]
m = 32
n = 400
nr = 10
length = 0.3
width = 0.06
threshold = 0.3
layers = 4
seed = 3
[[shapes]]
type = "rectangle"
material = "floor"
transform = [{ scale = 6.0 }, { rotate = { axis = [1, 0, 0], angle = -90 } }]
[[shapes]]
type = "sphere"
material = "glass"
center = [0, 0.6, 0]
radius = 0.6
[environment]
type = "constant"
radiance = [0.8, 0.9, 1.0]
"""


@pytest.fixture(autouse=True, scope="session")
def table_cache(tmp_path_factory):
    """Scratch tables are cached in a temporary folder, not the user's cache."""
    os.environ["STRIAE_CACHE"] = str(tmp_path_factory.mktemp("cache"))


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    return path


def striae_cli():
    """The CLI binary (STRIAE_BIN, else target/release/striae, else `striae` on PATH)."""
    for candidate in [os.environ.get("STRIAE_BIN"), ROOT / "target/release/striae"]:
        if candidate and pathlib.Path(candidate).is_file():
            return str(candidate)
    return shutil.which("striae")
