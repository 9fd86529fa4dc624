"""Render one image on a Dask ``distributed`` cluster, bit for bit the single-machine render.

The image is cut into ``parts`` (part ``i`` holds the film's tiles ``t % parts == i``); each
part is one Dask task that renders it (:func:`striae.render_part`) and returns the part file's
bytes, checksummed; the client merges them (:func:`striae.merge`), which refuses a set that is
not every part of one render exactly once. A pixel's value does not depend on which machine or
which other tiles rendered it, so the merged image is the one ``striae.render`` gives. If a
worker dies mid-render, the scheduler runs its task again on another worker (tasks are pure:
``pure=True`` and the same key for the same arguments), and the image is unchanged.

The workers need the ``striae`` package, and, for a scene given as a path, the scene file and
the files it names at the same path; a dict or TOML text travels with the task (files it
names, relative to the worker's working folder, must exist there).
"""

from __future__ import annotations

from typing import Any, Callable, Iterator, Tuple

import numpy as np

from . import SceneLike, merge, render_part


def render(
    scene: SceneLike, client: Any, parts: int = 0, retries: int = 2, **settings: Any
) -> np.ndarray:
    """Render ``scene`` over the Dask ``client`` in ``parts`` tasks (default: 4 per worker
    thread of the cluster, so that faster workers take more) and return the ``(h, w, 3)``
    float32 image. ``settings`` are :func:`striae.render`'s keywords (``spp``, ``res``,
    ``seed``, ``max_depth``, ``sampler``; ``threads``: render threads per task, default the
    worker's cores). ``retries``: how often a failed task is run again (a task on a worker
    that dies is re-run by the scheduler in any case)."""
    parts = parts if parts > 0 else _default_parts(client)
    futures = _submit(client, scene, parts, retries, settings)
    return merge(client.gather(futures))


def _default_parts(client: Any) -> int:
    return max(1, 4 * sum(client.nthreads().values()))


def _submit(client: Any, scene: SceneLike, parts: int, retries: int, settings: dict) -> list:
    return [
        client.submit(render_part, scene, i, parts, pure=True, retries=retries, **settings)
        for i in range(parts)
    ]


def render_frames(
    scene_for_frame: Callable[[int], SceneLike],
    frames: int,
    client: Any,
    parts: int = 0,
    retries: int = 2,
    **settings: Any,
) -> Iterator[Tuple[int, np.ndarray]]:
    """Render ``frames`` images over ``client``, frame ``f`` from the scene
    ``scene_for_frame(f)`` (a dict or TOML text, e.g. a camera moved around a turntable),
    every frame's parts in flight at once; yields ``(f, image)`` in frame order."""
    parts = parts if parts > 0 else _default_parts(client)
    per_frame = [
        _submit(client, scene_for_frame(f), parts, retries, settings) for f in range(frames)
    ]
    for f, futures in enumerate(per_frame):
        yield f, merge(client.gather(futures))
