"""The words of a plan's captions: what the hand does at each kind of plan step (pick, transfer, release, regrasp,
place). The caption and footer texts of an animation come from one place, `workbench.viewer.wan_harada.caption_track`,
and are shown as HTML beside the canvas, never as panels in the scene."""

from __future__ import annotations

CAPTION_TEXT = {"pick": "pick: grasp the part at its start pose", "transfer": "transfer: carry the part",
                "release": "release: put the part down to regrasp it", "regrasp": "regrasp: take it with another grasp",
                "place": "place: put the part down at its goal pose"}

CAPTION_SCRIPT = """(function () {
  var d = TRACK, live = d === null;
  function tick() {
    var v = window.viewer, a = v && v.animator && v.animator.actions[0];
    // the live view reads the track each frame: a new search sets another plan's track on the node
    if (live && v) { try { d = v.scene_tree.find(["Captions"]).object.workbench_captions || d; } catch (e) {} }
    if (d) {
      var f = a ? Math.min(Math.floor(a.time * d.fps + 1e-6), d.steps.length - 1) : 0, k = d.steps[Math.max(f, 0)] || 0;
      var c = document.getElementById("wb-caption"), b = document.getElementById("wb-footer");
      if (c && c.textContent !== d.captions[k]) c.textContent = d.captions[k];
      if (b && b.textContent !== d.footers[k]) b.textContent = d.footers[k];
    }
    requestAnimationFrame(tick);
  }
  tick();
})();"""
"""Shows the caption and footer of the frame playing: from the track given, or (TRACK = null, the live view) from the
track `PlanView.play` last set on the scene's /Captions node."""
