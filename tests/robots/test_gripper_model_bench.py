"""`bench grippers` measures an MJCF gripper in MuJoCo: checked on a two-slide gripper written here, whose opening,
pads, body, TCP and mass are known from its own numbers."""

from __future__ import annotations

import pytest

from workbench.benchmarks.grippers import measure
from workbench.cli.main import main

MJCF = """<mujoco>
  <option timestep="0.002"/>
  <worldbody>
    <body name="base">
      <geom type="box" size="0.03 0.05 0.04" pos="0 0 0.04" density="1000"/>
      <site name="pinch" pos="0 0 0.12"/>
      <body name="left_pad" pos="0 0.005 0.12">
        <joint name="l" type="slide" axis="0 1 0" range="0 0.03" damping="2"/>
        <geom type="box" size="0.01 0.003 0.015" pos="0 0.003 0" density="1000"/>
      </body>
      <body name="right_pad" pos="0 -0.005 0.12">
        <joint name="r" type="slide" axis="0 -1 0" range="0 0.03" damping="2"/>
        <geom type="box" size="0.01 0.003 0.015" pos="0 -0.003 0" density="1000"/>
      </body>
    </body>
  </worldbody>
  <contact><exclude body1="left_pad" body2="right_pad"/></contact>
  <equality><joint joint1="l" joint2="r"/></equality>
  <actuator><position joint="l" ctrlrange="0 0.03" kp="200"/></actuator>
</mujoco>
"""


def test_a_two_slide_gripper_measures_as_built(tmp_path, capsys):
    path = tmp_path / "slides.xml"
    path.write_text(MJCF)
    got = measure(path, samples=4)
    assert got["opening"] == pytest.approx((0.01, 0.07), abs=5e-4)  # 10 mm apart plus twice the slide
    assert got["pad_size"] == pytest.approx((0.02, 0.03), abs=1e-9) and got["pad_thickness"] == pytest.approx(0.006)
    assert got["pad_z"] == pytest.approx((0.12, 0.12, 0.12), abs=1e-6) and got["tilt"] == pytest.approx(0.0, abs=1e-3)
    assert got["palm"] == pytest.approx((0.06, 0.10, 0.08), abs=1e-9) and got["tcp"] == pytest.approx(0.12)
    assert got["mass"] == pytest.approx(1000 * (0.06 * 0.1 * 0.08 + 2 * 0.02 * 0.006 * 0.03))
    assert main(["bench", "grippers", "--mjcf", str(path), "--samples", "3"]) == 0
    assert "10.0 / 70.0" in capsys.readouterr().out
    assert main(["bench", "grippers", "--mjcf", str(path), "--pads", "a,b"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no body 'a'" in err[0]
