"""MuJoCo drop test for placement tests: release an object on the plane z = 0 and measure how far it moves.

Not a test module itself; tests import `drop_test` from here. MuJoCo collides a mesh through its
convex hull, which is what decides whether an object resting on a table stays put.

The table is not quite level: gravity is tilted by TILT_DEG toward the azimuth TILT_AZIMUTH_DEG.
Without it a perfectly symmetric simulation keeps an object balanced in an unstable equilibrium
(a cube on an edge, a polygonal cylinder on a vertex) forever; with it such an object falls, while
a placement with any real stability margin (more than about a degree) does not move.
"""

from __future__ import annotations

import mujoco
import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

TIMESTEP = 0.0005  # s; small enough for the stiff contacts below (time constant >= 2 timesteps)
FRICTION = 0.8
SOLREF = (0.004, 1.0)  # contact time constant (s) and damping ratio: stiff and critically damped
SOLIMP = (0.95, 0.99, 0.0005, 0.5, 2.0)  # high impedance: sub-millimetre penetration, no bounce
GRAVITY = 9.81
TILT_DEG = 0.5  # an unlevel table, far below the tipping angle of a stable placement
TILT_AZIMUTH_DEG = 20.0  # not a multiple of 15 or 45 degrees, the usual rotations of placements about z

_XML = """<mujoco model="drop_test">
  <compiler angle="radian"/>
  <option timestep="{timestep!r}" gravity="{gravity}" integrator="implicitfast" cone="elliptic"/>
  <asset>
    <mesh name="object" file="object.stl" inertia="{inertia}"/>
  </asset>
  <default>
    <geom condim="3" friction="{friction!r} 0 0" solref="{solref}" solimp="{solimp}"/>
  </default>
  <worldbody>
    <geom name="ground" type="plane" size="0 0 1"/>
    <body name="object">
      <freejoint/>
      <geom name="object" type="mesh" mesh="object" density="{density!r}"/>
    </body>
  </worldbody>
</mujoco>
"""


def _model(mesh: trimesh.Trimesh, density: float) -> mujoco.MjModel:
    """A MuJoCo model of a ground plane and the mesh as a free body whose frame is the mesh's frame."""
    tilt, azimuth = np.radians(TILT_DEG), np.radians(TILT_AZIMUTH_DEG)
    gravity = GRAVITY * np.array([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), -np.cos(tilt)])
    xml = _XML.format(timestep=TIMESTEP, friction=FRICTION, density=float(density),
                      gravity=" ".join(repr(float(g)) for g in gravity),
                      solref=" ".join(map(repr, SOLREF)), solimp=" ".join(map(repr, SOLIMP)),
                      inertia="exact" if mesh.is_watertight else "convex")
    stl = trimesh.exchange.stl.export_stl(mesh)
    return mujoco.MjModel.from_xml_string(xml, assets={"object.stl": stl})


def drop_test(mesh: trimesh.Trimesh, pose: np.ndarray, seconds: float = 1.0,
              density: float = 1000.0) -> tuple[float, float]:
    """Release `mesh` (object frame, metres) at the 4x4 world `pose` on the ground z = 0, at rest.

    The pose is shifted vertically so that the object's lowest point touches z = 0 (as a placement's
    pose has it), the object is simulated for `seconds`, and the result is (rotation in degrees
    between the initial and final orientation, displacement of the centre of mass in metres).
    """
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4):
        raise ValueError(f"pose must be a 4x4 transform, got shape {pose.shape}")
    model = _model(mesh, density)
    data = mujoco.MjData(model)
    lowest = float((mesh.vertices @ pose[:3, :3].T)[:, 2].min())
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(pose[:3, :3]).ravel())
    data.qpos[:3] = [pose[0, 3], pose[1, 3], -lowest]
    data.qpos[3:7] = quat
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    body = model.body("object").id
    rot0, com0 = data.xmat[body].reshape(3, 3).copy(), data.xipos[body].copy()
    mujoco.mj_step(model, data, nstep=max(1, int(round(seconds / model.opt.timestep))))
    rot1, com1 = data.xmat[body].reshape(3, 3), data.xipos[body]
    angle = float(np.degrees(Rotation.from_matrix(rot0.T @ rot1).magnitude()))
    return angle, float(np.linalg.norm(com1 - com0))
