"""Shared scenes for the Python tests: tiny, so that the whole directory runs in seconds."""

import os
import pathlib
import shutil

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]

# Scratched glass over a diffuse floor, 70 x 40 pixels (15 tiles), shared with the Rust tests.
SCENE = (ROOT / "crates/striae/tests/data/scratched-sphere.toml").read_text()


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
