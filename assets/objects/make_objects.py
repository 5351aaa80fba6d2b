"""Generate the workbench's own test objects (analogues of Table I of Wan & Harada) as binary STL in metres.

Run from the repository root:

    python assets/objects/make_objects.py

Every part is modelled in millimetres with manifold3d's boolean CSG (unions, differences,
extrusions, revolutions, hulls and warps), so each result is a closed, consistently oriented
2-manifold; it is scaled by 0.001 and written as binary STL by `write_stl` below. No randomness
and no timestamps are used, so running the script twice gives byte-identical files.
"""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import numpy as np
from manifold3d import CrossSection, JoinType, Manifold, OpType

OUT = Path(__file__).resolve().parents[2] / "workbench" / "assets" / "objects"  # shipped as package data
MM = 0.001


# --------------------------------------------------------------------------- helpers


def rounded_rect(w: float, h: float, r: float, seg: int) -> CrossSection:
    """A w x h rectangle centred on the origin with corners rounded to radius r."""
    return CrossSection.square((w - 2 * r, h - 2 * r), center=True).offset(r, JoinType.Round, circular_segments=seg)


def ellipse(a: float, b: float, seg: int) -> CrossSection:
    """An ellipse with semi-axes a (x) and b (y) as a polygon of `seg` vertices."""
    t = np.linspace(0.0, 2 * np.pi, seg, endpoint=False)
    return CrossSection([np.column_stack([a * np.cos(t), b * np.sin(t)])])


def airfoil(chord: float, thickness: float, n: int) -> CrossSection:
    """A symmetric NACA 00xx section (chord along x, quarter chord at the origin), 2n vertices, CCW."""
    beta = np.linspace(0.0, np.pi, n + 1)
    x = 0.5 * (1 - np.cos(beta))  # cosine spacing, 0 (leading edge) .. 1 (trailing edge)
    yt = 5 * thickness * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x**2 + 0.2843 * x**3 - 0.1015 * x**4)
    upper = np.column_stack([x[::-1], yt[::-1]])[:-1]  # trailing edge -> leading edge (excluded)
    lower = np.column_stack([x, -yt])  # leading edge -> trailing edge
    pts = np.vstack([upper, lower])
    pts[:, 0] = (pts[:, 0] - 0.25) * chord
    pts[:, 1] *= chord
    return CrossSection([pts])


def capsule(p0, p1, r: float, seg: int) -> Manifold:
    """The convex hull of two spheres of radius r centred at p0 and p1."""
    s = Manifold.sphere(r, seg)
    return Manifold.batch_hull([s.translate(tuple(p0)), s.translate(tuple(p1))])


def cyl_x(length: float, r: float, seg: int, x0: float = 0.0) -> Manifold:
    """A cylinder along +x from x0, axis through the origin."""
    return Manifold.cylinder(length, r, r, seg).rotate((0.0, 90.0, 0.0)).translate((x0, 0.0, 0.0))


def cyl_y(length: float, r: float, seg: int) -> Manifold:
    """A cylinder along y centred on the origin."""
    return Manifold.cylinder(length, r, r, seg, center=True).rotate((90.0, 0.0, 0.0))


def union(parts: list[Manifold]) -> Manifold:
    """Boolean union of several solids."""
    return Manifold.batch_boolean(parts, OpType.Add)


def centred(m: Manifold) -> Manifold:
    """Translate so that the bounding box is centred on the origin."""
    lo = np.asarray(m.bounding_box()[:3])
    hi = np.asarray(m.bounding_box()[3:])
    return m.translate(tuple(-(lo + hi) / 2))


# --------------------------------------------------------------------------- objects (millimetres)


def tube() -> Manifold:
    """TU analogue: a T-shaped thick-walled tube, 30 x 90 x 60 mm (main run along y, branch up +z)."""
    seg = 64
    run_out, run_in = cyl_y(90.0, 15.0, seg), cyl_y(92.0, 11.0, seg)
    branch_out = Manifold.cylinder(45.0, 13.0, 13.0, seg)
    branch_in = Manifold.cylinder(46.0, 9.0, 9.0, seg)
    bead = Manifold.cylinder(4.0, 15.0, 15.0, seg).translate((0.0, 0.0, 38.0))  # socket collar
    return (run_out + branch_out + bead) - run_in - branch_in


