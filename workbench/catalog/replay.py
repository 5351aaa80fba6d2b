"""The catalogue's driver at scale without the cores: recorded units replayed into it at the rate N workers would
produce them.

`record_units` runs every unit of a few parts once, in this process, and keeps what each left (a part unit's
folder, an IK unit's shard, a graph unit's sizes), its result and its measured seconds. `ReplayClient` stands for a Dask client with N
workers: the driver (`build_catalog`, unchanged) submits its units as usual; each is queued by priority, started on
the first free simulated worker and finished its recorded seconds later, in real time, when its files are put where
the driver expects them. The parts are replicated under new names (`NAME~K`) so that N workers have work. The
driver's utilisation is the share of the replay's wall time it was not waiting for a unit.
"""

from __future__ import annotations

import heapq
import itertools
import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Sequence

import pyarrow as pa
import pyarrow.parquet as pq

from workbench.catalog import stages
from workbench.catalog.robots import CatalogRobot
from workbench.catalog.units import ik_unit_files
from workbench.robots.ik import chunk_bounds

REPLICA = "~"  # NAME~K: the K-th copy of part NAME


@dataclass
class Recording:
    """Per part: its folder, its unit's result and seconds; per (part, robot, chunk): the shard, result, seconds."""

    folder: Path
    meshes: dict[str, Path] = field(default_factory=dict)
    parts: dict[str, tuple[Path, pa.Table, float]] = field(default_factory=dict)
    ik: dict[tuple[str, str, int], tuple[Path, pa.Table, float]] = field(default_factory=dict)
    graphs: dict[tuple[str, str], tuple[pa.Table, float]] = field(default_factory=dict)

    def units_per_copy(self) -> int:
        return len(self.parts) + len(self.ik) + len(self.graphs)


def record_units(parts: Sequence[tuple[Path, float | None]], robots: dict[str, CatalogRobot], params, folder: Path,
                 progress: bool = True) -> Recording:
    """Every unit of `parts` x `robots`, run once here (as a worker runs it); their files are kept in `folder`."""
    from tqdm.auto import tqdm

    rec = Recording(folder)
    folder.mkdir(parents=True, exist_ok=True)
    p = params
    for path, scale in tqdm(parts, desc="recording units", unit="part", disable=not progress):
        name = path.stem
        units = p.units if scale is None else None
        scale = p.scale if scale is None else scale
        part_folder = folder / f"part-{name}"
        table = stages.part_unit_files(str(path), name, scale, units, p.grasps, p.placements, p.tabletop,
                                       str(part_folder), p.ik_chunk)
        rec.meshes[name] = path
        rec.parts[name] = (part_folder, table, float(table.schema.metadata[b"seconds"]))
        n = json.loads(table.column("record")[0].as_py())["grips"]
        for robot, column in robots.items():
            for k, _ in enumerate(chunk_bounds(n, p.ik_chunk)):
                shard = folder / f"ik-{name}-{robot}-{k}.parquet"
                t = ik_unit_files(column.robot.spec, column.scene, p.ik, p.handx, p.worldz, p.worlda, str(part_folder),
                                  k, str(shard))
                rec.ik[name, robot, k] = (shard, t, float(t.schema.metadata[b"seconds"]))
            shards = [str(rec.ik[name, robot, k][0]) for k, _ in enumerate(chunk_bounds(n, p.ik_chunk))]
            t = stages.graph_unit_files(str(part_folder), shards, robot)
            rec.graphs[name, robot] = (t, float(t.schema.metadata[b"seconds"]))
    return rec


class _Future:
    status = "finished"

    def __init__(self, key: str):
        self.key = key

    def release(self) -> None:
        pass

    def cancel(self) -> None:
        pass


