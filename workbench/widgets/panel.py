"""What every explorer shares: its controls beside its 3D view in one output, a busy indicator while it recomputes,
and results cached by the digest of the parameters they came from (so that going back to a value is instant)."""

from __future__ import annotations

import contextlib
import hashlib
import json
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import asdict, is_dataclass
from typing import Any

import ipywidgets as W

from workbench.viewer.scenes import view

CONTROLS_WIDTH = "440px"
VIEW_HEIGHT = 480


def digest(*parts: Any) -> str:
    """A short digest of parameters (dataclasses, numbers, strings, tuples) for cache keys."""
    def plain(x: Any) -> Any:
        if is_dataclass(x) and not isinstance(x, type):
            return {"__type": type(x).__name__, **{k: plain(v) for k, v in asdict(x).items()}}
        if isinstance(x, (list, tuple)):
            return [plain(v) for v in x]
        if isinstance(x, dict):
            return {str(k): plain(v) for k, v in x.items()}
        return x if isinstance(x, (str, int, float, bool, type(None))) else repr(x)

    return hashlib.sha256(json.dumps(plain(parts), sort_keys=True, default=repr).encode()).hexdigest()[:20]


class StageCache:
    """Results of one stage by parameter digest, the `size` most recent kept."""

    def __init__(self, size: int = 8):
        self.size, self.items = size, OrderedDict()
        self.hits = self.misses = 0

    def get(self, key: str, compute: Callable[[], Any]) -> Any:
        if key in self.items:
            self.items.move_to_end(key)
            self.hits += 1
            return self.items[key]
        self.misses += 1
        value = compute()
        self.items[key] = value
        while len(self.items) > self.size:
            self.items.popitem(last=False)
        return value


class Busy:
    """A small status line: "computing ..." while a recomputation runs, then what it did."""

    def __init__(self):
        self.widget = W.HTML("")
        self.widget.add_class("workbench-busy")  # not a result: the browser test reads the numbers without it

    @contextlib.contextmanager
    def running(self, what: str) -> Iterator[None]:
        self.widget.value = f"<span style='color:#b60'>&#9203; {what} ...</span>"
        try:
            yield
        finally:
            self.widget.value = ""


def view_widget(vis, height: int = VIEW_HEIGHT, captions: bool = False) -> W.HTML:
    """The live meshcat view as a widget (so that it sits in the same output as its controls)."""
    return W.HTML(view(vis, height, captions).data, layout=W.Layout(width="100%"))


def beside(controls: list, vis, key: W.HTML | None = None, height: int = VIEW_HEIGHT, captions: bool = False) -> W.Box:
    """Controls in a side column, the view (fixed height) with its key under it: one output."""
    column = W.VBox(controls, layout=W.Layout(width=CONTROLS_WIDTH, min_width=CONTROLS_WIDTH, overflow="hidden"))
    right = W.VBox([view_widget(vis, height, captions)] + ([key] if key is not None else []),
                   layout=W.Layout(flex="1 1 auto"))
    return W.HBox([column, right], layout=W.Layout(width="100%", align_items="flex-start"))


class BesideView:
    """An explorer whose `widget` is its `controls` beside its live 3D view `vis` and colour key `key`, built once on
    first use; `captions` puts the step's caption and footer over the view."""

    captions = False
    _widget = None

    @property
    def widget(self) -> W.Widget:
        """The controls beside the live 3D view and its colour key."""
        if self._widget is None:
            self._widget = beside(self.controls.children, self.vis, self.key, captions=self.captions)
        return self._widget
