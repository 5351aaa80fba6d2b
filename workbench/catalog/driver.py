"""The catalogue's driver: schedules units on a Dask cluster, resumes by digest, is the single store writer.

Units: one per part (grasps, placements, tabletop grips; Wan & Harada Sections III-IV), one per chunk of a part's
tabletop grips and robot (IK with retractions, Section IV), one per part and robot (the regrasp graph's size,
Section V, a few milliseconds: the driver computes it from the run's stored rows when its last IK chunk is in, in
the transaction of the run's shard merge when there is one, cheaper than a worker's round trip). Workers return Arrow tables; the driver writes each finished unit and its `catalog_unit` row in one
transaction through the stage writers of `workbench.store`, so a unit is stored whole or not at all (a part and
robot's IK chunks are held and written together with its graph, one commit per run). Units whose
digest is stored are skipped, so a re-run after a crash computes only the rest. A task on a worker that dies is
rescheduled by the Dask scheduler on another worker; a unit that raises (a broken mesh) is recorded as failed with
its one-line reason and the others go on.
"""

from __future__ import annotations

import hashlib
import json
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np
import pyarrow as pa

from workbench.catalog import stages
from workbench.catalog.progress import Progress
from workbench.catalog.robots import CatalogRobot, parse_robots
from workbench.catalog.units import (
    graph_unit,
    ik_unit,
    part_from_tables,
    part_unit,
    table_arrays,
)
from workbench.errors import WorkbenchError
from workbench.geometry.objects import ObjectModel, resolve_scale
from workbench.grasping.grasps import GraspParams
from workbench.grasping.placements import PlacementParams
from workbench.planners.wan_harada.stages import HANDX, WORLDZ
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.gripper import franka_hand
from workbench.robots.ik import (
    WORLDA,
    IKOptions,
    check_poses,
    chunk_bounds,
    neighbour_order,
)

MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf", ".dae")
PART_PRIORITY = 1 << 40  # Dask priorities (higher runs first): parts, then IK chunks by their length
HOLD_MAX = 16  # IK units of one (part, robot) held in memory at most before they are written without its graph
SHARD_SUFFIX = ".parquet"


class CatalogError(WorkbenchError):
    """Bad input to `workbench catalog` (no parts, unknown robot, bad chunk size)."""


@dataclass(frozen=True)
class CatalogParams:
    """Every parameter of a catalogue build; `ik_chunk` tabletop grips per IK unit (the rows equal those of a serial
    run whatever the chunk: each grip is solved on its own)."""

    grasps: GraspParams = GraspParams()
    placements: PlacementParams = PlacementParams()
    tabletop: TabletopParams = TabletopParams()
    ik: IKOptions = IKOptions(self_collide=True)  # as `workbench build` and `workbench ik` solve: the same rows
    handx: float = HANDX
    worldz: float = WORLDZ
    worlda: float = WORLDA
    ik_chunk: int = 1024
    scale: float | None = None
    units: str | None = None

    def __post_init__(self) -> None:
        if self.ik_chunk < 1:
            raise CatalogError(f"IK chunk must be a positive number of grips, got {self.ik_chunk}")
        for label, v in (("handx", self.handx), ("worldz", self.worldz), ("worlda", self.worlda)):
            if not (np.isfinite(v) and v >= 0):
                raise CatalogError(f"--{label} must be a distance >= 0 m, got {v}")
        resolve_scale(self.scale, self.units)  # a bad scale or unit is refused before any part is loaded

    def part_dict(self) -> dict:
        return {"grasps": self.grasps.as_dict(), "placements": self.placements.as_dict(), "tabletop": self.tabletop.as_dict(),
                "scale": self.scale, "units": self.units}


