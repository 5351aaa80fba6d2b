"""Output options (--json, --html, --trajectory, --shards, --out): checked while the command line is parsed, before
any work starts or anything is stored, and written with their folders created.

A file option is refused, in one line, when the path is a folder, when an existing file cannot be written, when
a component above it is a regular file, or when the nearest existing folder above it cannot be written (the
folders in between are created when the file is written). A folder option is refused when the path is a file or
cannot be created or written.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Callable, Iterable


def output_problem(path: Path, folder: bool = False) -> str | None:
    """Why `path` cannot be written as an output file (or, with `folder`, made an output folder), or None."""
    if path.exists():
        if folder and not path.is_dir():
            return "is a file, not a folder"
        if not folder and path.is_dir():
            return "is a folder; give a file path"
        if not _writable(path):
            return "cannot be written (permission denied, or a read-only file system)"
        return None
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                return f"cannot be made: {parent} is a file, not a folder"
            if not _writable(parent):
                return f"cannot be written: folder {parent} is not writable"
            return None
    return None


def _writable(path: Path) -> bool:
    """Tried, not inferred from mode bits (root passes those; a read-only mount does not): a file opened for appending
    (its content untouched), a folder by creating and removing an empty file in it."""
    try:
        if path.is_dir():
            probe = path / f".workbench-write-test-{os.getpid()}"
            os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
            probe.unlink()
        else:
            os.close(os.open(path, os.O_WRONLY | os.O_APPEND))
    except OSError:
        return False
    return True


def output_path(suffixes: Iterable[str] = (), folder: bool = False) -> Callable[[str], Path]:
    """An argparse `type` for an output path: refused while parsing (one line, exit 2) when it cannot be written."""
    allowed = tuple(s.lower() for s in suffixes)

    def parse(text: str) -> Path:
        if not text.strip():
            raise argparse.ArgumentTypeError("an empty path; give a file path")
        path = Path(text).expanduser()
        if allowed and path.suffix.lower() not in allowed:
            raise argparse.ArgumentTypeError(f"{text!r} must end in {' or '.join(allowed)}")
        problem = output_problem(path, folder)
        if problem:
            raise argparse.ArgumentTypeError(f"{text} {problem}")
        return path

    parse.__name__ = "folder" if folder else "path"
    return parse


def add_output(parser: argparse.ArgumentParser, flag: str, help: str, suffixes: Iterable[str] = (),
               folder: bool = False, **kwargs) -> argparse.Action:
    """An output option whose path is checked while parsing (see the module)."""
    kwargs.setdefault("default", None)
    kwargs.setdefault("metavar", "DIR" if folder else "OUT")
    return parser.add_argument(flag, type=output_path(suffixes, folder), help=help, **kwargs)


def write_text(path: str | Path, text: str) -> Path:
    """Write an output file whole: its folders created, the text written under a temporary name, then renamed (an
    interrupted write leaves the old file or none, never half of one)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
