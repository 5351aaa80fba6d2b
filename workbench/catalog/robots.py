"""The robots of a catalogue: its columns (Wan & Harada Section IV's IK stage is run once per part and column).

`--robots` takes built-in names and `NAME=URDF` entries (the URDF entries share `--tip`, `--mount`, `--base` and
`--hand-links`), or the path of a small YAML file:

    robots:
      - panda                          # a built-in robot, its default base and table
      - name: ur10
        urdf: ur10.urdf                # relative to the YAML file
        tip: tool0
        mount: [0, 0, 0.1034, 0, 0, 0] # tip to TCP: x, y, z (m), roll, pitch, yaw (rad)
        base: [0, 0, 0, 0]             # x, y, z (m), yaw (rad)
        hand_links: []                 # link-name prefixes of the robot's own hand
        table: [0.2, -0.6, 1.0, 0.6]   # table top corners XMIN, YMIN, XMAX, YMAX (m)
    grippers:                          # optional: the catalogue's grippers, each a column with every robot
      - franka                         # a bundled gripper
      - my_gripper.yaml                # a spec file, relative to the YAML file
      - file: my_gripper.urdf          # a gripper URDF and its parts
        hand: hand_link
        fingers: [left_joint, right_joint]
        tcp: tcp_frame                 # optional
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from workbench.errors import RobotError, WorkbenchError
from workbench.robots.collider import Collider, Scene, default_scene
from workbench.robots.gripper import BUNDLED, Gripper, load_gripper
from workbench.robots.model import Robot, get_robot, pose_xyz_yaw, robot_from_spec

ROBOT_FILE_SUFFIXES = (".yaml", ".yml")


class RobotListError(WorkbenchError):
    """A bad `--robots` list or robots file."""


@dataclass(frozen=True)
class CatalogRobot:
    """One column of the catalogue: a robot (with its planning gripper) and the table it works at."""

    name: str
    robot: Robot
    scene: Scene


def _numbers(value: Any, n: int, what: str) -> list[float]:
    try:
        vals = [float(v) for v in value]
    except (TypeError, ValueError):
        raise RobotListError(f"{what} must be a list of {n} numbers, got {value!r}") from None
    if len(vals) != n or not np.isfinite(vals).all():
        raise RobotListError(f"{what} must be a list of {n} finite numbers, got {value!r}")
    return vals


def _radians(vals: Sequence[float], what: str) -> None:
    if any(abs(v) > 2 * np.pi + 1e-9 for v in vals):
        raise RobotListError(f"{what}: angles are radians, as in a URDF, within [-2 pi, 2 pi]; got {list(vals)}")


def base_pose(value: Any, what: str = "base") -> np.ndarray:
    """[x, y, z, yaw] (m, rad) as a base pose in the world."""
    vals = _numbers(value, 4, f"{what} (x, y, z, yaw)")
    _radians(vals[3:], what)
    return pose_xyz_yaw(*vals)


def mount_pose(value: Any, what: str = "mount") -> np.ndarray:
    """[x, y, z, roll, pitch, yaw] (m, rad) as the tip-to-TCP transform."""
    vals = _numbers(value, 6, f"{what} (x, y, z, roll, pitch, yaw)")
    _radians(vals[3:], what)
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("xyz", vals[3:]).as_matrix()
    out[:3, 3] = vals[:3]
    return out


def table_scene(name: str, table: Any | None) -> Scene:
    """The default table of robot `name`, or one with the corners [xmin, ymin, xmax, ymax] (m)."""
    scene = default_scene(name)
    if table is None:
        return scene
    t = _numbers(table, 4, f"table of robot {name!r} (xmin, ymin, xmax, ymax)")
    return Scene(table_min=(t[0], t[1]), table_max=(t[2], t[3]), table_thickness=scene.table_thickness,
                 workspace_min=scene.workspace_min, workspace_max=scene.workspace_max)


def make_robot(name: str, urdf: str | None = None, tip: str | None = None, mount: np.ndarray | None = None,
               base: np.ndarray | None = None, hand_links: Sequence[str] = (), table: Any | None = None,
               gripper: Gripper | None = None) -> CatalogRobot:
    """A catalogue column: a built-in robot by name, or a URDF robot stored under `name`, with `gripper` (default
    the Franka hand); refused when its fixed links cut into its table."""
    if urdf is None:
        robot = get_robot(name, base=base, tip_frame=tip, mount=mount, gripper=gripper)
    else:
        robot = get_robot(str(urdf), base=base, tip_frame=tip, mount=mount, hand_links=tuple(hand_links), gripper=gripper)
        if robot.name != name:  # the URDF's file name names it otherwise
            robot = robot_from_spec(replace(robot.spec, name=name))
    scene = table_scene(robot.name, table)
    hit = Collider(robot, scene, None).fixed_parts_hit_table()
    if hit:
        raise RobotError(f"the fixed links ({', '.join(hit[:3])}) of robot {robot.name!r} cut into its table; move its "
                         f"base or the table")
    return CatalogRobot(robot.name, robot, scene)


def _robots_doc(path: Path) -> Any:
    import yaml

    try:
        return yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise RobotListError(f"robots file {path} cannot be read ({type(exc).__name__})") from None
    except yaml.YAMLError as exc:
        raise RobotListError(f"robots file {path} is not YAML ({str(exc).splitlines()[0]})") from None


def file_grippers(text: str | Sequence[str]) -> list[Gripper] | None:
    """The grippers listed under `grippers:` in the robots file of a `--robots` value (None when it names no file or
    its file lists none; see the module's docstring)."""
    items = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    files = [Path(i) for i in items if Path(i).suffix.lower() in ROBOT_FILE_SUFFIXES and "=" not in i and Path(i).is_file()]
    out: list[Gripper] = []
    for path in files:
        doc = _robots_doc(path)
        entries = doc.get("grippers") if isinstance(doc, dict) else None
        if entries is None:
            continue
        if not isinstance(entries, list) or not entries:
            raise RobotListError(f"robots file {path}: `grippers:` must be a non-empty list of names, files or mappings")
        for i, e in enumerate(entries):
            if isinstance(e, str):
                name = e if e in BUNDLED or Path(e).is_absolute() else str(path.parent / e)
                out.append(load_gripper(name))
                continue
            extra = sorted(set(e) - {"file", "hand", "fingers", "tcp"}) if isinstance(e, dict) else None
            if extra is None or "file" not in e or extra:
                raise RobotListError(f"robots file {path}: gripper {i + 1} must be a name, a file or a mapping with `file` "
                                     f"(and `hand`, `fingers`, `tcp`)")
            file = Path(str(e["file"]))
            out.append(load_gripper(str(file if file.is_absolute() else path.parent / file), hand_link=e.get("hand"),
                                    finger_joints=tuple(e.get("fingers") or ()), tcp_frame=e.get("tcp")))
    return out or None


def robots_file(path: Path, gripper: Gripper | None = None) -> list[CatalogRobot]:
    """The robots listed in a YAML file (see the module's docstring)."""
    doc = _robots_doc(path)
    entries = doc.get("robots") if isinstance(doc, dict) else None
    if not isinstance(entries, list) or not entries:
        raise RobotListError(f"robots file {path} needs a non-empty list `robots:` of names or mappings")
    out = []
    known = {"name", "urdf", "tip", "mount", "base", "hand_links", "table"}
    for i, e in enumerate(entries):
        if isinstance(e, str):
            out.append(make_robot(e, gripper=gripper))
            continue
        if not isinstance(e, dict) or "name" not in e:
            raise RobotListError(f"robots file {path}: entry {i + 1} must be a name or a mapping with `name`")
        extra = sorted(set(e) - known)
        if extra:
            raise RobotListError(f"robots file {path}: robot {e['name']!r} has unknown keys {', '.join(extra)} "
                                 f"(known: {', '.join(sorted(known))})")
        urdf = e.get("urdf")
        if urdf is not None and not Path(urdf).is_absolute():
            urdf = path.parent / urdf
        what = f"robot {e['name']!r} in {path}"
        out.append(make_robot(str(e["name"]), None if urdf is None else str(urdf), e.get("tip"),
                              None if e.get("mount") is None else mount_pose(e["mount"], f"mount of {what}"),
                              None if e.get("base") is None else base_pose(e["base"], f"base of {what}"),
                              tuple(e.get("hand_links") or ()), e.get("table"), gripper))
    return out


def parse_robots(text: str | Sequence[str], tip: str | None = None, mount: np.ndarray | None = None,
                 base: np.ndarray | None = None, hand_links: Sequence[str] = (),
                 gripper: Gripper | None = None) -> dict[str, CatalogRobot]:
    """The catalogue's columns by name from 'panda,ur5,arm=arm.urdf' (the URDF entries take `tip`, `mount`, `base`
    and `hand_links`), a list of such entries, or the path of a YAML robots file; every robot carries `gripper`
    (default the Franka hand)."""
    items = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    if not items:
        raise RobotListError("--robots needs at least one robot, e.g. panda,ur5 or arm=arm.urdf (with --tip)")
    robots: list[CatalogRobot] = []
    for item in items:
        if Path(item).suffix.lower() in ROBOT_FILE_SUFFIXES and "=" not in item:
            if not Path(item).is_file():
                raise RobotListError(f"robots file {item} does not exist")
            robots += robots_file(Path(item), gripper)
        elif "=" in item:
            name, urdf = (s.strip() for s in item.split("=", 1))
            if not name or not urdf:
                raise RobotListError(f"--robots entry {item!r} must be NAME=URDF")
            if tip is None:
                raise RobotListError(f"--robots entry {item!r} is a URDF robot: give its tip frame with --tip")
            robots.append(make_robot(name, urdf, tip, mount, base, hand_links, gripper=gripper))
        else:
            robots.append(make_robot(item, gripper=gripper))
    out: dict[str, CatalogRobot] = {}
    for r in robots:
        if r.name in out:
            raise RobotListError(f"robot {r.name!r} is listed twice; give each column its own name")
        out[r.name] = r
    return out
