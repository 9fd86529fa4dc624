"""striae.distributed.render on a local Dask cluster of two workers: the image is the
single-machine render bit for bit, also when a worker dies mid-render."""

import os
import signal
import time

import numpy as np
import pytest

import striae
from conftest import SCENE

distributed = pytest.importorskip("distributed")
import striae.distributed  # noqa: E402


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    )
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def bits(a):
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


def test_dask_render_is_the_single_machine_render(client):
    whole = striae.render(SCENE, threads=1)
    image = striae.distributed.render(SCENE, client, parts=7, threads=1)
    np.testing.assert_array_equal(bits(image), bits(whole))


def test_a_worker_dying_mid_render_changes_nothing():
    """One of two worker processes exits abruptly while it renders a part: the scheduler runs
    its parts again (on the other worker or the restarted one), and the image is the same."""
    whole = striae.render(SCENE, spp=128, threads=1)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, distributed.Client(cluster) as c:
        futures = striae.distributed._submit(c, SCENE, 15, 2, dict(spp=128, threads=1))
        deadline = time.monotonic() + 30
        while not any(c.processing().values()) and time.monotonic() < deadline:
            time.sleep(0.01)
        victim = next(w for w, tasks in c.processing().items() if tasks)
        assert not all(f.done() for f in futures)
        pid = c.run(os.getpid, workers=[victim])[victim]
        os.kill(pid, signal.SIGKILL)
        image = striae.merge(c.gather(futures))
        assert victim not in c.scheduler_info()["workers"]
    np.testing.assert_array_equal(bits(image), bits(whole))
