"""A real gripper model beside the bundled spec that stands for it: MuJoCo drives an MJCF gripper (a closed linkage
held by equality constraints, such as MuJoCo Menagerie's robotiq_2f85/2f85.xml) along its actuator's range and
measures its opening, pads, body and TCP, beside `robotiq-2f85`'s spec (CONVENTIONS.md, Gripper spec)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from workbench.benchmarks import print_table
from workbench.errors import GripperError
from workbench.robots.gripper import BUNDLED, read_spec


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mjcf", required=True, metavar="XML",
                        help="the gripper's MJCF, e.g. MuJoCo Menagerie's robotiq_2f85/2f85.xml (its frame: origin on the "
                             "coupling face, +z toward the fingertips)")
    parser.add_argument("--spec", default=str(BUNDLED["robotiq-2f85"]), help="the spec to compare (default robotiq-2f85)")
    parser.add_argument("--pads", default="left_pad,right_pad", metavar="LEFT,RIGHT", help="the pads' body names")
    parser.add_argument("--palm", default="base", metavar="BODY", help="the body whose collision meshes are the palm")
    parser.add_argument("--tcp-site", default="pinch", metavar="SITE", help="the model's TCP site")
    parser.add_argument("--samples", type=int, default=9, help="actuator settings along its range")


def _points(m, data, geoms) -> np.ndarray:
    """World points of collision geoms: box corners or mesh vertices."""
    out = []
    for g in geoms:
        R, p = data.geom_xmat[g].reshape(3, 3), data.geom_xpos[g]
        if m.geom_type[g] == 6:  # box
            local = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * m.geom_size[g]
        elif m.geom_type[g] == 7:  # mesh
            i = m.geom_dataid[g]
            local = m.mesh_vert[m.mesh_vertadr[i]: m.mesh_vertadr[i] + m.mesh_vertnum[i]]
        else:
            continue
        out.append(local @ R.T + p)
    return np.vstack(out)


def measure(mjcf: str | Path, pads: tuple[str, str] = ("left_pad", "right_pad"), palm: str = "base",
            tcp_site: str = "pinch", samples: int = 9) -> dict:
    """Opening, pad size, pad height and tilt, palm extents, TCP and mass of an MJCF gripper, settled at `samples`
    actuator settings with gravity off (lengths in metres, in the model's frame; the jaw axis from pad to pad)."""
    import mujoco

    path = Path(mjcf)
    if not path.is_file():
        raise GripperError(f"gripper MJCF {path} does not exist")
    try:
        m = mujoco.MjModel.from_xml_path(str(path))
    except Exception as exc:
        raise GripperError(f"gripper MJCF {path} could not be loaded ({str(exc).splitlines()[0]})") from None
    d = mujoco.MjData(m)
    m.opt.gravity[:] = 0
    body = {name: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name) for name in (*pads, palm)}
    missing = [n for n, i in body.items() if i < 0]
    if missing or m.nu == 0:
        raise GripperError(f"gripper MJCF {path} has no body {missing[0]!r}" if missing else f"gripper MJCF {path} has no actuator")
    geoms = {n: [g for g in range(m.ngeom) if m.geom_bodyid[g] == i and m.geom_contype[g]] for n, i in body.items()}
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, tcp_site)
    rows = []
    for ctrl in np.linspace(*m.actuator_ctrlrange[0], samples):
        mujoco.mj_resetData(m, d)
        d.ctrl[0] = ctrl
        for _ in range(4000):  # 8 s at the default step: the linkage settles
            mujoco.mj_step(m, d)
        left, right = _points(m, d, geoms[pads[0]]), _points(m, d, geoms[pads[1]])
        jaw = left.mean(axis=0) - right.mean(axis=0)
        jaw /= np.linalg.norm(jaw)
        R = d.xmat[body[pads[0]]].reshape(3, 3)
        tilt = np.degrees(np.arccos(min(1.0, np.abs(R.T @ jaw).max())))
        rows.append({"opening": float((left @ jaw).min() - (right @ jaw).max()), "pad_z": float(left[:, 2].mean()),
                     "tilt": float(tilt), "jaw": jaw, "left": left})
    open_ = max(rows, key=lambda r: r["opening"])
    jaw = open_["jaw"]
    across = np.cross([0.0, 0.0, 1.0], jaw)
    pad = open_["left"]
    palm_pts = _points(m, d, geoms[palm])
    mid = np.interp(0.5 * (rows[0]["opening"] + rows[-1]["opening"]), sorted(r["opening"] for r in rows),
                    [r["pad_z"] for r in sorted(rows, key=lambda r: r["opening"])])
    return {"opening": (min(r["opening"] for r in rows), open_["opening"]),
            "pad_size": (float(np.ptp(pad @ across)), float(np.ptp(pad[:, 2]))), "pad_thickness": float(np.ptp(pad @ jaw)),
            "pad_z": (open_["pad_z"], float(mid), min(rows, key=lambda r: r["opening"])["pad_z"]),
            "tilt": max(r["tilt"] for r in rows),
            "palm": (float(np.ptp(palm_pts @ across)), float(np.ptp(palm_pts @ jaw)), float(palm_pts[:, 2].max())),
            "tcp": float(d.site_xpos[site][2]) if site >= 0 else float("nan"), "mass": float(m.body_mass.sum())}


def run(args: argparse.Namespace) -> int:
    got = measure(args.mjcf, tuple(args.pads.split(",")), args.palm, args.tcp_site, args.samples)
    spec = read_spec(args.spec)
    mm = lambda v: f"{v * 1e3:.1f}"  # noqa: E731
    palm_top = spec["palm"]["offset"][2] + spec["palm"]["size"][2] / 2
    rows = [["opening min / max (mm)", f"{mm(got['opening'][0])} / {mm(got['opening'][1])}",
             f"{mm(spec['stroke'][0])} / {mm(spec['stroke'][1])}"],
            ["pad across the jaw x along the approach (mm)", f"{mm(got['pad_size'][0])} x {mm(got['pad_size'][1])}",
             " x ".join(mm(v) for v in spec["pad"]["size"])],
            ["pad thickness along the jaw (mm)", mm(got["pad_thickness"]), mm(spec["pad"]["thickness"])],
            ["pad centre from the coupling face, open / mid / closed (mm)", " / ".join(mm(v) for v in got["pad_z"]),
             f"{mm(spec['tcp'][2])} at every opening"],
            ["largest pad turn over the stroke (deg)", f"{got['tilt']:.2f}", "0 (translating pads)"],
            ["body across the jaw / along the jaw / top (mm)", " / ".join(mm(v) for v in got["palm"]),
             f"{mm(spec['palm']['size'][0])} / {mm(spec['palm']['size'][1])} / {mm(palm_top)}"],
            ["TCP from the coupling face (mm)", mm(got["tcp"]), mm(spec["tcp"][2])],
            ["mass (kg)", f"{got['mass']:.3f}", f"{spec.get('mass', float('nan')):.3f}"]]
    print_table(["quantity", f"MJCF {Path(args.mjcf).name} (MuJoCo, settled)", f"spec {Path(args.spec).name}"], rows,
                title=f"A gripper model beside its spec: the MJCF driven over its actuator's range at {args.samples} "
                      f"settings, gravity off; the spec's pads translate at its TCP height")
    return 0