def wheel() -> Manifold:
    """PW analogue: a toy wheel, 60 mm diameter and 30 mm wide, tyre + web + hub revolved about z."""
    seg = 24
    tyre = rounded_rect(8.0, 30.0, 3.0, 8).translate((26.0, 0.0))
    web = CrossSection.square((16.0, 5.0), center=True).translate((15.0, 0.0))
    hub = CrossSection.square((6.0, 24.0), center=True).translate((6.0, 0.0))  # 3 mm axle bore
    body = (tyre + web + hub).revolve(seg)
    holes = [Manifold.cylinder(10.0, 3.5, 3.5, 16, center=True).translate((15.0 * np.cos(a), 15.0 * np.sin(a), 0.0))
             for a in np.linspace(0.0, 2 * np.pi, 5, endpoint=False)]
    return body - union(holes)


def planebody() -> Manifold:
    """PB analogue: a toy plane's lower body, an open tub 180 x 80 x 45 mm with bulkheads and bosses.

    The tail end narrows to 30 mm, so a parallel-jaw gripper can hold it across the tail as well as
    across the 45 mm height or a 3 mm wall.
    """
    xs = np.linspace(-90.0, 90.0, 61)
    # half width: 15 mm at the tail (x = -90), 40 mm amidships, a rounded nose at x = +90
    half = np.where(xs < 0.0, 15.0 + 25.0 * np.sin(np.clip((xs + 90.0) / 90.0, 0, 1) * np.pi / 2) ** 2,
                    40.0 * np.sqrt(np.clip(1.0 - (xs / 90.0) ** 4, 0.0, 1.0)))
    half[-1] = 0.0
    outline = np.vstack([np.column_stack([xs, -half])[:-1], np.column_stack([xs[::-1], half[::-1]])[:-1]])
    outer2d = CrossSection([outline])
    outer = Manifold.extrude(outer2d, 45.0)
    inner = Manifold.extrude(outer2d.offset(-3.0, JoinType.Round, circular_segments=24), 45.0).translate((0, 0, 3.0))
    body = outer - inner
    # the tail slopes down to 20 mm: cut by a plane through (x=-20, z=45) and (x=-90, z=20)
    n = np.array([25.0, 0.0, -70.0])
    n /= np.linalg.norm(n)
    body = body.trim_by_plane(tuple(n), float(n @ np.array([-20.0, 0.0, 45.0])))
    bulkheads = [Manifold.cube((3.0, 90.0, 45.0), center=True).translate((x, 0.0, 22.5)) for x in (-10.0, 35.0)]
    body = body + (union(bulkheads) ^ outer).trim_by_plane(tuple(n), float(n @ np.array([-20.0, 0.0, 45.0])))
    bosses, bores = [], []
    for x, y in ((-50.0, 0.0), (10.0, -22.0), (10.0, 22.0), (84.0, 0.0)):
        bosses.append(Manifold.cylinder(14.0, 5.0, 5.0, 32).translate((x, y, 0.0)))
        bores.append(Manifold.cylinder(20.0, 2.0, 2.0, 24).translate((x, y, 1.5)))
    cockpit = Manifold.extrude(rounded_rect(40.0, 44.0, 10.0, 32), 8.0).translate((58.0, 0.0, -1.0))
    slots = [Manifold.cube((30.0, 100.0, 8.0), center=True).translate((10.0, 0.0, 30.0))]  # wing slots in the walls
    return (body + union(bosses)) - union(bores) - union(slots) - cockpit


def bracket() -> Manifold:
    """PS analogue: an L-shaped support bracket, 60 x 100 x 80 mm, 6 mm plates, with filleted bend,
    two gusset ribs with lightening holes, four countersunk holes in the base, four holes and a slot in the wall."""
    seg = 176  # segments of holes and fillets
    # L profile in the (x, z) plane: base along x, wall along z, rounded outside corner, inside fillet
    profile = (CrossSection.square((60.0, 6.0)) + CrossSection.square((6.0, 80.0))
               + (CrossSection.square((6.0, 6.0)).translate((6.0, 6.0))
                  - CrossSection.circle(6.0, seg).translate((12.0, 12.0))))
    profile = profile - (CrossSection.square((10.0, 10.0)) - CrossSection.circle(10.0, seg).translate((10.0, 10.0)))
    solid = Manifold.extrude(profile, 100.0).rotate((90.0, 0.0, 0.0)).translate((0.0, 50.0, 0.0))
    # round the free corners of both plates
    base_outline = Manifold.extrude(rounded_rect(80.0, 100.0, 8.0, seg), 200.0).translate((20.0, 0.0, -100.0))
    wall_outline = (Manifold.extrude(rounded_rect(100.0, 100.0, 8.0, seg), 200.0)
                    .rotate((0.0, 90.0, 0.0)).translate((-100.0, 0.0, 30.0)))
    solid = solid ^ base_outline ^ wall_outline
    ribs = [Manifold.extrude(CrossSection([np.array([[0.0, 0.0], [44.0, 0.0], [0.0, 54.0]])]), 5.0)
            .rotate((90.0, 0.0, 0.0)).translate((5.0, y + 2.5, 5.0)) for y in (-30.0, 30.0)]
    solid = union([solid] + ribs)
    cuts = []
    for y in (-42.0, -14.0, 14.0, 42.0):
        cuts.append(Manifold.cylinder(20.0, 3.5, 3.5, seg, center=True).translate((40.0, y, 0.0)))  # base hole
        cuts.append(Manifold.cylinder(3.0, 3.5, 6.5, seg).translate((40.0, y, 3.001)))  # countersink
        cuts.append(cyl_x(20.0, 4.0, seg, -5.0).translate((0.0, y, 64.0)))  # wall hole
    cuts.append(Manifold.extrude(rounded_rect(40.0, 8.0, 4.0, seg), 20.0)
                .rotate((0.0, 90.0, 0.0)).translate((-5.0, 0.0, 42.0)))  # wall slot along y
    for y in (-30.0, 30.0):
        cuts.append(cyl_y(10.0, 6.0, seg).translate((18.0, y, 20.0)))  # lightening hole in the rib
    return solid - union(cuts)


