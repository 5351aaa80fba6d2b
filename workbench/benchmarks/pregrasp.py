"""`workbench bench grasps --set mug`: where a mug's grasp candidates go, with the pads starting at the pre-grasp
opening (the grasp's opening plus 10 mm, the default) and at full opening, with the lengths scaled with the part and
fixed (the paper's 50 mm centre-of-mass distance). A mug's rim is far from its centre of mass and most of its wall
is out of the hand's reach from above, so the table names the filter that removes each candidate: the opening, the
friction cone, the centre-of-mass distance (Wan & Harada, Section III, "resistance to gravity torques"), the hand
body at the grasp pose, the rest of the hand along the approach."""

from __future__ import annotations

import argparse

import numpy as np
import trimesh

from workbench.benchmarks import median_time, print_table
from workbench.benchmarks.graspcheck import check_grasps, failures
from workbench.benchmarks.organic import cup
from workbench.geometry.collision import bvh, collide_at_poses, object_collider
from workbench.geometry.objects import from_trimesh
from workbench.grasping.grasps import GraspParams, plan_grasps, swept_body
from workbench.robots.gripper import franka_hand


def mug(radius: float = 0.04, height: float = 0.095, wall: float = 0.004, handle: float = 0.007) -> trimesh.Trimesh:
    """A mug: `cup`'s body (open top, closed walls) with a ring handle of `handle` tube radius on its side, joined
    with manifold3d (one watertight body)."""
    body = cup(radius=radius, height=height, wall=wall, sections=48)
    ring = trimesh.creation.torus(major_radius=0.3 * height, minor_radius=handle, major_sections=32, minor_sections=12)
    ring.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    ring.apply_translation([radius + 0.3 * height - 2 * handle + 0.006, 0.0, height / 2])
    return trimesh.boolean.union([body, ring], engine="manifold")


def run(args: argparse.Namespace) -> int:
    """Print the mug table (see the module docstring)."""
    hand = franka_hand()
    rows = []
    for label, size in (("mug 80 x 95 mm", (0.04, 0.095)), ("mug 64 x 90 mm", (0.032, 0.09))):
        obj = from_trimesh(mug(*size), label)
        height = float(obj.mesh.bounds[1, 2])
        body = bvh(swept_body(hand, 0.0))
        target = object_collider(obj.mesh)
        for lengths in ("adaptive", "fixed"):
            for margin in (GraspParams().pregrasp_margin, None):
                params = GraspParams(pregrasp_margin=margin, lengths=lengths)
                t, plan = median_time(lambda: plan_grasps(obj, hand, params), args.repeats)
                c, g = plan.counts, plan.grasps
                live = plan.candidate_poses
                at_pose = int(collide_at_poses(body, live, target).sum())
                centre = 0.5 * (g.contact0 + g.contact1)
                v = check_grasps(obj.mesh, g.poses, g.jawwidth, g.contact0, g.contact1, g.normal0, g.normal1,
                                 plan.params.friction_coefficient, pregrasp_margin=margin)
                rows.append([label, lengths, "full" if margin is None else f"+{margin * 1e3:.0f} mm",
                             plan.lengths["com_max"] * 1e3, c["hand_poses"], c["pads_left"], c["pads_width"], c["pads_cone"],
                             c["pads_com"], at_pose, c["hand_open"], c["grasps"], int((centre[:, 2] > height - 0.012).sum()),
                             f"{int(v.ok.sum())}/{len(g)}", failures(v), t])
    print_table(["part", "lengths", "opening", "com max mm", "hand poses", "first pad cone ok", "width ok", "cone ok",
                 "com ok", "body hits at pose", "hand clear", "grasps", "rim grasps", "valid", "failing", "t-fg s"], rows,
                title=f"Grasp candidates of a mug with a handle, Franka hand, by filter (median of {args.repeats} runs; "
                      "opening: the pads start and the hand approaches at the grasp's opening plus the margin, or fully "
                      "open; 'body hits at pose': candidates past the centre-of-mass filter whose hand body meets the mug at "
                      "the grasp pose, whatever the opening; rim grasps: contact centre within 12 mm of the rim; valid: "
                      "the independent check of every grasp)")
    return 0
