"""A turntable: the camera circles the built-in scratched glass teapot scene, one frame per
step, each frame rendered in parts over a Dask cluster (a local one here; see
docs/distributed.md for Slurm, PBS and Kubernetes), every frame bit for bit the
single-machine render. Writes turntable-NNN.exr/png.

    pip install . "dask[distributed]"
    python examples/turntable.py [frames] [spp]
"""

import math
import sys
import tomllib  # Python >= 3.11; on 3.9/3.10 `pip install tomli` and import it instead

from dask.distributed import Client, LocalCluster

import striae
import striae.distributed

SCENE = "scenes/glass-teapot-setting1.toml"


def main(frames=8, spp=16):
    with open(SCENE, "rb") as f:
        base = tomllib.load(f)
    # Relative paths inside the scene (none in this one) would resolve against the workers'
    # working folder.
    cx, cy, cz = base["camera"]["look_at"]
    px, py, pz = base["camera"]["position"]
    radius = math.hypot(px - cx, pz - cz)

    def scene_for_frame(k):
        a = 2 * math.pi * k / frames
        scene = {**base, "camera": dict(base["camera"])}
        scene["camera"]["position"] = [cx + radius * math.sin(a), py, cz + radius * math.cos(a)]
        scene["render"] = {**base["render"], "spp": spp, "width": 320, "height": 240}
        return scene

    with LocalCluster(n_workers=2, threads_per_worker=1) as cluster, Client(cluster) as client:
        frames_done = striae.distributed.render_frames(scene_for_frame, frames, client)
        for k, image in frames_done:
            striae.write_image(image, f"turntable-{k:03d}", exposure=base["render"].get("exposure", 0.0))
            print(f"frame {k}: wrote turntable-{k:03d}.exr and .png")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