@dataclass
class CatalogResult:
    """What a build did: the summary rows (parts x robots), failures, units computed and skipped, seconds of wall
    time, of worker compute (wall and CPU) per unit kind and of the driver's work on finished units (`write_seconds`,
    split in `driver`: decoding the Arrow results, writing rows, committing, scheduling the units that depend on them,
    merging Parquet shards), rows written and write transactions (`batches`, and `merges` of shards)."""

    rows: list[dict]
    failures: list[dict]
    computed: dict = field(default_factory=lambda: {"part": 0, "ik": 0, "graph": 0})
    skipped: int = 0
    wall: float = 0.0
    compute: dict = field(default_factory=lambda: {"part": 0.0, "ik": 0.0, "graph": 0.0})
    write_seconds: float = 0.0
    rows_written: int = 0
    batches: int = 0
    driver: dict = field(default_factory=lambda: {"decode": 0.0, "rows": 0.0, "commit": 0.0, "schedule": 0.0, "merge": 0.0,
                                                  "graph": 0.0})
    # ... and the same driver seconds by the kind of unit they served (`driver_kind`): a part's rows and scheduling its
    # IK chunks; an IK chunk's rows (or note and merge); preparing and writing a graph
    workers: int = 0
    dashboard: str = ""
    cpu: dict = field(default_factory=lambda: {"part": 0.0, "ik": 0.0, "graph": 0.0})
    timeline: list = field(default_factory=list)  # (worker, kind, start, end) epoch seconds of every computed unit
    start: float = 0.0  # epoch seconds when the build started scheduling
    merges: int = 0
    shards: str | None = None
    driver_kind: dict = field(default_factory=lambda: {"part": 0.0, "ik": 0.0, "graph": 0.0})  # driver s per unit kind


def collect_parts(paths: Sequence[str | Path | tuple[str | Path, float]]) -> list[tuple[Path, float | None]]:
    """(mesh file, scale or None) for mesh files given directly or found (not recursively) in the given folders,
    sorted within each folder; an entry may be a (path, scale) pair to override the build's scale for it."""
    out: list[tuple[Path, float | None]] = []
    for item in paths:
        p, scale = (Path(item[0]), float(item[1])) if isinstance(item, tuple) else (Path(item), None)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.suffix.lower() in MESH_SUFFIXES and q.is_file())
            if not found:
                raise CatalogError(f"folder {p} holds no mesh files ({', '.join(MESH_SUFFIXES)})")
            out.extend((q, scale) for q in found)
        else:
            out.append((p, scale))  # a missing or broken file is reported as that part's failure
    if not out:
        raise CatalogError("no parts given: pass mesh files or folders of them")
    stems = [p.stem for p, _ in out]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise CatalogError(f"several parts are named {', '.join(dup)} (the file name is the part's name); rename them")
    return out


def catalog_robots(robots: str | Sequence[str] | dict[str, CatalogRobot]) -> dict[str, CatalogRobot]:
    """The catalogue's columns: given as parsed (`workbench.catalog.robots.parse_robots`), or parsed from names."""
    return robots if isinstance(robots, dict) else parse_robots(robots)


def _digest(*parts: object) -> str:
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:32]


def _file_digest(path: Path) -> str:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return "unreadable"