def fin(chord_root: float, chord_tip: float, thickness: float, span: float, sweep: float,
        n_pts: int, n_div: int, symmetric: bool = False) -> Manifold:
    """A swept airfoil fin along +z (or +/-z about 0 when `symmetric`), its chord tapering faster toward the tip."""
    length = 2 * span if symmetric else span
    m = Manifold.extrude(airfoil(chord_root, thickness, n_pts), length, n_div)
    if symmetric:
        m = m.translate((0.0, 0.0, -span))

    def warp(v: np.ndarray) -> np.ndarray:
        t = np.abs(v[:, 2]) / span
        c = 1.0 - (1.0 - chord_tip / chord_root) * t**1.6  # chord ratio, tapering faster near the tip
        out = v.copy()
        out[:, 0] = v[:, 0] * c + sweep * t**1.3 + 0.25 * chord_root * (1.0 - c)
        out[:, 1] = v[:, 1] * c
        return out

    return m.warp_batch(warp)


def tail() -> Manifold:
    """PT analogue: a tail unit, 85 x 115 x 75 mm: a tapered vertical fin and stabilisers on a base."""
    base = Manifold.extrude(rounded_rect(85.0, 34.0, 6.0, 48), 8.0)
    holes = union([Manifold.cylinder(20.0, 2.5, 2.5, 32, center=True).translate((x, 0.0, 0.0)) for x in (-32.0, 32.0)])
    vfin = fin(76.0, 32.0, 0.14, 70.0, 30.0, 90, 27).translate((-21.0, 0.0, 5.0))
    hstab = (fin(56.0, 26.0, 0.12, 57.5, 16.0, 70, 23, symmetric=True)
             .rotate((-90.0, 0.0, 0.0)).translate((-18.0, 0.0, 10.0)))
    return (base + vfin + hstab) - holes


