"""The part's collision shape for physics: a convex decomposition (CoACD), cached on disk by mesh digest
(CONVENTIONS.md, Simulation).

CoACD takes seconds to tens of seconds per part, so every decomposition is written once to
`$WORKBENCH_CACHE/coacd/DIGEST-PARAMS.npz` (default `~/.cache/workbench`) and read back on every later plan of
the same mesh. A file is written under a temporary name and renamed, so it is whole or absent.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from workbench.errors import SimulationError

CACHE_ENV = "WORKBENCH_CACHE"


@dataclass(frozen=True)
class Decomposition:
    """CoACD's settings (threshold: the concavity each part may keep, relative to the part's size)."""

    threshold: float = 0.1
    max_hulls: int = 16
    preprocess_resolution: int = 30
    mcts_iterations: int = 60
    seed: int = 0

    @property
    def key(self) -> str:
        return hashlib.sha256(json.dumps(self.__dict__, sort_keys=True).encode()).hexdigest()[:12]


def cache_dir() -> Path:
    """Where decompositions are kept: $WORKBENCH_CACHE/coacd, default ~/.cache/workbench/coacd."""
    root = os.environ.get(CACHE_ENV) or Path.home() / ".cache" / "workbench"
    return Path(root) / "coacd"


def convex_parts(mesh: trimesh.Trimesh, digest: str, name: str, opts: Decomposition = Decomposition(),
                 folder: Path | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Convex parts (vertices, faces) in the part's frame covering `mesh`; computed once per mesh digest and
    settings, then read from the cache. A decomposition that fails or yields no solid part raises one
    SimulationError naming the mesh `name`."""
    path = (folder or cache_dir()) / f"{digest}-{opts.key}.npz"
    if path.is_file():
        with np.load(path) as z:
            counts = z["counts"]
            verts, faces = np.split(z["vertices"], np.cumsum(counts[:, 0])[:-1]), np.split(z["faces"], np.cumsum(counts[:, 1])[:-1])
            return list(zip(verts, faces))
    parts = _decompose(mesh, name, opts)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
    np.savez(tmp, vertices=np.concatenate([v for v, _ in parts]), faces=np.concatenate([f for _, f in parts]),
             counts=np.array([(len(v), len(f)) for v, f in parts], dtype=np.int64))
    os.replace(tmp, path)
    return parts


def _decompose(mesh: trimesh.Trimesh, name: str, opts: Decomposition) -> list[tuple[np.ndarray, np.ndarray]]:
    """CoACD in a child process: on some degenerate meshes it aborts the whole process, which here is one error."""
    try:
        import coacd  # noqa: F401
    except ImportError:
        raise SimulationError("the convex decomposition needs coacd: pip install 'regrasp-workbench[physics]'") from None
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int32)
    if len(f) < 4 or not np.isfinite(v).all():
        raise SimulationError(f"convex decomposition of mesh {name!r} failed: {len(f)} faces; repair or replace the mesh")
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    try:
        with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context(method)) as pool:
            raw = pool.submit(_run_coacd, v, f, opts).result()
    except BrokenProcessPool:
        raise SimulationError(f"convex decomposition of mesh {name!r} failed (CoACD aborted on it at remeshing resolution "
                              f"{opts.preprocess_resolution}: too coarse a --hull-resolution, or a flat, open or "
                              f"self-intersecting mesh?); raise --hull-resolution, or repair or replace the mesh") from None
    except Exception as exc:  # CoACD reports bad input as RuntimeError with a C++ message
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise SimulationError(f"convex decomposition of mesh {name!r} failed ({first}); repair or replace the mesh") from None
    scale = float(np.ptp(v, axis=0).max())
    parts = []
    for pv, pf in raw:
        pv, pf = np.asarray(pv, dtype=np.float64), np.asarray(pf, dtype=np.int64)
        if len(pv) >= 4 and np.isfinite(pv).all() and _volume(pv) > (1e-4 * scale) ** 3:
            parts.append((pv, pf))
    if not parts:
        raise SimulationError(f"convex decomposition of mesh {name!r} failed: no solid convex part (a flat or open mesh?); "
                              f"repair or replace the mesh")
    return parts


def _run_coacd(v: np.ndarray, f: np.ndarray, opts: Decomposition) -> list:
    import faulthandler

    import coacd

    faulthandler.disable()  # an abort of CoACD is reported by the parent in one line, not as a C-level dump here
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 2)
    coacd.set_log_level("error")
    out = coacd.run_coacd(coacd.Mesh(v, f), threshold=opts.threshold, max_convex_hull=opts.max_hulls,
                          preprocess_resolution=opts.preprocess_resolution, mcts_iterations=opts.mcts_iterations, seed=opts.seed)
    return [(np.asarray(a), np.asarray(b)) for a, b in out]


def _volume(v: np.ndarray) -> float:
    try:
        return float(trimesh.convex.convex_hull(v).volume)
    except Exception:  # qhull refuses flat point sets
        return 0.0
