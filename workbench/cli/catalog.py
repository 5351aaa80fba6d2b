"""`workbench catalog build PARTS... --robots panda,ur5 --db DB`: grasps, placements, tabletop grips and IK of many
parts for several robots on a Dask cluster (Wan & Harada's fully off-line stages, Sections III-V), and
`workbench catalog report --db DB` to print the stored catalogue again."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from workbench.benchmarks import print_table
from workbench.catalog.cluster import cluster_client, dashboard_link
from workbench.catalog.stages import FORMS, open_store
from workbench.catalog.driver import (
    SUMMARY_HEADERS,
    CatalogParams,
    build_catalog,
    catalog_columns,
    collect_parts,
    report,
    summary_table,
)
from workbench.catalog.report import html_page, wide_table
from workbench.catalog.robots import CatalogRobot, RobotListError, file_grippers, parse_robots
from workbench.cli.grasps import SCALE, add_grasp_arguments, grasp_params
from workbench.cli.ik import RETRACT, WORKERS, parse_base, parse_mount
from workbench.cli.gripper import add_gripper_argument, add_grippers_argument, grippers_from_args
from workbench.cli.outputs import add_output, write_text
from workbench.cli.placements import add_placement_arguments, placement_params
from workbench.params import add_param, cli_bound, parse_number
from workbench.planners.wan_harada.stages import HANDX, WORLDZ
from workbench.robots.ik import WORLDA, IKOptions
from workbench.robots.model import ROBOTS

IK_CHUNK = cli_bound(1, 1 << 20, integer=True, help="tabletop grips per IK unit")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("catalog", help="build a parts x robots catalogue on a Dask cluster, or print one")
    inner = parser.add_subparsers(dest="action", required=True, parser_class=type(parser))
    b = inner.add_parser("build", help="compute every part's stages and every robot's IK on a local or existing cluster",
                         description="Progress: a bar per unit kind (parts, IK chunks, graphs) with its rate and ETA on "
                                     "stderr, and the Dask dashboard's address (its pages need bokeh: "
                                     "pip install 'regrasp-workbench[catalog]').")
    b.add_argument("parts", nargs="+",
                   help="mesh files (STL, OBJ, PLY, OFF, GLB, DAE) or folders of them; the file name names the part")
    b.add_argument("--robots", required=True, metavar="ROBOT,...|FILE.yaml",
                   help=f"the catalogue's robots, one column each: built-in names ({', '.join(ROBOTS)}) and NAME=URDF "
                        "entries (these take --tip, --mount, --base, --hand-links), comma-separated; or a YAML file "
                        "listing robots with their URDF, tip, mount, base, hand links and table (and the catalogue's "
                        "grippers)")
    b.add_argument("--tip", default=None, help="the URDF robots' tip frame")
    b.add_argument("--mount", default=None, help="the URDF robots' tip frame to gripper TCP: x,y,z,roll,pitch,yaw (m, rad)")
    b.add_argument("--base", default=None, help="the URDF robots' base in the world: X,Y,Z,YAW (m, rad)")
    b.add_argument("--hand-links", default=None, metavar="PREFIX,...",
                   help="the URDF robots' own hand links, replaced by the planning gripper (default: the links past --tip)")
    b.add_argument("--db", required=True,
                   help="the catalogue: a DuckDB store file, or with --form parquet a folder (created when missing; a "
                        "re-run resumes)")
    b.add_argument("--form", choices=FORMS, default="duckdb",
                   help="a new catalogue's form: one DuckDB file, or a folder of Hive-partitioned Parquet files (TABLE/"
                        "part=NAME/..., ik/part=NAME/robot=NAME/...) with its shared tables in catalog.duckdb, which "
                        "`plan`, `catalog report` and DuckDB read as they are (default duckdb)")
    where = b.add_mutually_exclusive_group()
    where.add_argument("--workers", type=parse_number(WORKERS, "--workers"), default=None, metavar="N",
                       help=f"worker processes of a local cluster ({WORKERS.describe(True)}, and within the memory budget; "
                            f"default: all cores)")
    where.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler, e.g. tcp://host:8786")
    unit = b.add_mutually_exclusive_group()
    unit.add_argument("--scale", type=parse_number(SCALE, "--scale"), default=None, metavar="X",
                      help=f"factor from the files' units to metres, e.g. 0.001 ({SCALE.describe(True)})")
    unit.add_argument("--units", choices=["m", "cm", "mm", "in"], default=None, help="the files' unit")
    for flag, default, text in (("--handx", HANDX, "retraction along the approach axis"),
                                ("--worldz", WORLDZ, "retraction up along world z"),
                                ("--worlda", WORLDA, "lift of the held object straight up")):
        b.add_argument(flag, type=parse_number(RETRACT, flag), default=default, metavar="M",
                       help=f"{text} ({RETRACT.describe(True)}; default {default})")
    o = IKOptions()
    b.add_argument("--ik-chunk", type=parse_number(IK_CHUNK, "--ik-chunk"), default=1024, metavar="N",
                   help=f"tabletop grips per IK unit ({IK_CHUNK.describe(True)}; default 1024)")
    add_param(b, IKOptions, "library", "--ik-library", cli_default=o.library)
    add_param(b, IKOptions, "seeds", "--ik-seeds", cli_default=o.seeds)
    add_output(b, "--shards", folder=True,
               help="the folder of the units' Parquet files, which the driver merges into the store in batches (default "
                    "DB.units beside the store; with a cluster of several machines, on a file system every worker "
                    "sees); files a killed build left there are merged by the re-run")
    b.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_placement_arguments(b)
    add_grasp_arguments(b)
    add_gripper_argument(b)
    add_grippers_argument(b)
    b.set_defaults(func=run_build)
    r = inner.add_parser("report", help="print the summary table of a stored catalogue")
    r.add_argument("--db", required=True, help="the catalogue: a DuckDB store file or a Parquet catalogue's folder")
    add_output(r, "--html", suffixes=(".html",), metavar="OUT.html",
               help="also write the parts x robots table as a page with a thumbnail of each part")
    r.set_defaults(func=run_report)


def catalog_params(args: argparse.Namespace) -> CatalogParams:
    pparams, tparams = placement_params(args)
    ik = replace(CatalogParams().ik, library=args.ik_library, seeds=args.ik_seeds)
    return CatalogParams(grasps=grasp_params(args), placements=pparams, tabletop=tparams, ik=ik, handx=args.handx,
                         worldz=args.worldz, worlda=args.worlda, ik_chunk=args.ik_chunk, scale=args.scale, units=args.units)


def catalog_robot_list(args: argparse.Namespace) -> list[dict[str, CatalogRobot]]:
    """The catalogue's columns, one robot list per gripper (--gripper or --grippers, or the robots file's grippers;
    default the Franka hand), from --robots and the URDF entries' --tip, --mount, --base, --hand-links."""
    given, listed = grippers_from_args(args), file_grippers(args.robots)
    if given and listed:
        raise RobotListError(f"the robots file {args.robots} lists grippers; give them there or with --grippers, not both")
    mount, base = parse_mount(args.mount) if args.mount else None, parse_base(args.base) if args.base else None
    hand_links = tuple(h.strip() for h in (args.hand_links or "").split(",") if h.strip())
    return [parse_robots(args.robots, tip=args.tip, mount=mount, base=base, hand_links=hand_links, gripper=g)
            for g in (given or listed or [None])]


