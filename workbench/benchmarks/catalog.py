"""Catalogue build on a local Dask cluster with 1 and 2 workers (workers write Parquet files, the driver merges them
in batches): speed-up, time per unit kind, the driver's share; and, with `--simulate-workers`, the driver fed at the
rate N workers would feed it, with a cost model for a factory's part list.

The bundled parts (metres) and the paper's Table I parts (millimetres, when ../shared is present) x Panda and UR5,
on a coarser table grid than Table I's by default (`--full` for TabletopParams()), each run into a fresh store, on a
fresh cluster whose workers have imported the library before the timed region (`cluster_client`).

The driver saturates when the workers finish units faster than it handles them: with W workers busy it spends
W x (driver seconds / worker second), so it saturates at W* = worker seconds / driver seconds. CPU seconds are
measured per process (the driver, which also runs the scheduler, and each worker) and per unit (the thread that ran
it): wall seconds inside units above their CPU seconds mean the cores were shared (with the driver, or with other
processes: the load average is printed beside each run).

`--simulate-workers 16,64,256,1024` records every unit of the parts once (run here, one after the other: their
files, results and seconds), then replays them into the real driver and a real store through `ReplayClient`: each
unit finishes its recorded seconds after a simulated worker of N starts it, and the parts are copied under new names
until N workers have `--units-per-worker` units each. The driver's utilisation is the share of the replay's wall
time it was not waiting for a unit; on this shared machine its wall seconds stretch with the load, so the table also
gives it from the driver's CPU seconds (as on a core of its own).
"""

from __future__ import annotations

import argparse
import itertools
import os
import resource
import shutil
import statistics
import tempfile
import time
from pathlib import Path
from typing import Sequence

from workbench.benchmarks import print_table
from workbench.catalog.cluster import cluster_client
from workbench.catalog.driver import CatalogParams, build_catalog, collect_parts
from workbench.catalog.replay import ReplayClient, copies_for, record_units
from workbench.catalog.robots import parse_robots
from workbench.catalog.stages import FORMS
from workbench.errors import WorkbenchError
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.resources import bundled_objects, paper_objects

SATURATION_TARGET = 64
KINDS = ("part", "ik", "graph")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--objects", choices=["all", "bundled", "paper"], default="all")
    parser.add_argument("--robots", default="panda,ur5")
    parser.add_argument("--workers", dest="worker_counts", default="1,2",
                        help="worker counts to compare (comma-separated; none: only the simulation)")
    parser.add_argument("--simulate-workers", default=None, metavar="N,...",
                        help="replay recorded units into the driver as N workers would produce them, e.g. 16,64,256,1024")
    parser.add_argument("--forms", default="duckdb,parquet",
                        help="the catalogue's forms to build (comma-separated: duckdb, parquet)")
    parser.add_argument("--units-per-worker", type=float, default=4.0, help="units per simulated worker (parts copied)")
    parser.add_argument("--cost-parts", type=int, default=10_000, help="parts of the cost model")
    parser.add_argument("--cost-robots", type=int, default=4, help="robots of the cost model")
    parser.add_argument("--cost-cores", type=int, default=256, help="cores of the cost model's wall time")
    parser.add_argument("--repeats", type=int, default=1, help="runs of each configuration (the median run is shown)")
    parser.add_argument("--full", action="store_true", help="Table I's grid (21 positions x 8 angles, 80 grasps)")
    parser.add_argument("--ik-chunk", type=int, default=1024, help="tabletop grips per IK unit")


def bench_parts(which: str) -> list[tuple[Path, float]]:
    """(mesh, scale to metres) of the bundled parts and of the paper's parts (millimetres)."""
    parts: list[tuple[Path, float]] = []
    if which in ("all", "bundled"):
        parts += [(p, 1.0) for p in bundled_objects().values()]
    if which in ("all", "paper"):
        parts += [(p, 0.001) for p in paper_objects().values()]
    return parts


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def one_run(parts, robots: str, params: CatalogParams, workers: int, tmp: Path, form: str = "duckdb"):
    """One build on a fresh cluster into a catalogue of `form`: (result, driver process CPU s, workers' process CPU s,
    load before, after)."""
    with cluster_client(workers=workers) as client:
        load0 = os.getloadavg()[0]
        w0, d0 = client.run(_cpu), _cpu()
        db = tmp / ("catalog.duckdb" if form == "duckdb" else "catalog")
        res = build_catalog(parts, robots, db, client, params, progress=False, form=form)
        w1, d1 = client.run(_cpu), _cpu()
        load1 = os.getloadavg()[0]
    return res, d1 - d0, sum(w1[k] - w0.get(k, 0.0) for k in w1), load0, load1


