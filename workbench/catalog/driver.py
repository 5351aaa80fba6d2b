"""The catalogue's driver: schedules units on a Dask cluster, resumes by digest, merges what the workers wrote.

Units: one per part (grasps, placements, tabletop grips; Wan & Harada Sections III-IV), one per chunk of a part's
tabletop grips and robot (IK with retractions, Section IV), one per part and robot (the regrasp graph's size,
Section V, a few milliseconds: the driver computes it from the merged rows in the merge's transaction, cheaper than
a worker's round trip). Workers write their rows as Parquet files (a folder per part unit, a file per IK unit) and
return a small record; the driver schedules a part's IK units from its record and merges the files of many units
into the store in one transaction, with their `catalog_unit` rows, so a unit is stored whole or not at all. Units
whose digest is stored are skipped, and files on disk are merged without computing them again, so a re-run after a
crash computes only the rest. A task on a worker that dies is rescheduled by the Dask scheduler on another worker;
a unit that raises (a broken mesh) is recorded as failed with its one-line reason and the others go on.
"""

from __future__ import annotations

import hashlib
import json
import shutil
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
from workbench.catalog.units import graph_unit, ik_unit_files, part_from_tables, part_unit
from workbench.errors import WorkbenchError
from workbench.geometry.objects import resolve_scale
from workbench.grasping.grasps import GraspParams
from workbench.grasping.placements import PlacementParams
from workbench.planners.wan_harada.stages import HANDX, WORLDZ
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.gripper import Gripper, franka_hand
from workbench.robots.ik import WORLDA, IKOptions, chunk_bounds

MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf", ".dae")
PART_PRIORITY = 1 << 40  # Dask priorities (higher runs first): parts, then IK chunks by their length
MERGE_UNITS = 256  # units waiting on disk that start a merge ...
MERGE_SECONDS = 5.0  # ... or seconds since the last merge
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
    sorted within each folder; an entry may be a (path, scale) pair to override the build's scale for it. A path that
    does not exist is refused (before any cluster starts)."""
    out: list[tuple[Path, float | None]] = []
    missing: list[Path] = []
    for item in paths:
        p, scale = (Path(item[0]), float(item[1])) if isinstance(item, tuple) else (Path(item), None)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.suffix.lower() in MESH_SUFFIXES and q.is_file())
            if not found:
                raise CatalogError(f"folder {p} holds no mesh files ({', '.join(MESH_SUFFIXES)})")
            out.extend((q, scale) for q in found)
        elif p.is_file():
            out.append((p, scale))  # a broken file is reported as that part's failure
        else:
            missing.append(p)
    if missing:
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise CatalogError(f"no such part file or folder: {', '.join(map(str, missing[:3]))}{more}")
    if not out:
        raise CatalogError("no parts given: pass mesh files or folders of them")
    stems = [p.stem for p, _ in out]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise CatalogError(f"several parts are named {', '.join(dup)} (the file name is the part's name); rename them")
    return out


Columns = list[tuple[Gripper, dict[str, CatalogRobot]]]  # per gripper, the catalogue's robots carrying it


def catalog_columns(robots: str | Sequence[str] | dict[str, CatalogRobot] | Sequence[dict[str, CatalogRobot]],
                    grippers: Sequence[Gripper] | None = None) -> Columns:
    """The catalogue's (robot, gripper) columns, per gripper: `robots` given as parsed
    (`workbench.catalog.robots.parse_robots`, one dict per gripper, each robot carrying its gripper), or as names
    parsed once per gripper of `grippers` (default the Franka hand)."""
    if isinstance(robots, dict):
        groups = [robots]
    elif not isinstance(robots, str) and robots and all(isinstance(r, dict) for r in robots):
        groups = list(robots)
    else:
        groups = [parse_robots(robots, gripper=g) for g in (grippers or [franka_hand()])]
    out: Columns = []
    for group in groups:
        hands = {c.robot.spec.hand.digest: c.robot.spec.hand for c in group.values()}
        if len(hands) != 1:
            raise CatalogError(f"robots {', '.join(group)} carry different grippers; give one robot list per gripper")
        out.append((next(iter(hands.values())), group))
    if grippers is not None and [h.digest for h, _ in out] != [g.digest for g in grippers]:
        raise CatalogError(f"the robots carry grippers {', '.join(h.name for h, _ in out)}, not the catalogue's "
                           f"{', '.join(g.name for g in grippers)}")
    digests = [h.digest for h, _ in out]
    dup = sorted({h.name for h, _ in out if digests.count(h.digest) > 1})
    if dup:
        raise CatalogError(f"gripper {', '.join(dup)} is listed twice; list each gripper once")
    return out


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
    """The state of one build: the store, the client, what is stored, what runs, what waits to be merged."""

    def __init__(self, store, client, columns: Columns, params: CatalogParams, progress: bool,
                 on_unit: Callable[[str, dict], None] | None, folder: Path):
        from distributed import as_completed

        self.store, self.client, self.params = store, client, params
        # per gripper row: the gripper and its robots (a part unit per part and gripper, an IK run per robot of it)
        self.hands = {stages.gripper_id(store, hand): hand for hand, _ in columns}
        self.columns = dict(zip(self.hands, (robots for _, robots in columns)))
        self.on_unit = on_unit
        self.done = stages.done_units(store)
        self.rows = stages.unit_digests(store)  # digests with a catalog_unit row (done or failed), kept by this writer
        self.pending: dict = {}  # future -> unit dict
        self.left: dict[tuple, int] = {}  # (part, idgripper, robot) -> IK chunks not finished yet
        self.broken: set[tuple] = set()  # runs with a failed IK chunk: their graph waits for a re-run
        self.runs: dict[tuple, dict] = {}
        # (idgripper, robot name) -> its run's ids in this store; created in the columns' order, so a robot stored
        # with several grippers is named as `workbench build` of each gripper in that order names it
        self.ik_runs = {(gid, name): stages.ik_run(store, c.robot, c.scene, params.ik, params.handx, params.worldz,
                                                    params.worlda)
                        for gid, robots in self.columns.items() for name, c in robots.items()}
        # results fetched in the background (a replay of recorded units brings its own)
        self.ac = client.as_completed() if hasattr(client, "as_completed") else as_completed(with_results=True,
                                                                                              raise_errors=False)
        self.result = CatalogResult(rows=[], failures=[], shards=str(folder))
        self.bar = Progress(progress)
        self.folder = folder
        self._stack: list[float] = []  # seconds of nested `charge` blocks, innermost last
        self.on_disk = open_shards(folder, self.done)  # digest -> shard file of an IK unit computed, not merged yet
        self.to_merge: dict[tuple, list[tuple[dict, Path]]] = {}  # (part, idgripper, robot) -> its IK units on disk
        # parts a DuckDB store holds already: written by the stage writers (a Parquet catalogue's merge reuses them)
        self.stored_names = stages.object_names(store) if store.dataset is None else set()
        self.queue_parts: list[tuple[dict, Path]] = []  # part units on disk, waiting for the next merge
        self.queue_direct: list[tuple[object, dict, dict]] = []  # part units of stored names, waiting to be written
        self.queue_runs: list[dict] = []  # (part, gripper, robot) runs whose IK units are all on disk
        # rows are written in the listed order (parts x grippers, then each part's robots), whichever unit finishes
        # first, so that the ids are those of `workbench build` of each in that order, for any worker count
        self.place: dict[tuple[str, int], int] = {}  # (part, idgripper) -> its place in the listed order
        self.waiting: set[int] | None = set()  # places whose part unit is still computing (None: the last merge)
        self.head = 0  # every place before it is written (or failed, or was stored already)
        self.runs_over: set[tuple] = set()  # runs written, failed or broken
        self.readers: dict[str, int] = {}  # part digest -> its runs still reading its folder
        self.last_merge = time.monotonic()

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
        # the last units to run are the short ones.
        fut = self.client.submit(fn, *args, key=key, pure=False, priority=priority, **kwargs)
        self.pending[fut] = unit
        self.ac.add(fut)
        self.bar.add(unit["kind"])

    def submit_part(self, path: Path, scale: float | None, idgripper: int) -> None:
        p, hand = self.params, self.hands[idgripper]
        units = p.units if scale is None else None
        scale = p.scale if scale is None else scale
        digest = _digest("part", _file_digest(path), path.stem, hand.digest,
                         {**p.part_dict(), "scale": scale, "units": units})
        unit = {"digest": digest, "kind": "part", "part": path.stem, "source": str(path), "idgripper": idgripper}
        self.place[path.stem, idgripper] = len(self.place)
        if digest in self.done:
            self._skip("part")
            self.schedule_stored({**self.done[digest], "idgripper": idgripper})
            return
        priority = PART_PRIORITY + min(path.stat().st_size if path.is_file() else 0, PART_PRIORITY - 1)
        self.waiting.add(self.place[path.stem, idgripper])
        if path.stem in self.stored_names:  # the store holds this part: the driver writes it with the stage writers
            self._submit(unit, part_unit, str(path), path.stem, scale, units, p.grasps, p.placements, p.tabletop,
                         hand, priority=priority)
            return
        folder = self.folder / f"part-{digest}"
        record = stages.read_record(folder) if folder.is_dir() else None
        if record is not None:  # computed by a run that stopped before merging it
            self._skip("part")
            self.waiting.discard(self.place[path.stem, idgripper])
            self.part_ready(unit, record, folder)
            return
        unit["folder"] = folder
        self._submit(unit, stages.part_unit_files, str(path), path.stem, scale, units, p.grasps, p.placements,
                     p.tabletop, str(folder), p.ik_chunk, hand, priority=priority)

    def part_ready(self, unit: dict, record: dict, folder: Path) -> None:
        """A part unit's folder is whole: queue it for the next merge and schedule its IK units from its record."""
        with self.charge("part", "schedule"):
            unit.update({k: v for k, v in record.items() if k != "grips"})
            self.queue_parts.append((unit, folder))
            self.schedule_runs(unit, folder, int(record["grips"]), stored=False)

    def schedule_stored(self, part: dict) -> None:
        """IK units of a part the store holds (a resumed build, or a part `workbench build` stored): its grips are
        read back once and left in a folder for the IK units."""
        with self.charge("part", "schedule"):
            bases = self._run_bases(part)
            if all(_digest(b, "graph") in self.done for b in bases):  # every run is stored: nothing to read back
                n = int(part["counts"].get("tabletop_grips", 0))
                for b in bases:
                    for k in range(len(chunk_bounds(n, self.params.ik_chunk))):
                        if _digest(b, "ik", k, n) in self.done:
                            self._skip("ik")
                    self._skip("graph")
                return
            folder = self.folder / f"stored-{part['digest']}"
            n = stages.stored_part_folder(self.store, part, folder, self.params.ik_chunk)
            self.schedule_runs(part, folder, n, stored=True)

    def _run_bases(self, part: dict) -> list[str]:
        return [self._run(part, name)["base"] for name in self.columns[part["idgripper"]]]

    def _run(self, part: dict, name: str) -> dict:
        p, column = self.params, self.columns[part["idgripper"]][name]
        ids = self.ik_runs[part["idgripper"], name]
        return {"part": part["part"], "robot": name, "idgripper": part["idgripper"], "idobject": part["idobject"],
                "idtabletop": part["idtabletop"],
                "idgrasps": part["idgrasps"], "idplacements": part["idplacements"], "source": part.get("source"),
                "idrobot": ids["idrobot"], "idscene": ids["idscene"], "idikret": ids["idikret"], "nq": column.robot.nq,
                "part_digest": part["digest"],
                "base": _digest(part["digest"], column.robot.spec.digest, ids["scene_params"], p.handx, p.worldz,
                                p.worlda, p.ik_chunk)}

    def schedule_runs(self, part: dict, folder: Path, n: int, stored: bool) -> None:
        """The IK chunk units of a part for every robot, reading the part's grips from `folder` (`stored`: some grips
        may have `ik` rows already, kept by the merge)."""
        p = self.params
        for name, column in self.columns[part["idgripper"]].items():
            run = self._run(part, name)
            run["stored"] = (stages.stored_ik(self.store, self.ik_runs[part["idgripper"], name], part["idtabletop"])
                             if stored else np.zeros(0, dtype=np.int64))
            key = _key(run)
            self.runs[key], self.to_merge[key], left = run, [], 0
            self.readers[part["digest"]] = self.readers.get(part["digest"], 0) + 1
            run["folder"] = folder
            for k, (s, e) in enumerate(chunk_bounds(n, p.ik_chunk)):
                unit = {**_unit_ids(run), "kind": "ik", "chunk": k, "digest": _digest(run["base"], "ik", k, n),
                        "nrows": 0 if stored else e - s}
                if unit["digest"] in self.done:
                    self._skip("ik")
                    continue
                if unit["digest"] in self.on_disk:  # computed by an earlier run, not merged yet
                    self._skip("ik")
                    self.to_merge[key].append((unit, self.on_disk.pop(unit["digest"])))
                    continue
                left += 1
                self._submit(unit, ik_unit_files, column.robot.spec, column.scene, p.ik, p.handx, p.worldz, p.worlda,
                             str(folder), k, str(shard_path(self.folder, unit["digest"])), priority=e - s)
            self.left[key] = left
            if left == 0:
                self.finish_run(run)

    def graph(self, run: dict) -> tuple[dict | None, Callable[[], None]]:
        """The run's regrasp-graph sizes (Section V; a few milliseconds), computed from the rows the caller's
        transaction can read: its unit (None when stored) for the batch's catalog_unit rows, and what to do once
        committed."""
        unit = {**_unit_ids(run), "kind": "graph", "digest": _digest(run["base"], "graph")}
        if unit["digest"] in self.done:
            self._skip("graph")
            return None, lambda: None
        self.bar.add("graph")
        with self.charge("graph", "graph"):
            rows, feasible = stages.graph_inputs(self.store, run)
            table = graph_unit(rows, feasible)
        unit.update(counts={k: v[0] for k, v in table.to_pydict().items()}, nrows=0, fresh=unit["digest"] not in self.rows)
        meta = {k: v for k, v in (table.schema.metadata or {}).items() if k not in (b"start", b"end")}  # not a worker's
        unit["seconds"] = float(meta.get(b"seconds", b"0"))

        def after() -> None:
            self.done[unit["digest"]] = unit
            self.rows.add(unit["digest"])
            self._account(unit, meta)
            self.bar.done("graph")
            if self.on_unit is not None:
                self.on_unit("graph", unit)
        return unit, after

    def _graph_computed(self, run: dict) -> tuple[dict, Callable[[], None]]:
        unit = run.pop("graph_unit")
        unit.update({k: run[k] for k in ("idobject", "idgrasps", "idplacements", "idtabletop")},
                    fresh=unit["digest"] not in self.rows)

        def after() -> None:
            self.done[unit["digest"]] = unit
            self.rows.add(unit["digest"])
            if self.on_unit is not None:
                self.on_unit("graph", unit)
        return unit, after

    def finish_run(self, run: dict) -> None:
        """Every IK chunk of a (part, robot) is finished: queue its shards and graph for the next merge (a run with a
        failed chunk gets no graph; its shards stay on disk for a re-run)."""
        key = _key(run)
        if key in self.broken:
            self._run_over(run)
            return
        unit = {**_unit_ids(run), "kind": "graph", "digest": _digest(run["base"], "graph")}
        if run["folder"].name.startswith("part-") and unit["digest"] not in self.done:  # its worker reads the files
            self._submit(unit, stages.graph_unit_files, str(run["folder"]), [str(p) for _, p in self.to_merge[key]],
                         run["robot"], priority=PART_PRIORITY // 2)
            return
        self.queue_runs.append(run)

    def graph_done(self, fut, unit: dict, table: pa.Table) -> None:
        """A run's graph unit came back: the run waits for the next merge with it."""
        meta = table.schema.metadata or {}
        unit.update(counts={k: v[0] for k, v in table.to_pydict().items()}, nrows=0)
        self._account(unit, meta)
        fut.release()
        self.bar.done("graph")
        run = self.runs[_key(unit)]
        run["graph_unit"] = unit
        self.queue_runs.append(run)

    def _run_over(self, run: dict) -> None:
        """A run no longer reads its part's folder: the folder goes when the part's last run is over."""
        self.runs_over.add(_key(run))
        d = run["part_digest"]
        self.readers[d] -= 1
        if self.readers[d] == 0 and all(u["digest"] != d for u, _ in self.queue_parts):
            shutil.rmtree(run["folder"], ignore_errors=True)

    # -- merging -------------------------------------------------------------------------------------------------
    def merge(self, force: bool = False) -> None:
        """Merge what waits and may be written in the listed order (part folders and part units of stored names up
        to the first part still computing, then the complete runs of written parts up to the first run still
        computing) when `MERGE_UNITS` units wait, `MERGE_SECONDS` passed since the last merge, or `force`."""
        waiting = (len(self.queue_parts) + len(self.queue_direct)
                   + sum(len(self.to_merge[_key(r)]) for r in self.queue_runs))
        if not (self.queue_parts or self.queue_direct or self.queue_runs):
            return
        if not force and waiting < MERGE_UNITS and time.monotonic() - self.last_merge < MERGE_SECONDS:
            return
        for kind, items in self._next_parts():
            if kind == "direct":
                self.write_parts(items)
            else:
                self._merge_checked(items, [])
        runs = self._next_runs()
        if runs:
            self._merge_checked([], runs)
        self.last_merge = time.monotonic()

    def _next_parts(self) -> list[tuple[str, list]]:
        """The waiting part units from the first unwritten place up to the first one still computing, taken off their
        queues, as runs of one kind ("folder": (unit, folder); "direct": (future, unit, tables)) in the listed order."""
        ready = {self.place[u["part"], u["idgripper"]]: ("folder", (u, f)) for u, f in self.queue_parts}
        ready.update({self.place[d[1]["part"], d[1]["idgripper"]]: ("direct", d) for d in self.queue_direct})
        out: list[tuple[str, list]] = []
        while self.head < len(self.place) and (self.waiting is None or self.head not in self.waiting):
            if self.head in ready:
                kind, item = ready.pop(self.head)
                if out and out[-1][0] == kind:
                    out[-1][1].append(item)
                else:
                    out.append((kind, [item]))
            self.head += 1
        self.queue_parts = [item for kind, item in ready.values() if kind == "folder"]
        self.queue_direct = [item for kind, item in ready.values() if kind == "direct"]
        return out

    def _next_runs(self) -> list[dict]:
        """The complete runs of written parts, in the listed order (part, then robot) up to the first run still
        computing, taken off their queue."""
        def order(key: tuple) -> tuple[int, int]:
            part, gid, robot = key
            return self.place[part, gid], list(self.columns[gid]).index(robot)

        if not self.queue_runs:
            return []
        queued = {_key(r): r for r in self.queue_runs}
        out = []
        for key in sorted((k for k in self.runs if k not in self.runs_over), key=order):
            if order(key)[0] >= self.head:
                break
            if key not in queued:
                if self.waiting is None:  # the last merge: nothing computes any more, so nothing is to come
                    continue
                break
            out.append(queued.pop(key))
        self.queue_runs = list(queued.values())
        return out

    def _merge_checked(self, parts: list[tuple[dict, Path]], runs: list[dict]) -> None:
        """`_merge` in one transaction, or, when that fails, each part and run alone (the one that cannot be merged
        is recorded as failed, the others stored)."""
        for run in [r for r in runs if r["part_digest"] not in self.done]:  # its part could not be written
            runs.remove(run)
            self._merge_failed([], [run], WorkbenchError("its part unit could not be merged"))
        if not (parts or runs):
            return
        try:
            self._merge(parts, runs)
        except WorkbenchError as exc:
            if len(parts) + len(runs) == 1:
                self._merge_failed(parts, runs, exc)
                return
            for item in parts:
                self._merge_checked([item], [])
            for run in runs:
                self._merge_checked([], [run])

    def _merge(self, parts: list[tuple[dict, Path]], runs: list[dict]) -> None:
        after: list[Callable[[], None]] = []
        n = 0
        with self.charge("part" if parts else "ik", "merge"), stages.batch(self.store):
            if parts:
                for unit, _ in parts:
                    unit["fresh"] = unit["digest"] not in self.rows
                n += stages.merge_units(self.store, parts)
            merged = {u["digest"]: u for u, _ in parts}
            for run in runs:
                part = merged.get(run["part_digest"]) or self.done[run["part_digest"]]
                ids = {k: part[k] for k in ("idobject", "idgrasps", "idplacements", "idtabletop")}  # the store's
                run.update(ids, offset=part["counts"].get("offset", 0))
                for unit, _ in self.to_merge[_key(run)]:
                    unit.update(ids, fresh=unit["digest"] not in self.rows)
            if runs:
                with self.charge("ik", "merge"):
                    n += stages.merge_runs(self.store, runs, [self.to_merge[_key(r)] for r in runs])
                graphs = [self.graph(run) if "graph_unit" not in run else self._graph_computed(run) for run in runs]
                with self.charge("graph", "rows"):
                    stages.put_units(self.store, [u for u, _ in graphs if u is not None])
                after = [then for _, then in graphs]
        self.result.merges += 1
        self.result.batches += 1
        self.result.rows_written += n
        for unit, _ in parts:
            self.done[unit["digest"]] = unit
            self.rows.add(unit["digest"])
            if self.on_unit is not None:
                self.on_unit("part", unit)
        for run in runs:
            for unit, path in self.to_merge.pop(_key(run)):
                self.done[unit["digest"]] = unit
                self.rows.add(unit["digest"])
                _drop(path)
            self._run_over(run)
        for then in after:
            then()
        for unit, folder in parts:
            if self.readers.get(unit["digest"], 0) == 0:
                _drop(folder)
        if self.result.write_seconds > 0:
            self.bar.note(f"{self.result.rows_written / self.result.write_seconds:,.0f} rows/s merged")

    def _merge_failed(self, parts: list[tuple[dict, Path]], runs: list[dict], exc: BaseException) -> None:
        """A part folder or a run's shards that cannot be merged: recorded as failed and deleted (a re-run computes
        them again)."""
        for unit, folder in parts:
            shutil.rmtree(folder, ignore_errors=True)
            stages.record_failure(self.store, {**unit, "fresh": unit["digest"] not in self.rows}, one_line(exc))
            self.rows.add(unit["digest"])
        for run in runs:
            key = _key(run)
            for unit, path in self.to_merge.pop(key, []):
                path.unlink(missing_ok=True)
                stages.record_failure(self.store, {**unit, "fresh": unit["digest"] not in self.rows}, one_line(exc))
                self.rows.add(unit["digest"])
            self.broken.add(key)
            self._run_over(run)

    # -- results -------------------------------------------------------------------------------------------------
    def part_done(self, fut, unit: dict, table: pa.Table) -> None:
        """A part unit whose worker left its folder: a note, then its IK units."""
        meta = table.schema.metadata or {}
        self._account(unit, meta)
        fut.release()
        self.bar.done("part")
        self.waiting.discard(self.place[unit["part"], unit["idgripper"]])
        self.part_ready(unit, json.loads(table.column("record")[0].as_py()), unit.pop("folder"))

    def write_parts(self, items: list[tuple[object, dict, dict]]) -> None:
        """Part units of names the store holds, written by the stage writers (which reuse what is stored) in one
        transaction; if one cannot be written, one by one."""
        try:
            with stages.batch(self.store):
                for _, unit, tables in items:
                    unit["fresh"] = unit["digest"] not in self.rows
                    with self.charge("part", "decode"):
                        res = part_from_tables(tables)
                    with self.charge("part", "rows"):
                        p = self.params
                        stages.write_part(self.store, unit, res, self.hands[unit["idgripper"]], p.grasps, p.placements, p.tabletop)
        except Exception as exc:  # noqa: BLE001 - one part's rows that cannot be stored must not stop the others
            if len(items) > 1:
                for item in items:
                    self.write_parts([item])
                return
            self.fail(items[0][1], exc, counted=True)
            items[0][0].release()
            return
        self.result.batches += 1
        for fut, unit, tables in items:
            self.done[unit["digest"]] = unit
            self.rows.add(unit["digest"])
            self.result.rows_written += int(unit.get("nrows") or 0)
            self._account(unit, tables["meta"].schema.metadata or {})
            fut.release()
            self.bar.done("part")
            if self.on_unit is not None:
                self.on_unit("part", unit)
            try:
                self.schedule_stored(unit)
            except WorkbenchError as exc:  # e.g. a part whose tabletop grips are not rigid poses: its IK cannot start
                self.fail({**unit, "kind": "ik", "digest": unit["digest"] + "-schedule"}, exc)

    def shard_done(self, fut, unit: dict, table: pa.Table) -> None:
        """An IK unit whose worker wrote its rows to a shard: note it; queue its run when it is the run's last."""
        with self.charge("ik", "schedule"):
            meta = table.schema.metadata or {}
            row = table.to_pylist()[0]
            unit.update(counts={k: int(row[k]) for k in ("grips", "feasible", "feasible_all")})
            self._account(unit, meta)
            key = _key(unit)
            self.to_merge[key].append((unit, Path(meta[b"shard"].decode())))
            fut.release()
            self.bar.done("ik")
            self._chunk_done(key)
        if self.on_unit is not None:
            self.on_unit("ik", unit)

    def _chunk_done(self, key: tuple[str, str]) -> None:
        self.left[key] -= 1
        if self.left[key] == 0:
            self.finish_run(self.runs[key])

    def _account(self, unit: dict, meta: dict) -> None:
        """A computed unit's worker seconds, CPU seconds and place on the workers' timeline."""
        kind = unit["kind"]
        unit.update(seconds=float(meta.get(b"seconds", b"0")), worker=meta.get(b"worker", b"").decode())
        self.result.computed[kind] += 1
        self.result.compute[kind] += unit["seconds"]
        self.result.cpu[kind] += float(meta.get(b"cpu", b"0"))
        if b"start" in meta:
            self.result.timeline.append((unit["worker"], kind, float(meta[b"start"]), float(meta[b"end"])))

    def fail(self, unit: dict, exc: BaseException, counted: bool = False) -> None:
        """Record a unit that raised or could not be written (`counted`: already counted as finished)."""
        reason = one_line(exc)
        unit.pop("folder", None)
        if unit["kind"] == "part" and self.waiting is not None:
            self.waiting.discard(self.place.get((unit["part"], unit["idgripper"]), -1))
        stages.record_failure(self.store, {**unit, "fresh": unit["digest"] not in self.rows}, reason)
        self.rows.add(unit["digest"])
        scheduling = unit["kind"] == "ik" and unit.get("chunk") is None  # a part whose IK could not be scheduled
        if not (counted or scheduling):
            self.bar.done(unit["kind"])
        if unit["kind"] == "ik" and not scheduling:
            key = _key(unit)  # the run's other chunks go on; its graph waits for a re-run
            self.broken.add(key)
            self._chunk_done(key)
        if unit["kind"] == "graph":  # its run's shards stay on disk; the re-run merges them and computes the graph
            key = _key(unit)
            self.broken.add(key)
            self._run_over(self.runs[key])

    # -- the loop ------------------------------------------------------------------------------------------------
    def run(self, parts: Sequence[tuple[Path, float | None]]) -> None:
        for path, scale in parts:
            for idgripper in self.hands:
                self.submit_part(path, scale, idgripper)
        for batch in self.ac.batches():
            direct = []
            for fut, result in batch:
                unit = self.pending.pop(fut)
                if fut.status == "error" or isinstance(result, BaseException):
                    self.fail(unit, result[1] if isinstance(result, tuple) else result)
                    fut.release()
                elif unit["kind"] == "ik":
                    self.shard_done(fut, unit, result)
                elif unit["kind"] == "graph":
                    self.graph_done(fut, unit, result)
                elif "folder" in unit:
                    self.part_done(fut, unit, result)
                else:
                    direct.append((fut, unit, result))
            for item in direct:
                self.waiting.discard(self.place[item[1]["part"], item[1]["idgripper"]])
            self.queue_direct += direct
            # a part the store held is written as soon as its turn comes: its IK units start only then
            self.merge(force=bool(self.queue_direct))
        self.waiting = None  # nothing computes any more: the last merge writes whatever waits
        self.merge(force=True)
        self.bar.close()


def shard_path(folder: Path, digest: str) -> Path:
    """The Parquet file of an IK unit's rows in the units folder."""
    return folder / f"ik-{digest}{SHARD_SUFFIX}"


def _drop(path: Path) -> None:
    """Delete a merged unit's file or folder, and what writers killed while writing it left beside it (its
    `.PID.tmp` files: Dask ran the unit again elsewhere, and nothing else will read them)."""
    for p in [path, *path.parent.glob(f"{path.name}.*.tmp")]:
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)


