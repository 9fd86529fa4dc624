"""striae.render, parts and merge from Python: against the CLI's EXR bit for bit, the three
forms of a scene, progress, Ctrl-C and errors."""

import subprocess
import sys
import signal
import threading
import _thread
import time

import numpy as np
import pytest

import striae
from conftest import SCENE, striae_cli


def bits(a):
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


def test_render_is_the_cli_exr_bit_for_bit(scene_file, tmp_path):
    cli = striae_cli()
    if cli is None:
        pytest.skip("no striae binary (cargo build --release)")
    out = tmp_path / "cli"
    subprocess.run(
        [cli, "render", str(scene_file), "--spp", "3", "--seed", "9", "-q", "-o", str(out)],
        check=True,
    )
    image = striae.render(scene_file, spp=3, seed=9, threads=2)
    assert image.shape == (40, 70, 3) and image.dtype == np.float32
    assert image.mean() > 0
    np.testing.assert_array_equal(bits(image), bits(striae.read_exr(f"{out}.exr")))
    # The CLI's part files merge, in Python, to the same image.
    for i in range(3):
        subprocess.run(
            [cli, "render", str(scene_file), "--spp", "3", "--seed", "9", "-q",
             "--tile", f"{i}/3", "-o", str(tmp_path / f"p{i}.part")],
            check=True,
        )
    merged = striae.merge([tmp_path / f"p{i}.part" for i in (2, 0, 1)])
    np.testing.assert_array_equal(bits(merged), bits(image))
    # and `striae merge` writes that EXR.
    subprocess.run(
        [cli, "merge", *[str(tmp_path / f"p{i}.part") for i in range(3)], "-o", str(tmp_path / "m")],
        check=True,
    )
    np.testing.assert_array_equal(bits(striae.read_exr(tmp_path / "m.exr")), bits(image))


def test_path_text_and_dict_give_the_same_image(scene_file):
    a = striae.render(scene_file, spp=2)
    b = striae.render(SCENE, spp=2)
    np.testing.assert_array_equal(bits(a), bits(b))
    if sys.version_info >= (3, 11):
        import tomllib

        c = striae.render(tomllib.loads(SCENE), spp=2)
        np.testing.assert_array_equal(bits(a), bits(c))


@pytest.mark.parametrize("count", [1, 2, 7, 4])
def test_parts_merge_to_the_whole_render(count):
    whole = striae.render(SCENE, threads=2)
    parts = [striae.render_part(SCENE, i, count) for i in range(count)]
    np.testing.assert_array_equal(bits(striae.merge(parts[::-1])), bits(whole))


def test_bad_parts_are_refused():
    parts = [striae.render_part(SCENE, i, 2, spp=1) for i in range(2)]
    other = striae.render_part(SCENE, 1, 2, spp=1, seed=6)
    with pytest.raises(striae.StriaeError, match="parts missing: \\[1\\]"):
        striae.merge(parts[:1])
    with pytest.raises(striae.StriaeError, match="given twice"):
        striae.merge(parts + parts[:1])
    with pytest.raises(striae.StriaeError, match="different renders: seed is 5 in one and 6"):
        striae.merge([parts[0], other])
    damaged = bytearray(parts[1])
    damaged[len(damaged) // 2] ^= 1
    with pytest.raises(striae.StriaeError, match="checksum"):
        striae.merge([parts[0], bytes(damaged)])
    with pytest.raises(striae.StriaeError, match="part 2/2: the part index must lie in 0..2"):
        striae.render_part(SCENE, 2, 2)
    with pytest.raises(striae.StriaeError, match="only 15 tiles"):
        striae.render_part(SCENE, 0, 16)


def test_sample_ranges_merge_within_the_noise():
    # docs/distributed.md: on this scene at 8 spp, max 0.05 and rms 0.002 from the whole
    # render (seed to seed: max 0.21, rms 0.02); not bit for bit.
    whole = striae.render(SCENE, spp=8, threads=2)
    parts = [striae.render_part(SCENE, 0, 1, samples=r, spp=8) for r in [(5, 8), (0, 2), (2, 5)]]
    d = np.abs(striae.merge(parts) - whole)
    assert d.max() < 0.1 and np.sqrt((d**2).mean()) < 0.005
    with pytest.raises(striae.StriaeError, match="overlap: both hold samples 5..8"):
        striae.merge(parts + parts[:1])
    with pytest.raises(striae.StriaeError, match="no part file holds samples 2..5"):
        striae.merge(parts[:2])
    with pytest.raises(striae.StriaeError, match="samples 0..9: B must be at most"):
        striae.render_part(SCENE, 0, 1, samples=(0, 9), spp=8)


def test_progress_counts_every_sample():
    seen = []
    striae.render(SCENE, spp=2, progress=seen.append)
    assert sum(seen) == 70 * 40 * 2 and all(n > 0 for n in seen)


def test_errors_carry_the_cli_message(tmp_path):
    bad = SCENE.replace("fov = 40", "fov = 400")
    with pytest.raises(striae.StriaeError, match=r"key `camera.fov` = 400.0: must lie in \(0, 180\)"):
        striae.render(bad)
    with pytest.raises(striae.StriaeError, match="cannot read scene file"):
        striae.render(tmp_path / "missing.toml")
    cli = striae_cli()
    if cli is not None:
        path = tmp_path / "bad.toml"
        path.write_text(bad)
        r = subprocess.run([cli, "render", str(path), "-q"], capture_output=True, text=True)
        with pytest.raises(striae.StriaeError) as e:
            striae.render(path)
        # The CLI prints `error: cannot load the scene: MESSAGE`.
        assert str(e.value) in r.stderr


def test_ctrl_c_stops_a_render():
    big = SCENE.replace("width = 70", "width = 640").replace("height = 40", "height = 480")
    # Python's own Ctrl-C handler: a shell that starts the tests in the background has them
    # ignore SIGINT, and `interrupt_main` then does nothing.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        timer = threading.Timer(0.5, _thread.interrupt_main)
        start = time.monotonic()
        timer.start()
        with pytest.raises(KeyboardInterrupt):
            striae.render(big, spp=256, threads=1)
        assert time.monotonic() - start < 20
    finally:
        signal.signal(signal.SIGINT, previous)


def test_part_files_are_read_as_the_cli_reads_them(tmp_path):
    """A path is read by the library as `striae merge` reads it: a folder is refused by name,
    and a file cut short by its size against its header, before its pixels are read."""
    part = striae.render_part(SCENE, 0, 1, spp=1)
    with pytest.raises(striae.StriaeError, match="is a folder, not a regular file"):
        striae.merge([tmp_path])
    short = tmp_path / "short.part"
    short.write_bytes(part[:-5])
    with pytest.raises(striae.StriaeError, match=f"short.part.* is {len(part) - 5} bytes"):
        striae.merge([short])
    whole = tmp_path / "whole.part"
    whole.write_bytes(part)
    np.testing.assert_array_equal(striae.merge([whole]), striae.merge([part]))