def run_build(args: argparse.Namespace) -> int:
    params = catalog_params(args)
    collect_parts(args.parts)  # bad input fails before a cluster starts: parts, robots, a locked or damaged store
    robots = catalog_robot_list(args)
    catalog_columns(robots)  # a gripper listed twice, too
    open_store(args.db, form=args.form).close()
    with cluster_client(workers=args.workers, scheduler=args.scheduler) as client:
        n = len(client.scheduler_info().get("workers", {}))
        print(f"dask: {n} worker(s) at {client.scheduler.address}; dashboard {dashboard_link(client)}", file=sys.stderr)
        res = build_catalog(args.parts, robots, args.db, client, params, progress=not args.no_progress,
                            shards=args.shards, form=args.form)
    print_summary(res.rows, res.failures)
    write_share = f", writing {res.write_seconds / res.wall:.0%} of it" if res.wall > 0 else ""
    print(f"{sum(res.computed.values())} units computed ({res.computed['part']} part, {res.computed['ik']} IK, "
          f"{res.computed['graph']} graph), {res.skipped} skipped (already stored), {len(res.failures)} failed; "
          f"{res.rows_written:,} rows written in {res.wall:.1f} s on {res.workers} worker(s){write_share}; store {args.db}")
    if res.failures and not res.rows:  # nothing was built: a failure, not a result
        print(f"workbench catalog: error: no part of {' '.join(map(str, args.parts))} could be built "
              f"({len(res.failures)} failed, each listed above with its reason)", file=sys.stderr)
        return 2
    return 0


def run_report(args: argparse.Namespace) -> int:
    rows, failures, meshes = report(args.db, meshes=args.html is not None)
    print_summary(rows, failures)
    if rows:
        headers, table = wide_table(rows)
        print()
        print_table(headers, table, title="parts x (robot, gripper): reachable grips (IK-feasible at all five poses, of the "
                                          "tabletop grips) and the regrasp graph's connected share (nodes in its largest "
                                          "component)")
    if args.html is not None:
        out = write_text(args.html, html_page(rows, failures, meshes, f"Catalogue {Path(args.db).name}"))
        print(f"html: {out.resolve()}")
    return 0


def print_summary(rows: list[dict], failures: list[dict]) -> None:
    """The parts x robots table, then one line per failed part or unit, or a warning when nothing is stored."""
    if rows:
        print_table(SUMMARY_HEADERS, summary_table(rows))
    else:
        print("warning: the catalogue holds no finished part yet", file=sys.stderr)
    empty = set()
    several = len({r.get("gripper") for r in rows}) > 1
    for r in rows:
        key = (r["part"], r.get("gripper"))
        name = f"{r['part']} with {r['gripper']}" if several else r["part"]
        if (not r["grasps"] or not r["tabletop_grips"]) and key not in empty:
            empty.add(key)
            what = ("free-air grasps" if not r["grasps"] else "stable placements" if not r["placements"]
                    else "tabletop grips (no stable placement keeps a grasp clear of the table)")
            why = f"stage {r['reason']}" if r.get("reason") else "check its size and units"
            print(f"warning: {name} has no {what}; {why}", file=sys.stderr)
        elif key not in empty and r["robot"] and r["ik_rows"] and not r["ik_feasible"]:
            print(f"warning: no tabletop grip of {name} is IK-feasible for {r['robot']} at all five poses",
                  file=sys.stderr)
    for f in failures:
        what = f["part"] if not f["robot"] else f"{f['part']} x {f['robot']} ({f['kind']})"
        if f.get("gripper") and several:
            what += f" with {f['gripper']}"
        print(f"failed: {what} ({f['source']}): {f['error']}")
