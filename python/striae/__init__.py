"""striae: scratched glass and metal, from Python.

The Rust library is the one implementation; this package converts arguments and numpy arrays.
Arrays come back as numpy arrays owned by Python (no copy on the way out beyond building them
once). Errors from the library are raised as :class:`StriaeError` with the message the CLI
prints.
"""

from __future__ import annotations

import json
import os
from typing import Any, Callable, Optional, Sequence, Tuple, Union

import numpy as np

from . import _striae
from ._striae import StriaeError

__all__ = [
    "StriaeError",
    "Table",
    "LayerSet",
    "precompute",
    "layers",
    "render",
    "render_part",
    "merge",
    "read_exr",
    "write_image",
    "hologram",
    "__version__",
]

__version__ = _striae.VERSION

SceneLike = Union[str, "os.PathLike[str]", dict]


def _json_value(x):
    """numpy arrays and numbers in a scene dict (curves as ``polylines``, docs/scenes.md) as
    JSON lists and numbers."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"scene dict holds a {type(x).__name__}, which is not a scene value")


def _scene_source(scene: SceneLike) -> Tuple[str, str]:
    """``(kind, source)`` for the library: a dict goes as JSON, a string holding a newline as
    TOML text, any other string or path-like as the path of a scene file."""
    if isinstance(scene, dict):
        return "json", json.dumps(scene, default=_json_value)
    if isinstance(scene, os.PathLike):
        return "path", os.fspath(scene)
    if isinstance(scene, str):
        return ("toml", scene) if "\n" in scene else ("path", scene)
    raise TypeError(f"scene must be a path, TOML text or a dict, not {type(scene).__name__}")


class Table:
    """A precomputed scratch BRDF table (``docs/table-format.md``) and its lobe, in the
    scratch frame of METHOD.md section 1: ``x`` across the scratch, ``y`` along it, ``z`` the
    surface normal; ``wo`` and ``wi`` point away from the surface."""

    def __init__(self, native: "_striae.Table"):
        self._t = native

    @staticmethod
    def load(path: Union[str, "os.PathLike[str]"]) -> "Table":
        return Table(_striae.Table.load(os.fspath(path)))

    def save(self, path: Union[str, "os.PathLike[str]"]) -> None:
        self._t.save(os.fspath(path))

    m = property(lambda self: self._t.m, doc="The number of angle bins M.")
    phi = property(lambda self: self._t.phi, doc="(M,) bin centres phi_k in radians.")
    theta = property(lambda self: self._t.theta, doc="(3,) theta of the rho_s slices.")
    rho_m = property(lambda self: self._t.rho_m, doc="(M, M) rho_m[phi_i, phi_o], eq. (1').")
    rho_s = property(lambda self: self._t.rho_s, doc="(3, M, M) rho_s at the theta slices.")
    gamma = property(lambda self: self._t.gamma, doc="(M, M) eq. (4) exponents.")
    dropped = property(lambda self: self._t.dropped, doc="(M,) energy dropped by the bounce cap.")
    version = property(lambda self: self._t.version, doc="The striae version that computed it.")
    is_delta = property(lambda self: self._t.is_delta, doc="Mirror walls: a delta lobe.")

    @property
    def params(self) -> dict:
        """The parameters the table was computed with (profile, trace settings)."""
        return json.loads(self._t.params_json)

    def eval(self, wo: np.ndarray, wi: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """``(f, pdf)``, each ``(N,)``, for ``(N, 3)`` directions: the BSDF without the cosine
        and the solid-angle density of :meth:`sample`."""
        return self._t.eval(_rows(wo, 3), _rows(wi, 3))

    def sample(self, wo: np.ndarray, u: np.ndarray):
        """Sample ``wi`` for ``(N, 3)`` ``wo`` and ``(N, 2)`` uniform numbers ``u``: returns
        ``(wi (N, 3), weight (N,), pdf (N,), valid (N,) bool)``; ``weight = f cos / pdf``."""
        return self._t.sample(_rows(wo, 3), _rows(u, 2))

    def __repr__(self) -> str:
        return f"<striae.Table M={self.m} {self.params.get('profile', {})}>"


def _rows(a, cols: int) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == cols:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != cols:
        raise ValueError(f"expected an (N, {cols}) array, got shape {a.shape}")
    return a


def precompute(
    profile: str = "v:angle=90",
    walls: str = "diffuse",
    m: int = 256,
    n: int = 10000,
    nr: int = 100,
    ior: float = 1.5,
    fresnel: Optional[str] = None,
    fresnel_law: str = "schlick",
    albedo: float = 1.0,
    max_bounces: int = 64,
    seed: int = 0,
    estimator: str = "walks",
    groove_slices: int = 0,
    threads: Optional[int] = None,
) -> Table:
    """Trace a scratch profile into a BRDF table, as ``striae precompute`` (same arguments;
    ``fresnel`` defaults to ``"seed"``, or ``"walls"`` with ``groove_slices``, the number of
    exact-groove ``theta_i`` slices the table then carries and evaluates instead of eq. (3))."""
    if fresnel is None:
        fresnel = "walls" if groove_slices else "seed"
    return Table(
        _striae.precompute(
            profile, walls, m, n, nr, ior, fresnel, fresnel_law, albedo, max_bounces, seed,
            estimator, groove_slices, threads,
        )
    )


class LayerSet:
    """Scratch layers from Worley cell noise (METHOD.md section 5)."""

    def __init__(self, native: "_striae.LayerSet", res: int):
        self._s = native
        self.res = res
        self._masks: Optional[np.ndarray] = None

    @property
    def masks(self) -> np.ndarray:
        """``(K, R, R)`` float32 coverage of each texel (row 0 at the top, ``v`` up)."""
        if self._masks is None:
            self._masks = self._s.masks(self.res)
        return self._masks

    directions = property(lambda self: self._s.directions, doc="(K, 2) scratch directions.")
    angles = property(lambda self: self._s.angles, doc="(K,) angles from +u, radians.")
    expected_coverage = property(lambda self: self._s.expected_coverage)

    def __len__(self) -> int:
        return len(self._s)

    def coverage(self, uv, duvdx, duvdy) -> np.ndarray:
        """``(N, K)`` float32 fraction of each footprint ``uv + s duvdx + t duvdy``
        (``s, t`` in ``[-1/2, 1/2]``; ``(N, 2)`` arrays) that each layer covers."""
        return self._s.coverage(_rows(uv, 2), _rows(duvdx, 2), _rows(duvdy, 2))


def layers(
    setting: Optional[int] = 1,
    layers: int = 8,
    seed: int = 1,
    res: int = 1024,
    length: Optional[float] = None,
    width: Optional[float] = None,
    threshold: Optional[float] = None,
) -> LayerSet:
    """Scratch layers as ``striae layers``: the seed's ``setting`` (1 or 2), or ``length``,
    ``width`` and ``threshold``. The masks are rasterised at ``res`` on first use."""
    if length is not None or width is not None or threshold is not None:
        setting = None
    return LayerSet(_striae.LayerSet(setting, layers, seed, length, width, threshold), res)


def render(
    scene: SceneLike,
    spp: Optional[int] = None,
    res: Optional[Tuple[int, int]] = None,
    seed: Optional[int] = None,
    threads: Optional[int] = None,
    max_depth: Optional[int] = None,
    sampler: Optional[str] = None,
    progress: Optional[Callable[[int], Any]] = None,
) -> np.ndarray:
    """Render ``scene`` (a scene file's path, TOML text, or a dict with a scene file's keys)
    to an ``(h, w, 3)`` float32 array of linear radiance, bit for bit the EXR that ``striae
    render`` writes for the same arguments (``res = (w, h)``). ``progress``, if given, is
    called on this thread with the number of camera samples finished since its last call
    (``tqdm(total=w * h * spp).update`` fits). Ctrl-C stops the render and raises
    ``KeyboardInterrupt``; a film larger than the memory the machine leaves (``MemAvailable``,
    ``ulimit -v``, the cgroup's limit) raises ``MemoryError`` naming the limit, before any
    work."""
    kind, source = _scene_source(scene)
    return _striae.render(
        kind, source, spp, _res(res), seed, threads, max_depth, sampler, progress, None
    )


def render_part(
    scene: SceneLike,
    index: int,
    count: int,
    samples: Optional[Tuple[int, int]] = None,
    **settings: Any,
) -> bytes:
    """Render part ``index`` of ``count`` of the image (its tiles ``t % count == index``) and
    return it as the bytes of a part file (``striae render --tile index/count`` writes the
    same bytes); ``samples = (a, b)`` renders only the samples ``a`` to ``b - 1`` of each
    pixel (``--samples a..b``); ``settings`` are :func:`render`'s keywords. :func:`merge`
    joins the parts (parts of sample ranges within Monte Carlo noise of the whole render, not
    bit for bit: docs/distributed.md)."""
    kind, source = _scene_source(scene)
    s = dict(_SETTINGS, **settings)
    if set(s) != set(_SETTINGS):
        raise TypeError(f"unknown settings {sorted(set(s) - set(_SETTINGS))}")
    return _striae.render(
        kind, source, s["spp"], _res(s["res"]), s["seed"], s["threads"], s["max_depth"],
        s["sampler"], s["progress"], (index, count),
        None if samples is None else (int(samples[0]), int(samples[1])),
    )


_SETTINGS = dict(
    spp=None, res=None, seed=None, threads=None, max_depth=None, sampler=None, progress=None
)


def _res(res):
    return None if res is None else (int(res[0]), int(res[1]))


def merge(parts: Sequence[Union[bytes, str, "os.PathLike[str]"]]) -> np.ndarray:
    """The ``(h, w, 3)`` image of every part of one render, given as part-file bytes or paths:
    bit for bit the whole render (within Monte Carlo noise where parts hold sample ranges:
    docs/distributed.md). Raises :class:`StriaeError` for parts of different renders,
    missing or repeated parts, overlapping or missing sample ranges and damaged files."""
    data, names = [], []
    for i, p in enumerate(parts):
        if isinstance(p, (bytes, bytearray, memoryview)):
            data.append(bytes(p))
            names.append(f"<part {i}>")
        else:
            # Read by the library, as `striae merge` reads it: a regular file only, its size
            # checked against its header before the pixels are read.
            data.append(None)
            names.append(os.fspath(p))
    image, _exposure = _striae.merge(data, names)
    return image


def read_exr(path: Union[str, "os.PathLike[str]"]) -> np.ndarray:
    """The RGB pixels of an EXR file as an ``(h, w, 3)`` float32 array."""
    return _striae.read_exr(os.fspath(path))


def write_image(image: np.ndarray, path: Union[str, "os.PathLike[str]"], exposure: float = 0.0):
    """Write ``NAME.exr`` (linear) and ``NAME.png`` (sRGB preview, ``exposure`` stops) for an
    ``(h, w, 3)`` image, both or neither, as ``striae render``."""
    image = np.ascontiguousarray(image, dtype=np.float32)
    base, ext = os.path.splitext(os.fspath(path))
    _striae.write_image(image, base if ext.lower() in (".exr", ".png") else os.fspath(path), exposure)


def hologram(
    points,
    plate: Optional[Sequence[float]] = None,
    view_angle: Optional[float] = None,
    scale: Optional[float] = None,
    span: float = 90.0,
    azimuth: float = 90.0,
    width: Optional[float] = None,
) -> dict:
    """The arcs of a scratch hologram (METHOD.md 9.4, ``docs/hologram.md``), as
    ``striae hologram``: one arc per row ``(x, y, z)`` of ``points`` ``(N, 3)``, the plate
    being ``z = 0`` and ``z > 0`` in front of it (toward the viewer).

    ``plate`` is the drawing's rectangle ``(x0, y0, size_x, size_y)`` (default: fitted around
    the arcs); ``view_angle`` the design angle from the normal in degrees (default 45) or
    ``scale`` the radius over the distance from the plate instead; ``span`` the view azimuths
    each arc covers and ``azimuth`` the direction toward the viewer, in degrees from ``+x``
    toward ``+y``; ``width`` the stroke width in drawing units.

    Returns a dict: ``svg`` (the document), ``centres`` ``(N, 2)``, ``radii``, ``start`` and
    ``end`` (radians, from ``+x`` toward ``+y``), ``z``, ``plate``, ``width``, ``scale`` and
    ``outside`` (arcs reaching out of a given plate)."""
    points = _rows(points, 3)
    return _striae.hologram(
        points,
        None if plate is None else [float(v) for v in plate],
        view_angle,
        scale,
        float(span),
        float(azimuth),
        width,
    )
