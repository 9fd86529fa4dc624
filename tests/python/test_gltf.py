"""striae.render with a glTF path: a GLB built here (an emissive triangle before a camera)
renders; one without a camera is an error saying so."""

import json
import struct

import numpy as np
import pytest

import striae


def glb(camera=True):
    """A GLB: the triangle (-1, -1, 0), (1, -1, 0), (0, 1, 0), emissive, seen from z = 3."""
    positions = [-1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0]
    binary = struct.pack("<9f", *positions)
    nodes = [{"mesh": 0}]
    doc = {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0, 1] if camera else [0]}],
        "nodes": nodes,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
        "materials": [{"emissiveFactor": [1, 1, 1]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [-1, -1, 0], "max": [1, 1, 0]}],
        "bufferViews": [{"buffer": 0, "byteLength": len(binary)}],
        "buffers": [{"byteLength": len(binary)}],
    }
    if camera:
        nodes.append({"camera": 0, "translation": [0, 0, 3]})
        doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.1}}]
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    return (b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(text)) + b"JSON" + text
            + struct.pack("<I", len(binary)) + b"BIN\0" + binary)


def test_render_a_glb(tmp_path):
    path = tmp_path / "tri.glb"
    path.write_bytes(glb())
    image = striae.render(path, res=(9, 7), spp=2, threads=1)
    assert image.shape == (7, 9, 3)
    # The centre sees the emitter (radiance 1), a corner the black background.
    assert image[3, 4].min() == pytest.approx(1.0)
    assert np.all(image[0, 0] == 0)


def test_a_glb_without_camera_is_an_error(tmp_path):
    path = tmp_path / "nocam.glb"
    path.write_bytes(glb(camera=False))
    with pytest.raises(striae.StriaeError, match="no camera"):
        striae.render(path, res=(4, 4), spp=1)
