"""Spectral clustering of contact points by their wrench cones (Phoka & Sudsang, Section III-B).

- `cone_distance`: d(i, j) = M(i, j) / m, M the minimum over cyclic shifts x of the summed angles between
  matched primitive wrenches w(f_ik, r_i, c) and w(f_j(k+x), r_j, c), torques about the pair's centroid c.
- `affinity`: a(i, j) = exp(-d(i, j) / 2 sigma^2), sigma the mean of all d(i, j).
- `spectral_clustering`: Ng-Jordan-Weiss [9]: L = D^-1/2 A D^-1/2, the eigenvectors of its k largest
  eigenvalues, rows normalised to U, k-means on the rows of U.
- `cluster_contacts`: all of it, plus the representative of each cluster (the row of U closest to its
  centre), the matrix E of distances from every row of U to every centre, and the tables T_O (the contact
  points with their cluster) and T_R (the representatives).

The torque term is the paper's, (r - c) x f in metres (`torque_scale="none"`, the default). Dividing the torque
arms by the object's radius (`torque_scale="radius"`, as `forceclosure` does for its own, scale-free test) makes
the angles independent of the part's size but is not in the paper; it is kept as an option and both are measured
by `workbench bench fingers` (cluster agreement, %run, #connect).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh

from workbench.errors import WorkbenchError
from workbench.params import Params, check_memory, memory_budget, param, single_blas
from workbench.planners.phoka_sudsang.contacts import ContactSet
from workbench.planners.phoka_sudsang.forceclosure import FrictionParams, friction_pyramid

MAX_CONTACTS = 4000
TORQUE_SCALES = ("none", "radius")


class ClusteringError(WorkbenchError):
    """Clustering parameters that do not fit the contact set."""


@dataclass(frozen=True)
class ClusterParams(Params):
    """k clusters of contacts for friction `mu` and an m-sided pyramid (`sides`); `seed` for k-means."""

    k: int = param(50, ge=4, le=MAX_CONTACTS, integer=True, flag="--clusters",
                   help="number of clusters k (at least the 4 representatives a grasp needs)")
    mu: float = param(0.3, gt=0, le=10, help="Coulomb friction coefficient", flag="--friction")
    sides: int = param(8, ge=3, le=64, integer=True, help="sides m of the friction pyramid", flag="--pyramid")
    seed: int = param(0, ge=0, le=2**32 - 1, integer=True, help="k-means seed")
    n_init: int = param(10, ge=1, le=1000, integer=True, help="k-means restarts")
    torque_scale: str = "none"

    @property
    def friction(self) -> FrictionParams:
        return FrictionParams(self.mu, self.sides)

    def validate(self, n_contacts: int) -> "ClusterParams":
        self.friction.validate()
        if int(self.k) != self.k or self.k < 1:
            raise ClusteringError(f"number of clusters {self.k!r} must be a positive integer (e.g. --clusters 50)")
        if self.k > n_contacts:
            raise ClusteringError(f"{self.k} clusters is more than the {n_contacts} contact points; "
                                  f"lower --clusters or keep more triangles (--faces)")
        if n_contacts > MAX_CONTACTS:
            raise ClusteringError(f"{n_contacts} contact points are too many to cluster (the distance matrix grows as N^2 m^2); "
                                  f"decimate the mesh to about 500 triangles (--faces 500)")
        if self.torque_scale not in TORQUE_SCALES:
            raise ClusteringError(f"torque scaling {self.torque_scale!r} is not one of {', '.join(TORQUE_SCALES)} "
                                  f"(none: the paper's d(i, j); radius: torque arms divided by the object's radius)")
        if self.k < 4:
            raise ClusteringError(f"{self.k} clusters give fewer than the 4 representatives a grasp needs; use --clusters 4 or more")
        return self


@dataclass(frozen=True)
class Clustering:
    """The result of Section III-B: T_O (labels), T_R (reps), U, the centres and E."""

    labels: np.ndarray      # (N,) cluster of every contact (T_O)
    reps: np.ndarray        # (k,) representative contact of every cluster (T_R)
    embedding: np.ndarray   # (N, k) rows of U
    centers: np.ndarray     # (k, k) k-means centres in U space
    E: np.ndarray           # (N, k) distance of every row of U to every centre
    sigma: float

    @property
    def k(self) -> int:
        return int(len(self.reps))

    def members(self, cluster: int) -> np.ndarray:
        """The contacts of one cluster (the set S of a local roadmap)."""
        return np.flatnonzero(self.labels == cluster)


def cone_distance(points: np.ndarray, normals: np.ndarray, mu: float, sides: int, length: float = 1.0,
                  chunk: int = 64) -> np.ndarray:
    """(N, N) wrench-cone distance d(i, j) of Section III-B1 (symmetric, zero diagonal).

    With h = (r_i - r_j) / 2 the wrenches about the centroid are (a, h x a) and (b, -h x b) for edges a, b, so
    their inner product is (1 - |h|^2) a.b + (h.a)(h.b) and their norms sqrt(1 + |h|^2 - (h.a)^2).
    """
    p = np.asarray(points, dtype=np.float64) / length
    n, m = len(p), int(sides)
    # memory: the (N, m, N) projections and (N, N) results, then per block row about 5 float32 arrays of
    # (rows, N, m, m) in each of the 2 threads; the block shrinks to fit the budget, or the work is refused
    fixed = 12.0 * n * n * m + 24.0 * n * n
    per_row = 2 * 5 * 4.0 * n * m * m
    check_memory(fixed + per_row, f"the wrench-cone distances of {n} contacts with {m}-sided pyramids",
                 "lower --pyramid or keep fewer triangles (--faces)")
    chunk = int(max(1, min(chunk, (memory_budget() - fixed) // per_row)))
    f = friction_pyramid(normals, mu, sides)                     # (N, m, 3)
    ff = f.reshape(-1, 3)
    own = np.einsum("nkc,nc->nk", f, p) / 2.0                   # f_ik . r_i / 2
    cross = (ff @ p.T).reshape(n, m, n) / 2.0                   # f_ik . r_j / 2
    sq = (p ** 2).sum(1)
    # flat index of (k, k + x) in an m x m block, ordered by shift x then k
    perm = (np.arange(m)[None, :] * m + (np.arange(m)[None, :] + np.arange(m)[:, None]) % m).ravel()
    # the angles only rank pairs for clustering: float32 halves the cost of arccos and of memory traffic
    f32, own32, cross32 = f.astype(np.float32), own.astype(np.float32), cross.astype(np.float32)
    out = np.zeros((n, n))

    def rows(s: int) -> None:
        i = np.arange(s, min(n, s + chunk))
        j = np.arange(s, n)                                     # upper triangle only, mirrored below
        c, r = len(i), len(j)
        ab = (f32[i].reshape(-1, 3) @ f32[j].reshape(-1, 3).T).reshape(c, m, r, m).transpose(0, 2, 1, 3)
        hh = ((sq[i, None] + sq[None, j] - 2.0 * p[i] @ p[j].T) / 4.0).astype(np.float32)   # |h|^2, (c, r)
        si = own32[i][:, None, :] - cross32[i][:, :, j].transpose(0, 2, 1)   # h . f_ik, (c, r, m)
        sj = cross32[j][:, :, i].transpose(2, 0, 1) - own32[j][None, :, :]   # h . f_jl, (c, r, m)
        ni = 1.0 / np.sqrt(np.maximum(1.0 + hh[..., None] - si ** 2, 1e-30))
        nj = 1.0 / np.sqrt(np.maximum(1.0 + hh[..., None] - sj ** 2, 1e-30))
        cos = ab * (1.0 - hh)[..., None, None]
        cos += si[..., :, None] * sj[..., None, :]
        cos *= ni[..., :, None]
        cos *= nj[..., None, :]
        np.clip(cos, -1.0, 1.0, out=cos)
        ang = np.arccos(cos).reshape(c, r, m * m)[..., perm].reshape(c, r, m, m)
        out[s:s + c, s:] = ang.sum(axis=-1, dtype=np.float64).min(axis=-1) / m

    # numpy releases the GIL in these array operations: two threads take alternate row blocks
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as pool:
        list(pool.map(rows, range(0, n, chunk)))
    out = np.triu(out, 1)
    return out + out.T


def affinity(d: np.ndarray) -> tuple[np.ndarray, float]:
    """Affinity a(i, j) = exp(-d / 2 sigma^2) with sigma the mean of d over all N^2 pairs (Section III-B1).

    The diagonal is zero as in Ng-Jordan-Weiss step 1.
    """
    sigma = float(d.mean())
    if sigma <= 0:
        raise ClusteringError("all contact points have the same wrench cone; nothing to cluster")
    a = np.exp(-d / (2.0 * sigma ** 2))
    np.fill_diagonal(a, 0.0)
    return a, sigma


@single_blas
def spectral_clustering(a: np.ndarray, k: int, seed: int = 0, n_init: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """NJW spectral clustering (Section III-B2, [9]): labels (N,), U (N, k), centres (k, k)."""
    from sklearn.cluster import (
        KMeans,  # imported here: scikit-learn takes a while to load
    )

    deg = a.sum(axis=1)
    inv = 1.0 / np.sqrt(np.where(deg > 0, deg, 1.0))
    lap = inv[:, None] * a * inv[None, :]
    n = len(a)
    _, v = eigh(lap, subset_by_index=[n - k, n - 1])
    v = v[:, ::-1]                                               # largest eigenvalue first
    u = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)
    km = KMeans(n_clusters=k, n_init=n_init, random_state=seed).fit(u)
    return km.labels_.astype(np.int64), u, km.cluster_centers_


@single_blas
def cluster_contacts(contacts: ContactSet, params: ClusterParams = ClusterParams(), length: float | None = None) -> Clustering:
    """Cluster T_O into k groups and pick T_R, the representatives (Section III-B). `length` overrides the divisor
    of the torque arms that `params.torque_scale` picks (1 m: the paper's d(i, j))."""
    params.validate(len(contacts))
    if length is None:
        length = contacts.radius if params.torque_scale == "radius" else 1.0
    d = cone_distance(contacts.points, contacts.normals, params.mu, params.sides, length)
    a, sigma = affinity(d)
    labels, u, centers = spectral_clustering(a, params.k, params.seed, params.n_init)
    present = np.unique(labels)
    if len(present) < params.k:
        raise ClusteringError(f"k-means found only {len(present)} distinct clusters of the {params.k} asked; lower --clusters")
    e = np.linalg.norm(u[:, None, :] - centers[None, :, :], axis=2)
    own = np.where(labels[:, None] == np.arange(params.k)[None, :], e, np.inf)
    reps = own.argmin(axis=0).astype(np.int64)
    return Clustering(labels=labels, reps=reps, embedding=u, centers=centers, E=e, sigma=sigma)