def run(args: argparse.Namespace) -> int:
    parts = bench_parts(args.objects)
    tparams = TabletopParams() if args.full else TabletopParams(nx=3, ny=3, angles=4, max_grasps=40)
    params = CatalogParams(tabletop=tparams, ik_chunk=args.ik_chunk)
    if args.simulate_workers:
        simulated = _counts(args.simulate_workers, "--simulate-workers")
        with tempfile.TemporaryDirectory() as tmp:
            rec, rows = simulate(parts, args.robots, params, simulated, args.units_per_worker, Path(tmp), _forms(args.forms))
            print_simulation(rec, rows, args)
        if args.worker_counts in ("", "none"):
            return 0
    counts = _counts(args.worker_counts, "--workers")
    paths = _forms(args.forms)
    # each form's first worker count is its base
    configs = [(w, path) for path in paths for w in counts]
    runs = {}
    for w, path in configs:
        done = []
        for _ in range(max(1, args.repeats)):
            with tempfile.TemporaryDirectory() as tmp:
                done.append(one_run(parts, args.robots, params, w, Path(tmp), path))
        done.sort(key=lambda r: r[0].wall)
        runs[w, path] = done[len(done) // 2]  # the median run
    print(f"catalogue: {len(parts)} parts x {args.robots} ({'Table I grid' if args.full else 'grid 3x3 positions, 4 angles, 40 grasps'}), "
          f"IK chunk {args.ik_chunk}, median of {max(1, args.repeats)} run(s); {os.cpu_count()} cores")
    rows = []
    for (w, path), (r, dcpu, wcpu, l0, l1) in runs.items():
        base = runs[counts[0], path][0]
        worker_s = sum(r.compute.values())
        rows.append((w, path, sum(r.computed.values()), round(r.wall, 1), round(base.wall / r.wall, 2) if r.wall else "-",
                     round(worker_s, 1), round(sum(r.cpu.values()), 1), f"{worker_s / (w * r.wall):.0%}" if r.wall else "-",
                     round(wcpu, 1), round(dcpu, 1), round(r.write_seconds, 2),
                     f"{r.write_seconds / r.wall:.1%}" if r.wall else "-", r.rows_written,
                     round(r.rows_written / r.write_seconds) if r.write_seconds else "-",
                     round(worker_s / r.write_seconds) if r.write_seconds else "-", f"{l0:.1f}-{l1:.1f}", len(r.failures)))
    print_table(("workers", "form", "units", "wall s", "speed-up", "unit s", "unit cpu s", "busy", "worker cpu s",
                 "driver cpu s", "driver s", "driver share", "rows", "rows/s written", "saturates at", "load", "failed"), rows)
    print_table(("workers", "form", "write transactions", "merges", "decode s", "rows s", "commit s", "schedule s", "merge s",
                 "graphs s"),
                [(w, path, r.batches, r.merges,
                  *(round(r.driver[k], 2) for k in ("decode", "rows", "commit", "schedule", "merge", "graph")))
                 for (w, path), (r, *_) in runs.items()], title="driver time (all of it on finished units)")
    kinds = []
    for (w, path), (r, *_) in runs.items():
        for kind in KINDS:
            k = r.computed[kind]
            dk = r.driver_kind[kind]
            kinds.append((w, path, kind, k, round(r.compute[kind], 2), round(r.cpu[kind], 2),
                          round(r.compute[kind] / k, 3) if k else "-", round(r.cpu[kind] / k, 3) if k else "-",
                          round(dk, 2), round(1000 * dk / k, 1) if k else "-",
                          round(r.compute[kind] / dk, 1) if dk else "-"))
    print_table(("workers", "form", "unit kind", "units", "unit s", "unit cpu s", "s per unit", "cpu s per unit",
                 "driver s", "driver ms per unit", "saturates at"), kinds,
                title="time per unit kind (saturates at: unit s / driver s, for a build of this kind of unit only)")
    tails = []
    for (w, path), (r, *_) in runs.items():
        if r.timeline:
            end = r.start + r.wall
            last = {}
            for worker, _, _, e in r.timeline:
                last[worker] = max(last.get(worker, 0.0), e)
            first = min(s for _, _, s, _ in r.timeline) - r.start
            idle_end = statistics.mean(end - e for e in last.values())
            tails.append((w, path, round(first, 2), round(idle_end, 2), round(max(last.values()) - min(last.values()), 2)))
    print_table(("workers", "form", "first unit starts s", "idle at the end s (mean)", "workers' last ends spread s"),
                tails, title="the start and the tail")
    two = [(w, path) for w, path in runs if w == counts[-1]] or list(runs)
    for key in two:
        r = runs[key][0]
        sat = sum(r.compute.values()) / r.write_seconds if r.write_seconds else float("inf")
        verdict = "below" if sat < SATURATION_TARGET else "at or above"
        writing = sum(r.driver[k] for k in ("rows", "commit", "merge"))
        base = runs[counts[0], key[1]][0]
        print(f"{key[1]}: speed-up {base.wall / r.wall:.2f} with {key[0]} workers (target >= 1.8); writing (rows, commits, "
              f"merges) {writing / r.wall:.1%} of the wall time (target <= 10%), the driver in all (with scheduling and "
              f"decoding) {r.write_seconds / r.wall:.1%}; the single writer saturates at about {sat:.0f} workers ({verdict} "
              f"{SATURATION_TARGET}).")
    # On free cores each process would run at its CPU seconds: W workers and the driver (which also runs the scheduler)
    # share min(cores, W + 1) cores, and no worker finishes before its share of the units' CPU seconds.
    cores = os.cpu_count() or 1

    def free_wall(key) -> float:
        _, dcpu, wcpu, *_ = runs[key]
        return max(wcpu / key[0], (wcpu + dcpu) / min(cores, key[0] + 1))

    print("on free cores (from the CPU seconds above): " + "; ".join(
        f"{path} {w} worker(s) {free_wall((w, path)):.1f} s, speed-up {free_wall((counts[0], path)) / free_wall((w, path)):.2f}"
        for w, path in runs))
    last = runs[two[0]][0]
    inflation = (sum(last.compute.values()) / max(sum(last.cpu.values()), 1e-9))
    if inflation > 1.15:
        print(f"note: with {two[0][0]} workers the units took {inflation:.2f}x their CPU seconds in wall time: the cores "
              f"were shared (the driver and scheduler, or other processes; see the load), so part of the missing "
              f"speed-up is the machine's, not the design's.")
    return 0


def _forms(text: str) -> list[str]:
    forms = [f.strip() for f in text.split(",") if f.strip()]
    if not forms or any(f not in FORMS for f in forms):
        raise WorkbenchError(f"--forms takes {', '.join(FORMS)} (comma-separated), got {text!r}")
    return forms


def _counts(text: str, option: str) -> list[int]:
    try:
        out = [int(w) for w in text.split(",") if w.strip()]
    except ValueError:
        raise WorkbenchError(f"{option} takes comma-separated worker counts, got {text!r}") from None
    if not out or min(out) < 1:
        raise WorkbenchError(f"{option} takes worker counts >= 1, got {text!r}")
    return out


def simulate(parts, robots: str, params: CatalogParams, counts: list[int], per_worker: float, tmp: Path,
             forms: Sequence[str] = ("duckdb",)):
    """Record every unit once, then replay them into the driver for each simulated worker count and catalogue form:
    (recording, rows)."""
    catalog = parse_robots(robots)
    rec = record_units(collect_parts(parts), catalog, params, tmp / "recorded")
    rows = []
    for n, form in itertools.product(counts, forms):
        client = ReplayClient(rec, n, copies_for(rec, n, per_worker), tmp / f"staging-{n}-{form}")
        db = tmp / (f"replay-{n}.duckdb" if form == "duckdb" else f"replay-{n}")
        load0, c0 = os.getloadavg()[0], time.process_time()
        res = build_catalog(client.parts(), catalog, db, client, params, progress=False, form=form)
        client.stop()
        cpu = time.process_time() - c0
        size = db.stat().st_size if db.is_file() else sum(f.stat().st_size for f in db.rglob("*") if f.is_file())
        rows.append({"workers": n, "form": form, "parts": len(client.parts()), "units": client.units,
                     "unit_s": client.unit_seconds,
                     "bound": client.lower_bound(), "wall": client.wall, "idle": client.idle, "cpu": cpu,
                     "util": client.utilisation(), "own": cpu / (cpu + client.idle) if cpu + client.idle else 0.0,
                     "merges": res.merges, "rows": res.rows_written, "bytes": size,
                     "failed": len(res.failures), "load": f"{load0:.1f}-{os.getloadavg()[0]:.1f}"})
        client.close()
        shutil.rmtree(db) if db.is_dir() else db.unlink()
    return rec, rows


def print_simulation(rec, rows: list[dict], args: argparse.Namespace) -> None:
    print(f"recorded units: {len(rec.parts)} parts x {args.robots}: {len(rec.parts)} part, {len(rec.ik)} IK, "
          f"{len(rec.graphs)} graph units, {sum(s for *_, s in rec.parts.values()) + sum(s for *_, s in rec.ik.values()) + sum(s for _, s in rec.graphs.values()):.1f} s "
          f"(run here one after the other)")
    print_table(("simulated workers", "form", "parts", "units", "unit s", "at least s", "wall s", "driver idle s", "driver cpu s",
                 "utilisation", "utilisation (own core)", "merges", "rows", "failed", "load"),
                [(r["workers"], r["form"], r["parts"], r["units"], round(r["unit_s"], 1), round(r["bound"], 1), round(r["wall"], 1),
                  round(r["idle"], 1), round(r["cpu"], 1), f"{r['util']:.0%}", f"{r['own']:.0%}", r["merges"],
                  f"{r['rows']:,}", r["failed"], r["load"]) for r in rows],
                title="the driver fed by N simulated workers (target: below 50% at 256)")
    # the cost model: per part and robot from the recorded units, the driver's and the disk's from the replays
    nparts, nrobots = len(rec.parts), max(1, len({r for _, r, _ in rec.ik} | {r for _, r in rec.graphs}))
    part_s = sum(s for *_, s in rec.parts.values()) / nparts
    run_s = (sum(s for *_, s in rec.ik.values()) + sum(s for _, s in rec.graphs.values())) / (nparts * nrobots)
    units_part = 1 + (len(rec.ik) + len(rec.graphs)) / nparts / nrobots * args.cost_robots
    big = max(rows, key=lambda r: (r["parts"], r["form"] == "parquet"))
    rows_part = big["rows"] / big["parts"] / nrobots  # rows of one part and one robot's IK rows, measured
    driver_unit = big["cpu"] / big["units"]
    p, k, cores = args.cost_parts, args.cost_robots, args.cost_cores
    cpu_s = p * (part_s + k * run_s)
    units = p * units_part
    total_rows = p * k * rows_part
    bytes_ = big["bytes"] / big["rows"] * total_rows if big["rows"] else 0
    wall = max(cpu_s / cores, units * driver_unit)
    print_table(("parts", "robots", "units", "CPU-hours", "rows", "bytes on disk", f"wall on {cores} cores",
                 "bound by", "driver s per unit"),
                [(f"{p:,}", k, f"{units:,.0f}", round(cpu_s / 3600, 1), f"{total_rows:,.0f}", f"{bytes_ / 1e9:.1f} GB",
                  f"{wall / 3600:.2f} h", "workers" if cpu_s / cores >= units * driver_unit else "driver",
                  f"{driver_unit * 1000:.1f} ms")],
                title=f"cost model: per part {part_s:.1f} s of part unit and {run_s:.1f} s of IK and graph per robot "
                      f"(recorded here), rows, bytes and the driver per part from the largest replay ({big['form']})")
