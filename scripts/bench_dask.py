"""Parts over Dask: speed-up of 2 local workers over 1, and the overhead per part.

Renders one scene (default: scenes/glass-teapot-setting1.toml at 320x240, 16 spp) as:
  * one call of striae.render with 1 thread (the reference time T1),
  * striae.distributed.render on a LocalCluster of 1 worker (1 thread) with P parts, and
  * the same on 2 workers (1 thread each),
for P in 2, 8, 32, each image checked bit for bit against the reference. The overhead per part
is (T(1 worker, P parts) - T1) / P. Worker processes (processes=True), as on a cluster.

    python scripts/bench_dask.py [scene] [WxH] [spp]
"""

import sys
import time

import numpy as np
from dask.distributed import Client, LocalCluster

import striae
import striae.distributed


def timed(f):
    t = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t


def main(scene="scenes/glass-teapot-setting1.toml", res="320x240", spp=16):
    w, h = (int(x) for x in res.split("x"))
    kw = dict(spp=int(spp), res=(w, h), threads=1)
    striae.render(scene, spp=1, res=(16, 16), threads=1)  # warm the table cache
    ref, t1 = timed(lambda: striae.render(scene, **kw))
    print(f"striae.render, 1 thread: {t1:.2f} s")
    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster, Client(cluster) as client:
            client.run(lambda: __import__("striae").render(scene, spp=1, res=(16, 16), threads=1))
            for parts in (2, 8, 32):
                img, t = timed(lambda: striae.distributed.render(scene, client, parts=parts, **kw))
                assert np.array_equal(img.view(np.uint32), ref.view(np.uint32))
                extra = f", overhead per part {(t - t1) / parts * 1e3:.0f} ms" if workers == 1 else ""
                print(f"{workers} worker(s), {parts:2d} parts: {t:.2f} s, speed-up {t1 / t:.2f}{extra}")


if __name__ == "__main__":
    main(*sys.argv[1:4])
