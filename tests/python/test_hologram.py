"""Scratch holograms from Python (METHOD.md 9.4): the arcs as arrays, the SVG, the parallax of
the glints, the CLI's identical drawing, and errors."""

import subprocess

import numpy as np
import pytest

import striae
from conftest import striae_cli

POINTS = np.array(
    [
        [0.3, -0.2, -0.5],
        [1.0, 2.0, 0.25],
        [-1.5, 0.5, 1.5],
        [0.0, 0.0, -2.0],
    ]
)


def test_arcs_as_arrays_and_svg():
    h = striae.hologram(POINTS)
    n = len(POINTS)
    assert h["centres"].shape == (n, 2) and h["radii"].shape == (n,)
    np.testing.assert_array_equal(h["centres"], POINTS[:, :2])
    # The default view angle, 45 degrees: the radius is the distance from the plate.
    assert h["scale"] == 1.0
    np.testing.assert_allclose(h["radii"], np.abs(POINTS[:, 2]), rtol=1e-15)
    np.testing.assert_allclose(h["end"] - h["start"], np.pi / 2, rtol=1e-15)
    # The middle of each arc: toward the viewer (+y, azimuth 90) for a point behind, away
    # from the viewer for a point in front.
    middle = 0.5 * (h["start"] + h["end"])
    direction = np.stack([np.cos(middle), np.sin(middle)], axis=1)
    np.testing.assert_allclose(direction[:, 1], -np.sign(POINTS[:, 2]), atol=1e-12)
    assert h["svg"].count("<path ") == n
    x0, y0, sx, sy = h["plate"]
    assert f'viewBox="{x0!r} {y0!r} {sx!r} {sy!r}"' in h["svg"]
    assert h["outside"] == 0 and h["width"] > 0


def test_two_views_see_the_point_at_its_depth():
    """Light at the normal, eye at the design angle: the rays from two views' glints along
    the eye directions meet at the point (METHOD.md 9.4)."""
    h = striae.hologram(POINTS, view_angle=60.0, span=120.0, azimuth=-30.0)
    theta = np.radians(60.0)
    for (c, r, z) in zip(h["centres"], h["radii"], POINTS[:, 2]):
        rays = []
        for alpha in np.radians([-30.0 - 40.0, -30.0 + 25.0]):
            v = np.array([np.sin(theta) * np.cos(alpha), np.sin(theta) * np.sin(alpha), np.cos(theta)])
            # h = l + v with l the normal: h_p = v_p; the glint on the designed side.
            g = c - np.sign(z) * r * v[:2] / np.linalg.norm(v[:2])
            rays.append((np.array([g[0], g[1], 0.0]), v))
        (p, d), (q, e) = rays
        # The nearest points of the two lines.
        w = p - q
        a, b, cc, dd, ee = d @ d, d @ e, e @ e, d @ w, e @ w
        s = (b * ee - cc * dd) / (a * cc - b * b)
        t = (a * ee - b * dd) / (a * cc - b * b)
        x, y = p + s * d, q + t * e
        assert np.linalg.norm(x - y) < 1e-12
        np.testing.assert_allclose(0.5 * (x + y), [c[0], c[1], z], rtol=1e-9, atol=1e-12)


def test_given_plate_scale_and_width():
    h = striae.hologram(POINTS, plate=(-1, -1, 2, 4), scale=0.5, width=0.01, span=360)
    assert h["plate"] == (-1.0, -1.0, 2.0, 4.0) and h["width"] == 0.01 and h["scale"] == 0.5
    np.testing.assert_allclose(h["end"] - h["start"], 2 * np.pi, rtol=1e-15)
    assert h["outside"] == 3
    assert 'stroke-width="0.01"' in h["svg"]


def test_the_cli_draws_the_same_svg(tmp_path):
    cli = striae_cli()
    if cli is None:
        pytest.skip("no striae binary (STRIAE_BIN, target/release/striae or PATH)")
    csv = tmp_path / "points.csv"
    csv.write_text("x,y,z\n" + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in POINTS))
    out = tmp_path / "arcs.svg"
    subprocess.run([cli, "hologram", str(csv), "-o", str(out), "--azimuth", "-90"], check=True)
    assert out.read_text() == striae.hologram(POINTS, azimuth=-90.0)["svg"]


def test_bad_input_is_refused():
    with pytest.raises(striae.StriaeError, match=r"point 1 \(1, 2, 0\): lies on the plate"):
        striae.hologram([[0, 0, 1], [1, 2, 0]])
    with pytest.raises(striae.StriaeError, match="span"):
        striae.hologram(POINTS, span=0)
    with pytest.raises(striae.StriaeError, match="view_angle"):
        striae.hologram(POINTS, view_angle=90)
    with pytest.raises(striae.StriaeError, match="no points"):
        striae.hologram(np.zeros((0, 3)))
    with pytest.raises(ValueError, match="not both"):
        striae.hologram(POINTS, view_angle=30, scale=1)
    with pytest.raises(ValueError, match="plate"):
        striae.hologram(POINTS, plate=(0, 0, 1))
    with pytest.raises(ValueError):
        striae.hologram(np.zeros((4, 2)))


def test_scene_dict_takes_numpy_polylines_as_curves():
    """Curves given as numpy polylines in a scene dict render as the same curves in TOML text
    (docs/scenes.md, `polylines`)."""
    t = np.linspace(0.0, 2.0 * np.pi, 200)
    ring = np.stack([0.5 + 0.3 * np.cos(t), 0.5 + 0.3 * np.sin(t)], axis=1)
    ring[-1] = ring[0]
    widths = np.full(len(ring), 0.01)
    scene = {
        "render": {"width": 24, "height": 24, "spp": 2, "seed": 1},
        "camera": {"position": [0.0, 0.0, 3.0], "look_at": [0.0, 0.0, 0.0], "fov": 50.0},
        "materials": {
            "m": {
                "type": "scratched",
                "base": "metal",
                "preset": "gold",
                "scratches": {
                    "m": 16,
                    "n": 200,
                    "walls": "diffuse",
                    "polylines": [{"points": ring, "widths": widths}],
                },
            }
        },
        "shapes": [{"type": "rectangle", "material": "m"}],
        "environment": {"type": "constant", "radiance": 1.0},
    }
    image = striae.render(scene, threads=1)
    toml_lines = "[" + ", ".join(f"[{u!r}, {v!r}]" for u, v in ring.tolist()) + "]"
    text = f"""
[render]
width = 24
height = 24
spp = 2
seed = 1
[camera]
position = [0.0, 0.0, 3.0]
look_at = [0.0, 0.0, 0.0]
fov = 50.0
[materials.m]
type = "scratched"
base = "metal"
preset = "gold"
[materials.m.scratches]
m = 16
n = 200
walls = "diffuse"
polylines = [{{ points = {toml_lines}, widths = {[0.01] * len(ring)} }}]
[[shapes]]
type = "rectangle"
material = "m"
[environment]
type = "constant"
radiance = 1.0
"""
    np.testing.assert_array_equal(image, striae.render(text, threads=1))
    # Without the ring the plate is the gold base alone: the ring changes the image.
    plain = dict(scene)
    plain["materials"] = {"m": {"type": "conductor", "preset": "gold"}}
    assert not np.array_equal(image, striae.render(plain, threads=1))