def drill() -> Manifold:
    """ED analogue: a cordless drill, 227 mm long: housing, chuck, fluted bit, pistol grip, battery, trigger guard."""
    seg = 192
    # motor housing revolved about x: domed back, cylindrical middle, tapering nose (profile in r, axial)
    a = np.linspace(0.0, np.pi / 2, 24)
    back = np.column_stack([30.0 * np.sin(a), -60.0 - 25.0 * np.cos(a)])  # r, x
    nose = np.array([[30.0, 30.0], [28.0, 40.0], [24.0, 48.0], [20.0, 50.0]])
    prof = np.vstack([[[0.0, -85.0]], back[1:], nose, [[0.0, 50.0]]])
    housing = CrossSection([prof]).revolve(seg).rotate((0.0, 90.0, 0.0))
    vents = union([Manifold.cube((3.0, 80.0, 16.0), center=True).translate((-70.0 + 7.0 * i, 0.0, 8.0)) for i in range(5)])
    housing = housing - (vents - Manifold.cube((60.0, 44.0, 40.0), center=True).translate((-60.0, 0.0, 0.0)))
    # knurled chuck: sinusoidal ridges, tapering toward the front, then a nose cone
    th = np.linspace(0.0, 2 * np.pi, 288, endpoint=False)
    r = 17.0 + 0.8 * np.cos(24 * th)
    chuck2d = CrossSection([np.column_stack([r * np.cos(th), r * np.sin(th)])])
    chuck = Manifold.extrude(chuck2d, 30.0, 9, 15.0, (0.85, 0.85)).rotate((0.0, 90.0, 0.0)).translate((48.0, 0.0, 0.0))
    chuck_nose = Manifold.cylinder(8.0, 13.0, 7.0, 64).rotate((0.0, 90.0, 0.0)).translate((78.0, 0.0, 0.0))
    # twist drill bit: two flutes, 2 turns, pointed tip
    bit2d = CrossSection.circle(4.0, 48) - CrossSection.circle(2.2, 32).translate((3.6, 0.0)) \
        - CrossSection.circle(2.2, 32).translate((-3.6, 0.0))
    bit = Manifold.extrude(bit2d, 60.0, 79, 720.0)
    tip = Manifold.cylinder(53.0, 6.0, 6.0, 48) + Manifold.cylinder(6.0, 6.0, 0.3, 48).translate((0.0, 0.0, 53.0))
    bit = (bit ^ tip).rotate((0.0, 90.0, 0.0)).translate((82.0, 0.0, 0.0))
    shank = cyl_x(8.0, 4.0, 48, 78.0)
    # pistol grip: elliptic section 44 x 32 mm, raked back, slightly waisted
    grip_h = 115.0
    grip = Manifold.extrude(ellipse(22.0, 16.0, 96), grip_h, 35)

    def rake(v: np.ndarray) -> np.ndarray:
        t = v[:, 2] / grip_h
        s = 1.0 - 0.08 * np.sin(np.pi * t)
        out = v.copy()
        out[:, 0] = v[:, 0] * s - 0.27 * v[:, 2]
        out[:, 1] = v[:, 1] * s
        out[:, 2] = -v[:, 2]
        return out

    grip = grip.warp_batch(rake).translate((-20.0, 0.0, 10.0))
    battery = Manifold.extrude(rounded_rect(84.0, 60.0, 10.0, 32), 26.0).translate((-44.0, 0.0, -120.0))
    battery = battery + Manifold.extrude(rounded_rect(70.0, 48.0, 8.0, 32), 6.0).translate((-44.0, 0.0, -96.0))
    # trigger guard: a bent rod from the housing's underside to the front of the grip
    guard_pts = [(30.0, 0.0, -18.0), (30.0, 0.0, -45.0), (18.0, 0.0, -68.0), (0.0, 0.0, -75.0), (-12.0, 0.0, -72.0)]
    guard = union([capsule(p, q, 4.5, 48) for p, q in zip(guard_pts[:-1], guard_pts[1:])])
    trigger = capsule((6.0, 0.0, -32.0), (4.0, 0.0, -48.0), 5.0, 48)
    switch = cyl_y(40.0, 4.0, 32).translate((-8.0, 0.0, -14.0))
    return union([housing, chuck, chuck_nose, shank, bit, grip, battery, guard, trigger, switch])


OBJECTS = {"tube": tube, "wheel": wheel, "planebody": planebody, "bracket": bracket, "tail": tail, "drill": drill}


# --------------------------------------------------------------------------- output


def to_arrays(m: Manifold) -> tuple[np.ndarray, np.ndarray]:
    """Vertices in metres (float64) and triangle indices of a manifold built in millimetres."""
    mesh = centred(m).to_mesh64()
    return np.asarray(mesh.vert_properties)[:, :3] * MM, np.asarray(mesh.tri_verts, dtype=np.int64)


def write_stl(path: Path, vertices: np.ndarray, faces: np.ndarray, name: str) -> None:
    """Write a binary STL with a fixed header (no timestamps), float32 coordinates and facet normals."""
    tri = vertices[faces].astype(np.float32)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).astype(np.float64)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    rec = np.zeros(len(faces), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["n"], rec["v"] = normal.astype(np.float32), tri
    header = f"regrasp workbench {name} (metres) - assets/objects/make_objects.py".encode()[:80].ljust(80, b" ")
    with open(path, "wb") as fh:
        fh.write(header + struct.pack("<I", len(faces)) + rec.tobytes())


def main(names: list[str]) -> None:
    """Build the named objects (all by default) and write <name>.stl next to this script."""
    for name in names or list(OBJECTS):
        solid = OBJECTS[name]()
        if solid.status().name != "NoError" or solid.is_empty():
            raise RuntimeError(f"{name}: manifold3d failed ({solid.status()})")
        v, f = to_arrays(solid)
        write_stl(OUT / f"{name}.stl", v, f, name)
        ext = (v.max(0) - v.min(0)) / MM
        print(f"{name}.stl: {len(f)} triangles, {ext[0]:.1f} x {ext[1]:.1f} x {ext[2]:.1f} mm, "
              f"volume {solid.volume() / 1e3:.1f} cm^3, genus {solid.genus()}")


if __name__ == "__main__":
    main(sys.argv[1:])
