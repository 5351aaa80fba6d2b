"""Progress of a catalogue build: one tqdm bar for all units and one per unit kind (parts, IK chunks, graphs), each
with its count, rate and ETA, on stderr (widgets in a notebook). Units skipped because they are stored advance the
bars without counting toward the rate, so the ETA is that of the work left."""

from __future__ import annotations

KINDS = {"part": ("parts", "part"), "ik": ("IK chunks", "chunk"), "graph": ("graphs", "graph")}


class Progress:
    """The bars of one build (all disabled when `enabled` is false)."""

    def __init__(self, enabled: bool = True):
        from tqdm.auto import tqdm

        self.all = tqdm(total=0, desc="catalog", unit="unit", disable=not enabled, dynamic_ncols=True, position=0)
        self.kinds = {k: tqdm(total=0, desc=f"  {label}", unit=unit, disable=not enabled, dynamic_ncols=True, position=i + 1)
                      for i, (k, (label, unit)) in enumerate(KINDS.items())}

    def _bars(self, kind: str) -> tuple:
        return self.all, self.kinds[kind]

    def add(self, kind: str) -> None:
        """A unit of `kind` to do."""
        for bar in self._bars(kind):
            bar.total += 1
            bar.refresh()

    def done(self, kind: str) -> None:
        """A unit of `kind` finished (computed, or failed)."""
        for bar in self._bars(kind):
            bar.update(1)

    def skipped(self, kind: str) -> None:
        """A unit of `kind` found in the store: counted, not timed."""
        for bar in self._bars(kind):
            if bar.disable:
                continue
            bar.total += 1
            bar.n += 1
            bar.initial += 1
            bar.refresh()

    def note(self, text: str) -> None:
        self.all.set_postfix_str(text, refresh=False)

    def close(self) -> None:
        for bar in (*self.kinds.values(), self.all):
            bar.close()