class ReplayClient:
    """A stand-in for a Dask client of `workers` workers that replays `recording`'s units (see the module)."""

    def __init__(self, recording: Recording, workers: int, copies: int, staging: Path):
        self.rec, self.n, self.copies, self.staging = recording, int(workers), int(copies), staging
        self.dashboard_link = ""
        self.queue: list = []  # (-priority, seq, submitted, future, seconds, finish action)
        self.free = [0.0] * self.n  # simulated workers' free times (s since the start)
        self.running: list = []  # (finish, seq, future, result, action)
        self.seq = itertools.count()
        self.folder_part: dict[str, str] = {}
        self.t0: float | None = None
        self.idle = 0.0
        self.wall = 0.0
        self.unit_seconds = 0.0
        self.units = 0
        self._stage()

    # -- the replicas --------------------------------------------------------------------------------------------
    def _stage(self) -> None:
        """Mesh names and part folders of every copy, prepared before the replay starts (not the driver's work)."""
        meshes = self.staging / "meshes"
        meshes.mkdir(parents=True, exist_ok=True)
        self.paths: list[Path] = []
        for name, (folder, _, _) in self.rec.parts.items():
            obj = pq.read_table(folder / "object.parquet")
            for k in range(self.copies):
                copy = f"{name}{REPLICA}{k}"
                mesh = meshes / f"{copy}{self.rec.meshes[name].suffix}"
                if not mesh.exists():
                    mesh.symlink_to(self.rec.meshes[name].resolve())
                self.paths.append(mesh)
                staged = self.staging / "parts" / copy
                staged.mkdir(parents=True, exist_ok=True)
                for f in folder.iterdir():
                    if f.name != "object.parquet":
                        os.link(f, staged / f.name)
                named = obj.set_column(obj.schema.get_field_index("name"), "name", pa.array([copy]))
                pq.write_table(named, staged / "object.parquet")

    def parts(self) -> list[Path]:
        """The copies' mesh paths, for `build_catalog`."""
        return self.paths

    # -- the client's side ----------------------------------------------------------------------------------------
    def scheduler_info(self) -> dict:
        return {"workers": {str(i): {} for i in range(self.n)}}

    def as_completed(self) -> "ReplayClient":
        return self

    def add(self, future: _Future) -> None:
        pass  # every submitted unit is followed already

    def now(self) -> float:
        if self.t0 is None:
            self.t0 = time.monotonic()
        return time.monotonic() - self.t0

    def submit(self, fn, *args, key: str, priority: int = 0, **kwargs) -> _Future:
        fut = _Future(key)
        if fn is stages.part_unit_files:
            name, folder = args[1], args[7]
            base = name.split(REPLICA)[0]
            _, table, seconds = self.rec.parts[base]
            self.folder_part[folder] = name
            staged = self.staging / "parts" / name
            action = (lambda: os.replace(staged, folder))
            result = table
        elif fn is ik_unit_files:
            spec, folder, chunk, shard = args[0], args[6], args[7], kwargs.get("shard", args[8] if len(args) > 8 else None)
            base = self.folder_part[folder].split(REPLICA)[0]
            path, table, seconds = self.rec.ik[base, spec.name, chunk]
            action = (lambda: os.link(path, shard))
            result = table.replace_schema_metadata({**(table.schema.metadata or {}), b"shard": str(shard).encode()})
        elif fn is stages.graph_unit_files:
            base = self.folder_part[args[0]].split(REPLICA)[0]
            result, seconds = self.rec.graphs[base, args[2]]
            action = (lambda: None)
        else:
            raise TypeError(f"a replay has no recorded unit for {getattr(fn, '__name__', fn)}")
        self.units += 1
        self.unit_seconds += seconds
        heapq.heappush(self.queue, (-priority, next(self.seq), self.now(), fut, seconds, action, result))
        self._dispatch()
        return fut

    def _dispatch(self) -> None:
        """Start queued units on simulated workers free by now (each at the later of its worker's free time and its
        submission)."""
        now = self.now()
        while self.queue and self.free[0] <= now:
            w = heapq.heappop(self.free)
            _, seq, submitted, fut, seconds, action, result = heapq.heappop(self.queue)
            finish = max(w, submitted) + seconds
            heapq.heappush(self.running, (finish, seq, fut, result, action))
            heapq.heappush(self.free, finish)

    def batches(self) -> Iterator[list]:
        """The finished units, in real time: the driver waits (idle) until the next one finishes."""
        while self.running or self.queue:
            self._dispatch()
            if not self.running:
                t = self.free[0] - self.now()
                if t > 0:
                    self.idle += t
                    time.sleep(t)
                continue
            wait = self.running[0][0] - self.now()
            if wait > 0:
                self.idle += wait
                time.sleep(wait)
            now = self.now()
            batch = []
            while self.running and self.running[0][0] <= now:
                _, _, fut, result, action = heapq.heappop(self.running)
                action()
                batch.append((fut, result))
            self._dispatch()
            yield batch

    def stop(self) -> None:
        """The replay's end: the driver returned (its last merge and summary included)."""
        self.wall = self.now()

    def utilisation(self) -> float:
        """The share of the replay's wall time the driver was busy (not waiting for a unit)."""
        return 1.0 - self.idle / self.wall if self.wall > 0 else 0.0

    def lower_bound(self) -> float:
        """The wall time N workers need at least: the units' seconds spread over them."""
        return self.unit_seconds / self.n

    def close(self) -> None:
        shutil.rmtree(self.staging / "parts", ignore_errors=True)


def copies_for(recording: Recording, workers: int, units_per_worker: float = 4.0) -> int:
    """Copies of the recorded parts that give `workers` workers `units_per_worker` units each."""
    return max(1, -(-int(workers * units_per_worker) // max(1, recording.units_per_copy())))
