"""The explorers' gripper menu: the grippers whose rows a store holds, by name and digest, then the bundled and given
grippers to build for (CONVENTIONS.md, Gripper). It only lists and loads grippers; the explorers plan with the one
chosen."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

import ipywidgets as W

from workbench.errors import GripperError
from workbench.planners.wan_harada.stages import grippers_in_store
from workbench.robots.gripper import BUNDLED, Gripper, franka_hand, load_gripper


def known_grippers(given: Sequence[Gripper] = ()) -> dict[str, Gripper]:
    """The bundled grippers and `given` ones, by digest (the Franka hand first)."""
    out = {}
    for g in [franka_hand(), *(load_gripper(name) for name in BUNDLED if name != "franka"), *given]:
        out.setdefault(g.digest, g)
    return out


class GripperMenu:
    """A dropdown of grippers: those with rows in store `db` first ("in store", their digest; the objects and robots
    they were built for), then the other bundled or `given` grippers ("build"). A stored gripper that is neither
    bundled nor given is listed too, and choosing it says to pass its file. `on_change(gripper)` runs on a choice."""

    def __init__(self, db: str | Path | None = None, given: Sequence[Gripper] = (), value: Gripper | None = None,
                 on_change: Callable[[Gripper], None] | None = None, width: str = "420px"):
        self.db, self.known, self.on_change = db, known_grippers(given), on_change
        self.widget = W.Dropdown(description="gripper", style={"description_width": "initial"},
                                 layout=W.Layout(width=width))
        self.note = W.HTML()
        self.stored: dict[str, dict] = {}
        self.refresh(value.digest if value is not None else None)
        self.widget.observe(self._changed, names="value")

    def refresh(self, digest: str | None = None) -> None:
        """Read the store's grippers again (after a build) and keep the choice, or select `digest`."""
        keep = digest or self.widget.value
        self.stored = {g["digest"]: g for g in (grippers_in_store(self.db) if self.db is not None else [])}
        options = []
        for d, g in self.stored.items():
            where = ", ".join(g["objects"][:3] + g["robots"][:3])
            known = "" if d in self.known else "; not loaded"
            options.append((f"{g['name']} (in store, {d[:8]}: {where}{known})", d))
        options += [(f"{g.name} (build)", d) for d, g in self.known.items() if d not in self.stored]
        quiet, self._quiet = getattr(self, "_quiet", False), True
        self.widget.options = options
        values = [v for _, v in options]
        self.widget.value = keep if keep in values else values[0]
        self._quiet = quiet

    @property
    def gripper(self) -> Gripper:
        """The chosen gripper; a stored one the menu was not given is refused, naming what to pass."""
        d = self.widget.value
        if d in self.known:
            return self.known[d]
        name = self.stored.get(d, {}).get("name", d)
        raise GripperError(f"the store's gripper {name!r} ({d[:8]}) is not bundled: load it from its file "
                           f"(load_gripper(PATH)) and give it to the explorer's grippers=[...]")

    def _changed(self, _) -> None:
        if self._quiet:
            return
        try:
            gripper = self.gripper
        except GripperError as exc:
            self.note.value = f"<span style='color:#a00'>{exc}</span>"
            return
        self.note.value = ""
        if self.on_change is not None:
            self.on_change(gripper)
