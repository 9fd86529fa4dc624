"""striae.distributed.render on a local Dask cluster of two workers: the image is the
single-machine render bit for bit, also when a worker leaves mid-render."""

import threading

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


def test_a_worker_leaving_mid_render_changes_nothing():
    """One of two workers is closed while the parts run: its tasks are recomputed on the
    other one, and the image is the same."""
    whole = striae.render(SCENE, spp=8, threads=1)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster, distributed.Client(cluster) as c:
        victim = list(cluster.workers.values())[0]
        timer = threading.Timer(0.2, lambda: c.sync(victim.close))
        timer.start()
        image = striae.distributed.render(SCENE, c, parts=15, spp=8, threads=1)
        timer.join()
        assert len(c.scheduler_info()["workers"]) == 1
    np.testing.assert_array_equal(bits(image), bits(whole))
