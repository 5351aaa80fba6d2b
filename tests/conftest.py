"""Shared fixtures: meshes built in code, the Franka hand, and the paper's objects when ../shared is present."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from workbench.geometry.objects import MeshWarning, from_trimesh, load_object
from workbench.resources import bundled_objects, paper_objects
from workbench.robots.gripper import franka_hand


ROOT = Path(__file__).resolve().parents[1]

# Commands run in processes forked from one server that imported the command line once (a real process per
# command: its own exit status, stdout, stderr, signals and file-size limit), which keeps the suite fast. A request
# is a list of commands, forked together and running at once; the reply lists their exit statuses.
SERVER = r"""
import json, os, resource, signal, sys, traceback
from workbench.cli.main import build_parser, main
build_parser(full=True)  # every command's module imported once here, not again in each forked child
import toppra  # noqa: F401  (the timing of every plan's motions imports it)
from workbench.robots.gripper import franka_hand
franka_hand()  # the default gripper, loaded once (a cached, immutable value) for every child


def child(req):
    code = 1
    try:
        os.chdir(req["cwd"])
        os.environ.update(req["env"])
        if req["fsize"]:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (req["fsize"], req["fsize"]))
        sys.stdin = open(os.devnull)
        for fd, name in ((1, "out"), (2, "err")):
            os.dup2(os.open(req[name], os.O_WRONLY | os.O_CREAT | os.O_TRUNC), fd)
        try:
            code = main(req["argv"])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        except BaseException:
            traceback.print_exc()
            code = 1
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


for line in sys.stdin:
    pids = []
    for req in json.loads(line):
        pid = os.fork()
        if pid == 0:
            child(req)
        pids.append(pid)
    print(json.dumps([os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) for pid in pids]), flush=True)
"""


class ForkServer:
    """A process that imported the command line; `run` forks one child per command and returns its results."""

    def __init__(self, tmp: Path):
        self.tmp = tmp
        self.count = 0
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        self.proc = subprocess.Popen([sys.executable, "-c", SERVER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     text=True, env=env)

    def run(self, argv: list, cwd: Path, env: dict | None = None, fsize: int | None = None) -> subprocess.CompletedProcess:
        """`workbench ARGV` in its own forked process."""
        return self.run_many([argv], cwd, env, fsize)[0]

    def run_many(self, argvs: list[list], cwd: Path, env: dict | None = None,
                 fsize: int | None = None) -> list[subprocess.CompletedProcess]:
        """Each `workbench ARGV` of `argvs` in its own forked process, all running at once."""
        reqs = []
        for argv in argvs:
            self.count += 1
            reqs.append({"argv": [str(a) for a in argv], "cwd": str(cwd), "fsize": fsize,
                         "env": {k: str(v) for k, v in (env or {}).items()},
                         "out": str(self.tmp / f"{self.count}.out"), "err": str(self.tmp / f"{self.count}.err")})
        self.proc.stdin.write(json.dumps(reqs) + "\n")
        self.proc.stdin.flush()
        codes = json.loads(self.proc.stdout.readline())
        return [subprocess.CompletedProcess(["workbench", *r["argv"]], code, Path(r["out"]).read_text(),
                                            Path(r["err"]).read_text()) for r, code in zip(reqs, codes)]

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


@pytest.fixture(scope="session")
def cli_server(tmp_path_factory):
    """The session's command server (see ForkServer)."""
    server = ForkServer(tmp_path_factory.mktemp("forks"))
    yield server
    server.close()


@pytest.fixture(scope="session")
def hand():
    return franka_hand()


@pytest.fixture(scope="session")
def box():
    """A 50 x 40 x 30 mm box: every size within the Franka hand's 80 mm jaw."""
    return from_trimesh(trimesh.creation.box((0.05, 0.04, 0.03)), "box")


@pytest.fixture(scope="session")
def cylinder():
    return from_trimesh(trimesh.creation.cylinder(radius=0.025, height=0.08, sections=48), "cylinder")


@pytest.fixture(scope="session")
def tube_paper():
    """The paper's TU tube (millimetres), or skip when ../shared is absent."""
    objs = paper_objects()
    if "TU" not in objs:
        pytest.skip("the paper's objects (../shared/objects/wan-harada) are not present")
    return load_object(objs["TU"], units="mm", name="TU")


@pytest.fixture(scope="session")
def bundled():
    """The project's own objects, loaded (metres)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshWarning)
        return {name: load_object(path) for name, path in bundled_objects().items()}


def rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) of the rotation between two 3x3 rotation matrices."""
    c = (np.trace(a.T @ b) - 1) / 2
    return float(np.arccos(np.clip(c, -1, 1)))