def open_shards(folder: Path, done: dict) -> dict[str, Path]:
    """The units folder (created when missing): the files of IK units computed but not merged yet, by digest.
    Temporary files and folders of killed writers, and files of units already stored (a driver killed after the
    merge's commit), are deleted."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CatalogError(f"cannot create the units folder {folder}: {exc.strerror or exc}") from None
    for tmp in folder.glob("*.tmp"):
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
    for old in folder.glob("part-*"):
        if old.name[5:] in done:
            shutil.rmtree(old, ignore_errors=True)
    out = {}
    for path in folder.glob(f"ik-*{SHARD_SUFFIX}"):
        digest = path.name[3:-len(SHARD_SUFFIX)]
        if digest in done:
            path.unlink(missing_ok=True)
        else:
            out[digest] = path
    return out


def _unit_ids(run: dict) -> dict:
    return {k: run[k] for k in ("part", "robot", "idgripper", "source", "idobject", "idgrasps", "idplacements", "idtabletop",
                                "idrobot", "idscene", "idikret")}


def _key(unit: dict) -> tuple[str, int, str]:
    """A (part, gripper, robot) run's key: the part's name, the gripper's row and the robot's column name."""
    return unit["part"], unit["idgripper"], unit["robot"]


def build_catalog(parts: Sequence[str | Path | tuple[str | Path, float]],
                  robots: str | Sequence[str] | dict[str, CatalogRobot] | Sequence[dict[str, CatalogRobot]],
                  db: str | Path, client, params: CatalogParams = CatalogParams(), progress: bool = True,
                  on_unit: Callable[[str, dict], None] | None = None, shards: str | Path | None = None,
                  gripper: Gripper | None = None, form: str = "duckdb",
                  grippers: Sequence[Gripper] | None = None) -> CatalogResult:
    """Build (or finish) the catalogue of `parts` x `robots` in the store `db` on the Dask `client`; returns the
    summary. Stored units are skipped.

    Workers write: a part unit leaves its rows as Parquet files in its own folder (ids from the unit's own range),
    an IK unit reads its chunk of the part's grips from there and leaves its rows as one Parquet file; every file
    is written under a temporary name and renamed, so it is whole or absent. The driver notes each finished unit and
    merges what waits into the store in large batches, one transaction each (`MERGE_UNITS` units or
    `MERGE_SECONDS`), then deletes the files. `shards` is the folder of these files (default: beside the store,
    `DB.units`; with a cluster of several machines, on a file system every worker sees). Files of a killed build are
    merged by the re-run without computing them again. `grippers` (or one `gripper`): the catalogue's grippers,
    each a part unit per part and a column per robot (default the Franka hand, or the grippers the robots carry
    when given parsed; see `catalog_columns`). `form`: the catalogue's form when `db` is new, a DuckDB file
    ("duckdb") or a folder of Hive-partitioned Parquet files ("parquet"; `workbench.store.catalog`)."""
    paths = collect_parts(parts)
    columns = catalog_columns(robots, grippers if grippers is not None else None if gripper is None else [gripper])
    folder = Path(shards) if shards is not None else Path(f"{db}.units")
    t0 = time.perf_counter()
    with stages.open_store(db, form=form) as store:
        build = _Build(store, client, columns, params, progress, on_unit, folder)
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
        stages.checkpoint(store)
    res.workers = len(client.scheduler_info().get("workers", {}))
    res.dashboard = client.dashboard_link or ""
    return res


def report(db: str | Path, meshes: bool = False) -> tuple[list[dict], list[dict], dict]:
    """The stored catalogue's summary rows, failures and (with `meshes`) each part's mesh (for `workbench catalog
    report`)."""
    with stages.open_store(db, read_only=True) as store:
        rows, failures = stages.summary(store), stages.failures(store)
        return rows, failures, stages.part_meshes(store, sorted({r["part"] for r in rows})) if meshes else {}


SUMMARY_HEADERS = ("part", "robot", "gripper", "grasps", "placements", "tabletop grips", "IK-feasible", "components", "time s")


def summary_table(rows: list[dict]) -> list[tuple]:
    """Rows for printing: part, robot, gripper, grasps, placements, tabletop grips, share of grips feasible at all five IK
    poses, graph components, seconds of worker time (part stages + the robot's IK and graph)."""
    out = []
    for r in rows:
        share = f"{r['ik_feasible'] / r['tabletop_grips']:.1%}" if r["tabletop_grips"] and r["robot"] else "-"
        comps = r["graph"].get("components", "-") if r["robot"] else "-"
        t = (r["part_seconds"] or 0.0) + (r["ik_seconds"] or 0.0) + (r["graph_seconds"] or 0.0)
        out.append((r["part"], r["robot"] or "-", r.get("gripper") or "-", r["grasps"], r["placements"], r["tabletop_grips"], share, comps, round(t, 2)))
    return out