def one_line(exc: BaseException) -> str:
    """A failure's one-line reason: the message of a WorkbenchError, else the exception type and first line."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    if isinstance(exc, WorkbenchError):
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class _Build:
    """The state of one build: the store, the client, what is stored, what runs."""

    def __init__(self, store, client, robots: dict[str, CatalogRobot], params: CatalogParams, progress: bool,
                 on_unit: Callable[[str, dict], None] | None, shards: Path | None = None):
        from distributed import as_completed
        self.store, self.client, self.robots, self.params = store, client, robots, params
        self.on_unit = on_unit
        self.done = stages.done_units(store)
        self.rows = stages.unit_digests(store)  # digests with a catalog_unit row (done or failed), kept by this writer
        self.pending: dict = {}  # future -> unit dict
        self.left: dict[tuple[str, str], int] = {}  # (part, robot) -> IK chunks not finished yet
        self.broken: set[tuple[str, str]] = set()  # runs with a failed IK chunk: their graph waits for a re-run
        self.held: dict[tuple[str, str], list] = {}  # (part, robot) -> finished IK units not written yet (direct path)
        self.runs: dict[tuple[str, str], dict] = {}
        self.ik_runs: dict[str, dict] = {}  # robot name -> its run's ids in this store
        self.ac = as_completed(with_results=True, raise_errors=False)  # results fetched in the background
        self.result = CatalogResult(rows=[], failures=[])
        self.bar = Progress(progress)
        self.hand = franka_hand()
        self.shards = shards
        self._stack: list[float] = []  # seconds of nested `charge` blocks, innermost last
        self.on_disk: dict[str, Path] = {}  # digest -> shard file of an IK unit computed but not merged yet
        self.to_merge: dict[tuple[str, str], list[tuple[dict, Path]]] = {}  # (part, robot) -> its IK units on disk
        if shards is not None:
            self.on_disk = open_shards(shards, self.done)
            self.result.shards = str(shards)

    @contextmanager
    def charge(self, kind: str, what: str) -> Iterator[None]:
        """Count the block's seconds (less those of nested blocks) as driver time of `what` for a unit of `kind`; the
        outermost blocks add up to `write_seconds`."""
        t0 = time.perf_counter()
        self._stack.append(0.0)
        try:
            yield
        finally:
            dt = time.perf_counter() - t0
            own = dt - self._stack.pop()
            self.result.driver_kind[kind] += own
            self.result.driver[what] += own
            if self._stack:
                self._stack[-1] += dt
            else:
                self.result.write_seconds += dt

    # -- scheduling --------------------------------------------------------------------------------------------
    def _skip(self, kind: str) -> None:
        self.result.skipped += 1
        self.bar.skipped(kind)

    def _submit(self, unit: dict, fn, *args, priority: int = 0, **kwargs) -> None:
        key = f"{unit['kind']}-{unit['part']}-{unit.get('robot') or ''}-{unit.get('chunk') or 0}-{unit['digest'][:12]}"
        # pure=False: a retry after a crash must not reuse a result the cluster still holds under the same key.
        # priority: parts first (they unlock the IK units; the largest file first), then IK chunks longest first, so
        # the last units to run are the short ones (a run's graph is computed by the driver when its last chunk is in).
        fut = self.client.submit(fn, *args, key=key, pure=False, priority=priority, **kwargs)
        self.pending[fut] = unit
        self.ac.add(fut)
        self.bar.add(unit["kind"])

    def submit_part(self, path: Path, scale: float | None) -> None:
        p = self.params
        units = p.units if scale is None else None
        scale = p.scale if scale is None else scale
        digest = _digest("part", _file_digest(path), path.stem, self.hand.digest,
                         {**p.part_dict(), "scale": scale, "units": units})
        unit = {"digest": digest, "kind": "part", "part": path.stem, "source": str(path)}
        if digest in self.done:
            self._skip("part")
            self.schedule_robots(self.done[digest])
            return
        size = path.stat().st_size if path.is_file() else 0
        self._submit(unit, part_unit, str(path), path.stem, scale, units, p.grasps, p.placements, p.tabletop,
                     priority=PART_PRIORITY + min(size, PART_PRIORITY - 1))

    def schedule_robots(self, part: dict, obj: ObjectModel | None = None) -> None:
        """IK chunk units of a stored part for every robot (and the graph units of runs already complete)."""
        with self.charge("part", "schedule"):
            self._schedule_robots(part, obj)

    def _schedule_robots(self, part: dict, obj: ObjectModel | None) -> None:
        p = self.params
        grips, obj = stages.part_grips(self.store, part, obj)
        n = len(grips["idtabletopgrips"])
        order = neighbour_order(grips)
        poses = check_poses(grips["rotmat"])
        places = check_poses(grips["placement_rotmat"], "object placement")
        ids = np.asarray(grips["idtabletopgrips"], dtype=np.int64)
        verts, faces = np.asarray(obj.mesh.vertices, dtype=np.float64), np.asarray(obj.mesh.faces, dtype=np.int64)
        for name, column in self.robots.items():
            robot, scene = column.robot, column.scene
            if name not in self.ik_runs:  # robot, scene and ikret rows: once per build
                self.ik_runs[name] = stages.ik_run(self.store, robot, scene, p.ik, p.handx, p.worldz, p.worlda)
            ids_run = self.ik_runs[name]
            stored = stages.stored_ik(self.store, ids_run, part["idtabletop"], part.get("new_tabletop", False))
            run = {"part": part["part"], "robot": name, "idobject": part["idobject"], "idtabletop": part["idtabletop"],
                   "idgrasps": part["idgrasps"], "idplacements": part["idplacements"], "source": part.get("source"),
                   "idrobot": ids_run["idrobot"], "idscene": ids_run["idscene"], "idikret": ids_run["idikret"],
                   "stored": stored, "base": _digest(part["digest"], robot.spec.digest, ids_run["scene_params"], p.handx,
                                                     p.worldz, p.worlda, p.ik_chunk)}
            self.runs[(part["part"], name)] = run
            run["nq"] = robot.nq
            left, key = 0, (part["part"], name)
            self.to_merge[key] = []
            for k, (s, e) in enumerate(chunk_bounds(n, p.ik_chunk)):
                unit = {**_unit_ids(run), "kind": "ik", "chunk": k, "digest": _digest(run["base"], "ik", k, n)}
                if unit["digest"] in self.done:
                    self._skip("ik")
                    continue
                ix = order[s:e]
                if self.shards is not None:
                    unit["nrows"] = int((~np.isin(ids[ix], stored)).sum())
                    if unit["digest"] in self.on_disk:  # computed by an earlier run, not merged yet
                        self._skip("ik")
                        self.to_merge[key].append((unit, self.on_disk.pop(unit["digest"])))
                        continue
                left += 1
                extra = {} if self.shards is None else {"shard": str(shard_path(self.shards, unit["digest"]))}
                self._submit(unit, ik_unit, robot.spec, scene, p.ik, p.handx, p.worldz, p.worlda, obj.digest, verts,
                             faces, ids[ix], poses[ix], places[ix], priority=len(ix), **extra)
            self.left[key] = left
            if left == 0:
                self.finish_run(run)

    def graph(self, run: dict) -> Callable[[], None]:
        """The run's regrasp-graph sizes (a few milliseconds), computed here from the rows the caller's transaction
        can read and written in it: a worker round trip and a commit of their own would cost more. Returns what to
        do once committed."""
        unit = {**_unit_ids(run), "kind": "graph", "digest": _digest(run["base"], "graph")}
        if unit["digest"] in self.done:
            self._skip("graph")
            return lambda: None
        self.bar.add("graph")
        with self.charge("graph", "graph"):
            rows, feasible = stages.graph_inputs(self.store, run)
            table = graph_unit(rows, feasible)
        with self.charge("graph", "rows"):
            self.write_rows(unit, table)

        def after() -> None:
            self.done[unit["digest"]] = unit
            self.rows.add(unit["digest"])
            meta = {k: v for k, v in unit.pop("meta", {}).items() if k not in (b"start", b"end")}  # not a worker's
            self._account(unit, meta)
            self.bar.done("graph")
            if self.on_unit is not None:
                self.on_unit("graph", unit)
        return after

    def finish_run(self, run: dict) -> None:
        """Every IK chunk of a (part, robot) is finished: write the held ones (direct path) or merge the shards, and
        the graph, in one transaction; a run with a failed chunk gets no graph (shards stay on disk for a re-run)."""
        key = (run["part"], run["robot"])
        if self.shards is None:
            self.write_batch(self.held.pop(key, []), None if key in self.broken else run)
            return
        if key in self.broken:
            return
        units = self.to_merge.pop(key, [])
        if units:
            for unit, _ in units:
                unit["fresh"] = unit["digest"] not in self.rows
            try:
                with self.charge("ik", "merge"), stages.batch(self.store):  # the merge and its graph commit together
                    n = stages.merge_ik_shards(self.store, run, units)
                    then = self.graph(run)
            except WorkbenchError as exc:  # an unreadable shard: the run's chunks are computed again by a re-run
                for unit, path in units:
                    path.unlink(missing_ok=True)
                    stages.record_failure(self.store, {**unit, "fresh": False}, one_line(exc))
                    self.rows.add(unit["digest"])
                self.broken.add(key)
                return
            self.result.merges += 1
            self.result.rows_written += n
            for unit, path in units:
                self.done[unit["digest"]] = unit
                self.rows.add(unit["digest"])
                path.unlink(missing_ok=True)
            then()
            return
        with self.charge("graph", "commit"), stages.batch(self.store):
            then = self.graph(run)
        then()

    # -- writing -------------------------------------------------------------------------------------------------
    def write_rows(self, unit: dict, result) -> Callable[[], None]:
        """Write a part or graph unit's rows and its catalog_unit row (joining the caller's transaction); returns what
        to do once committed (schedule the units that depend on it). IK units go through `write_iks`."""
        if self._stamp(unit, result) == "part":
            return self.write_part(unit, result)
        stages.write_graph(self.store, unit, {k: v[0] for k, v in result.to_pydict().items()})
        return lambda: None

    def _stamp(self, unit: dict, result) -> str:
        """Note whether the unit's row is new and its worker's timings; returns its kind."""
        kind = unit["kind"]
        unit["fresh"] = unit["digest"] not in self.rows
        meta = (result["meta"] if kind == "part" else result).schema.metadata or {}
        unit.update(seconds=float(meta.get(b"seconds", b"0")), worker=meta.get(b"worker", b"").decode(), meta=meta)
        return kind

    def write_part(self, unit: dict, tables: dict[str, pa.Table]) -> Callable[[], None]:
        with self.charge("part", "decode"):
            res = part_from_tables(tables)
        p = self.params
        stages.write_part(self.store, unit, res, self.hand, p.grasps, p.placements, p.tabletop)

        def after() -> None:
            self.done[unit["digest"]] = unit
            self.schedule_robots(unit, res.obj)  # the mesh as stored (its digest is the stored one)
        return after

    def write_iks(self, units: list[dict], tables: list[pa.Table]) -> None:
        """IK units (stamped) of one part and robot: their rows in one `ik` insert, and their catalog_unit rows."""
        with self.charge("ik", "decode"):
            cols = [table_arrays(t) for t in tables]
        run = self.runs[(units[0]["part"], units[0]["robot"])]
        stages.write_ik(self.store, units, [(c["idtabletopgrips"], c["feasible"], c["joints"]) for c in cols],
                        run["stored"])

    def hold(self, fut, unit: dict, result) -> None:
        """A finished IK unit (direct path): held until its run's last chunk is in, then written with the others and
        the run's graph in one transaction (one commit per run, not per chunk); `HOLD_MAX` bounds what a killed
        driver loses (units not written are computed again by the re-run)."""
        key = (unit["part"], unit["robot"])
        self.held.setdefault(key, []).append((fut, unit, result))
        self._chunk_done(key)
        if key in self.held and len(self.held[key]) >= HOLD_MAX:
            self.write_batch(self.held.pop(key))

    def _chunk_done(self, key: tuple[str, str]) -> None:
        self.left[key] -= 1
        if self.left[key] == 0:
            self.finish_run(self.runs[key])

    def shard_done(self, fut, unit: dict, table: pa.Table) -> None:
        """An IK unit whose worker wrote its rows to a shard: note it; merge its run when it is the run's last."""
        with self.charge("ik", "schedule"):
            meta = table.schema.metadata or {}
            row = table.to_pylist()[0]
            unit.update(counts={k: int(row[k]) for k in ("grips", "feasible", "feasible_all")})
            self._account(unit, meta)
            key = (unit["part"], unit["robot"])
            self.to_merge[key].append((unit, Path(meta[b"shard"].decode())))
            fut.release()
            self.bar.done("ik")
            self._chunk_done(key)
        if self.on_unit is not None:
            self.on_unit("ik", unit)

    def _account(self, unit: dict, meta: dict) -> None:
        """A computed unit's worker seconds, CPU seconds and place on the workers' timeline."""
        kind = unit["kind"]
        unit.update(seconds=float(meta.get(b"seconds", b"0")), worker=meta.get(b"worker", b"").decode())
        self.result.computed[kind] += 1
        self.result.compute[kind] += unit["seconds"]
        self.result.cpu[kind] += float(meta.get(b"cpu", b"0"))
        if b"start" in meta:
            self.result.timeline.append((unit["worker"], kind, float(meta[b"start"]), float(meta[b"end"])))

    def write_batch(self, items: list[tuple[object, dict, object]], run: dict | None = None) -> None:
        """Write finished units in one transaction (each unit whole, so they share the commit's cost), with `run`'s
        graph when given (its IK chunks are all among them or stored); if one of them cannot be written, write them
        one by one (and leave the graph to a re-run)."""
        graph_done = None
        try:
            with stages.batch(self.store):
                after: list = []
                iks: dict[tuple[str, str], list] = {}  # IK units by part and robot: one insert each
                for _, unit, result in items:
                    if unit["kind"] == "ik":
                        self._stamp(unit, result)
                        iks.setdefault((unit["part"], unit["robot"]), []).append((unit, result))
                        after.append(lambda: None)
                        continue
                    with self.charge(unit["kind"], "rows"):
                        after.append(self.write_rows(unit, result))
                for group in iks.values():
                    with self.charge("ik", "rows"):
                        self.write_iks([u for u, _ in group], [r for _, r in group])
                if run is not None:
                    graph_done = self.graph(run)
                t1 = time.perf_counter()
        except Exception as exc:  # noqa: BLE001 - one part's rows that cannot be stored must not stop the others
            if len(items) > 1:
                for item in items:
                    self.write_batch([item])
                return
            if not items:  # the graph alone
                raise
            self.fail(items[0][1], exc, counted=True)
            items[0][0].release()
            return
        commit = time.perf_counter() - t1  # shared by the batch's units
        self.rows.update(unit["digest"] for _, unit, _ in items)
        self.result.driver["commit"] += commit
        self.result.write_seconds += commit
        kinds = [unit["kind"] for _, unit, _ in items] + (["graph"] if run is not None else [])
        for kind in kinds:
            self.result.driver_kind[kind] += commit / len(kinds)
        for (fut, unit, _), then in zip(items, after):
            try:
                with self.charge(unit["kind"], "schedule"):
                    then()
            except WorkbenchError as exc:  # e.g. a part whose tabletop grips are not rigid poses: its IK cannot start
                self.fail({**unit, "kind": "ik", "digest": unit["digest"] + "-schedule"}, exc)
            fut.release()
            kind = unit["kind"]
            self.result.rows_written += int(unit.get("nrows") or 0)
            self._account(unit, unit.pop("meta", {}))
            self.bar.done(kind)
            if self.on_unit is not None:
                self.on_unit(kind, unit)
        if graph_done is not None:
            graph_done()
        self.result.batches += 1
        if self.result.write_seconds > 0:
            self.bar.note(f"{self.result.rows_written / self.result.write_seconds:,.0f} rows/s written")

    def fail(self, unit: dict, exc: BaseException, counted: bool = False) -> None:
        """Record a unit that raised or could not be written (`counted`: an IK unit already counted as finished)."""
        reason = one_line(exc)
        stages.record_failure(self.store, {**unit, "fresh": unit["digest"] not in self.rows}, reason)
        self.rows.add(unit["digest"])
        if unit.get("chunk") is not None or unit["kind"] != "ik":  # not a part whose IK could not be scheduled
            self.bar.done(unit["kind"])
        if unit["kind"] == "ik" and unit.get("chunk") is not None:  # not a part whose IK could not be scheduled
            key = (unit["part"], unit["robot"])  # the run's other chunks go on; its graph waits for a re-run
            self.broken.add(key)
            if not counted:
                self._chunk_done(key)

    # -- the loop ------------------------------------------------------------------------------------------------
    def run(self, parts: Sequence[tuple[Path, float | None]]) -> None:
        for path, scale in parts:
            self.submit_part(path, scale)
        for batch in self.ac.batches():
            items = []
            for fut, result in batch:
                unit = self.pending.pop(fut)
                if fut.status == "error" or isinstance(result, BaseException):
                    self.fail(unit, result[1] if isinstance(result, tuple) else result)
                    fut.release()
                elif unit["kind"] == "ik" and self.shards is not None:
                    self.shard_done(fut, unit, result)
                elif unit["kind"] == "ik":
                    self.hold(fut, unit, result)
                else:
                    items.append((fut, unit, result))
            if items:
                self.write_batch(items)
        for key in list(self.held):  # runs cut short (none when every unit came back)
            self.write_batch(self.held.pop(key))
        self.bar.close()


