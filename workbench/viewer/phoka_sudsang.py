"""meshcat views of five-finger regrasping (Phoka & Sudsang): contacts coloured by cluster, representatives
marked, and the five fingertips along a finger-switching sequence with the placed and lifted finger highlighted."""

from __future__ import annotations

import meshcat
import meshcat.geometry as g
import meshcat.transformations as tf
import numpy as np

from workbench.planners.phoka_sudsang.contacts import ContactSet
from workbench.viewer.live import Switches
from workbench.viewer.scenes import palette, show_face_colors, show_points

FINGER = 0x3366DD       # a finger holding a contact
PLACED = 0x33AA55       # the finger just placed on a new contact
LIFTED = 0xDD3333       # the finger just lifted (drawn off the surface)
FREE = 0xB0B0B0         # the fifth finger, waiting
REP = 0x111111


def cluster_colors(labels: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """One 0xRRGGBB colour per contact from its cluster."""
    return palette(k, seed)[np.asarray(labels, dtype=np.int64)]


def show_clusters(vis: meshcat.Visualizer, path: str, contacts: ContactSet, labels: np.ndarray, reps: np.ndarray,
                  rep_radius: float | None = None) -> None:
    """Faces coloured by the cluster of their contact point; representatives T_R as dark spheres."""
    k = int(labels.max()) + 1 if len(labels) else 0
    colors = cluster_colors(labels, k)
    face_colors = np.full(len(contacts.mesh.faces), 0xB0B0B0, dtype=np.int64)
    face_colors[contacts.face] = colors
    show_face_colors(vis, f"{path}/faces", contacts.mesh, face_colors)
    r = rep_radius if rep_radius is not None else 0.025 * contacts.radius
    vis[f"{path}/reps"].delete()
    for i, c in enumerate(np.asarray(reps, dtype=np.int64)):
        node = vis[f"{path}/reps/{i}"]
        node.set_object(g.Sphere(r), g.MeshLambertMaterial(color=REP))
        node.set_transform(tf.translation_matrix(contacts.points[c] - r * contacts.normals[c]))
    show_points(vis, f"{path}/contacts", contacts.points, colors, size=0.4 * r)


def fingertip_positions(contacts: ContactSet, fingers: np.ndarray, lifted_from: np.ndarray, radius: float) -> np.ndarray:
    """(5, 3) fingertip centres: on a contact, the sphere touches the surface; a lifted finger hovers above the
    contact it left; a finger that never touched waits above the object."""
    out = np.zeros((5, 3))
    park = contacts.com + np.array([0.0, 0.0, 1.6 * contacts.radius])
    for f in range(5):
        c = int(fingers[f])
        if c >= 0:
            out[f] = contacts.points[c] - radius * contacts.normals[c]
        elif lifted_from[f] >= 0:
            c = int(lifted_from[f])
            out[f] = contacts.points[c] - 4.0 * radius * contacts.normals[c]
        else:
            out[f] = park
    return out


class FingerView:
    """The five fingertips as spheres, sent once: each switch only moves and recolours them (the placed finger
    green, the lifted one red, the others blue, a waiting finger grey)."""

    def __init__(self, vis: meshcat.Visualizer, path: str, contacts: ContactSet, radius: float | None = None):
        self.vis, self.path, self.contacts = vis, path, contacts
        self.radius = radius if radius is not None else 0.09 * contacts.radius
        self.switches = Switches(vis)
        vis[path].delete()
        for f in range(5):
            vis[f"{path}/finger{f}"].set_object(g.Sphere(self.radius),
                                                g.MeshLambertMaterial(color=FREE, opacity=0.9, transparent=True))

    def show(self, fingers: np.ndarray, placed: int = -1, lifted: int = -1, lifted_from: np.ndarray | None = None) -> None:
        """`fingers` (5,) holds each finger's contact (-1: free); `lifted_from` the contact a free finger left."""
        lifted_from = np.full(5, -1) if lifted_from is None else np.asarray(lifted_from)
        pos = fingertip_positions(self.contacts, np.asarray(fingers), lifted_from, self.radius)
        for f in range(5):
            color = PLACED if f == placed else LIFTED if f == lifted else FINGER if fingers[f] >= 0 else FREE
            name = f"{self.path}/finger{f}"
            self.switches.set(name, "color", [((color >> s) & 255) / 255 for s in (16, 8, 0)] + [0.9])
            self.switches.move(name, tf.translation_matrix(pos[f]))
