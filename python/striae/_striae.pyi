"""Type stubs of the native module ``striae._striae`` (the Rust bindings, crates/striae-py).
The public API is the ``striae`` package, which wraps these."""

from typing import Callable, List, Optional, Tuple

import numpy as np
import numpy.typing as npt

VERSION: str

class StriaeError(Exception):
    """An error of the striae library, with the message the CLI prints (file, key, value)."""

class Table:
    """A scratch BRDF table and its lobe (``ScratchBrdf``)."""

    @staticmethod
    def load(path: str) -> "Table":
        """Read a table file (``.npz``, docs/table-format.md)."""
    def save(self, path: str) -> None:
        """Write the table file atomically."""
    m: int
    phi: npt.NDArray[np.float64]
    theta: npt.NDArray[np.float64]
    rho_m: npt.NDArray[np.float64]
    rho_s: npt.NDArray[np.float64]
    gamma: npt.NDArray[np.float64]
    dropped: npt.NDArray[np.float64]
    params_json: str
    version: str
    is_delta: bool
    def eval(
        self, wo: npt.NDArray[np.float64], wi: npt.NDArray[np.float64]
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``(f, pdf)`` per row of the ``(N, 3)`` arrays ``wo``, ``wi`` (scratch frame)."""
    def sample(
        self, wo: npt.NDArray[np.float64], u: npt.NDArray[np.float64]
    ) -> Tuple[
        npt.NDArray[np.float64],
        npt.NDArray[np.float64],
        npt.NDArray[np.float64],
        npt.NDArray[np.bool_],
    ]:
        """``(wi, weight, pdf, valid)`` per row of ``wo`` ``(N, 3)`` and ``u`` ``(N, 2)``."""

class LayerSet:
    """Scratch layers from Worley noise (METHOD.md section 5)."""

    def __init__(
        self,
        setting: Optional[int] = None,
        layers: int = 8,
        seed: int = 1,
        length: Optional[float] = None,
        width: Optional[float] = None,
        threshold: Optional[float] = None,
    ) -> None: ...
    def __len__(self) -> int: ...
    directions: npt.NDArray[np.float64]
    angles: npt.NDArray[np.float64]
    expected_coverage: float
    def masks(self, res: int) -> npt.NDArray[np.float32]:
        """``(K, res, res)`` float32 coverage masks, row 0 at the top."""
    def coverage(
        self,
        uv: npt.NDArray[np.float64],
        duvdx: npt.NDArray[np.float64],
        duvdy: npt.NDArray[np.float64],
    ) -> npt.NDArray[np.float32]:
        """``(N, K)`` coverage of each footprint, per layer."""

def precompute(
    profile: str,
    walls: str,
    m: int,
    n: int,
    nr: int,
    ior: float,
    fresnel: str,
    fresnel_law: str,
    albedo: float,
    max_bounces: int,
    seed: int,
    estimator: str,
    threads: Optional[int] = None,
) -> Table:
    """Trace a scratch profile into a table (``striae precompute``)."""

def render(
    kind: str,
    source: str,
    spp: Optional[int] = None,
    res: Optional[Tuple[int, int]] = None,
    seed: Optional[int] = None,
    threads: Optional[int] = None,
    max_depth: Optional[int] = None,
    sampler: Optional[str] = None,
    progress: Optional[Callable[[int], object]] = None,
    tile: Optional[Tuple[int, int]] = None,
    samples: Optional[Tuple[int, int]] = None,
) -> object:
    """Render the scene (``kind``: ``"path"``, ``"toml"`` or ``"json"``): an ``(h, w, 3)``
    float32 array, or with ``tile = (index, count)`` that part's file contents (bytes), of the
    samples ``samples = (a, b)`` of each pixel only where given."""

def merge(parts: List[bytes], names: List[str]) -> Tuple[npt.NDArray[np.float32], float]:
    """The image of every part of one render, and the preview exposure they carry."""

def write_image(image: npt.NDArray[np.float32], path: str, exposure: float) -> None:
    """Write ``path.exr`` and ``path.png`` (both or neither)."""

def read_exr(path: str) -> npt.NDArray[np.float32]:
    """An EXR file's RGB pixels as ``(h, w, 3)`` float32."""

def hologram(
    points: npt.NDArray[np.float64],
    plate: Optional[List[float]] = None,
    view_angle: Optional[float] = None,
    scale: Optional[float] = None,
    span: float = 90.0,
    azimuth: float = 90.0,
    width: Optional[float] = None,
) -> dict:
    """The arcs of a scratch hologram for ``(N, 3)`` points: ``svg``, ``centres``, ``radii``,
    ``start``, ``end``, ``z``, ``plate``, ``width``, ``scale``, ``outside``."""