def shard_path(folder: Path, digest: str) -> Path:
    """The Parquet file of an IK unit's rows in the shard folder."""
    return folder / f"ik-{digest}{SHARD_SUFFIX}"


def open_shards(folder: Path, done: dict) -> dict[str, Path]:
    """The shard folder (created when missing): the files of IK units computed but not merged yet, by digest.
    Temporary files of killed writers, and files of units already stored (a driver killed after the merge's commit),
    are deleted."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CatalogError(f"cannot create the shard folder {folder}: {exc.strerror or exc}") from None
    for tmp in folder.glob(f"ik-*{SHARD_SUFFIX}.*.tmp"):
        tmp.unlink(missing_ok=True)
    out = {}
    for path in folder.glob(f"ik-*{SHARD_SUFFIX}"):
        digest = path.name[3:-len(SHARD_SUFFIX)]
        if digest in done:
            path.unlink(missing_ok=True)
        else:
            out[digest] = path
    return out


def _unit_ids(run: dict) -> dict:
    return {k: run[k] for k in ("part", "robot", "source", "idobject", "idgrasps", "idplacements", "idtabletop", "idrobot",
                                "idscene", "idikret")}


def build_catalog(parts: Sequence[str | Path | tuple[str | Path, float]],
                  robots: str | Sequence[str] | dict[str, CatalogRobot], db: str | Path, client,
                  params: CatalogParams = CatalogParams(), progress: bool = True,
                  on_unit: Callable[[str, dict], None] | None = None, shards: str | Path | None = None) -> CatalogResult:
    """Build (or finish) the catalogue of `parts` x `robots` in the store `db` on the Dask `client`; returns the
    summary. Stored units are skipped; each finished unit is written in one transaction.

    With `shards` (a folder, created when missing; on a file system every worker sees), the IK units' workers write
    their rows to one Parquet file per unit there, and the driver merges the files of each (part, robot) into the
    store in one transaction once all its chunks are on disk, then deletes them: the driver's per-unit work is a
    note, not a write. Files of a killed build are merged by the re-run; a file is whole or absent (renamed into
    place), and the merge skips grips that already have rows, so nothing is lost or duplicated."""
    paths = collect_parts(parts)
    robot_models = catalog_robots(robots)
    t0 = time.perf_counter()
    with stages.open_store(db) as store:
        build = _Build(store, client, robot_models, params, progress, on_unit,
                       None if shards is None else Path(shards))
        build.result.start = time.time()
        try:
            build.run(paths)
        finally:
            for fut in list(build.pending):
                fut.cancel()
        res = build.result
        res.wall = time.perf_counter() - t0
        res.rows = stages.summary(store)
        res.failures = stages.failures(store)
    res.workers = len(client.scheduler_info().get("workers", {}))
    res.dashboard = client.dashboard_link or ""
    return res


def report(db: str | Path) -> tuple[list[dict], list[dict]]:
    """The stored catalogue's summary rows and failures (for `workbench catalog report`)."""
    with stages.open_store(db, read_only=True) as store:
        return stages.summary(store), stages.failures(store)


SUMMARY_HEADERS = ("part", "robot", "grasps", "placements", "tabletop grips", "IK-feasible", "components", "time s")


def summary_table(rows: list[dict]) -> list[tuple]:
    """Rows for printing: part, robot, grasps, placements, tabletop grips, share of grips feasible at all five IK
    poses, graph components, seconds of worker time (part stages + the robot's IK and graph)."""
    out = []
    for r in rows:
        share = f"{r['ik_feasible'] / r['tabletop_grips']:.1%}" if r["tabletop_grips"] and r["robot"] else "-"
        comps = r["graph"].get("components", "-") if r["robot"] else "-"
        t = (r["part_seconds"] or 0.0) + (r["ik_seconds"] or 0.0) + (r["graph_seconds"] or 0.0)
        out.append((r["part"], r["robot"] or "-", r["grasps"], r["placements"], r["tabletop_grips"], share, comps, round(t, 2)))
    return out
