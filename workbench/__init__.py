"""Regrasp workbench: grasp, placement and regrasp planning (Wan & Harada; Phoka & Sudsang; Tournassoud et al.)."""

import os as _os
import signal as _signal
import sys as _sys

__version__ = "0.1.0"


def _stopped_while_loading(signum, frame) -> None:  # pragma: no cover - exercised in a subprocess by the tests
    name = next((a for a in _sys.argv[1:] if not a.startswith("-")), "")
    _os.write(2, f"workbench {name}: interrupted; the store keeps only completed stages\n".replace("  ", " ").encode())
    _os._exit(130)


# Run as the command line (`python -m workbench` or `-m workbench.cli` imports this package first, while argv[0] is
# still "-m"; the `workbench` script imports it first too): a Ctrl-C from here until the command has loaded ends it
# at once, with its one line (`workbench.cli.main` takes over; a library import leaves Python's handler alone).
SIGINT_BEFORE_LOADING = None
if ((_sys.argv[:1] == ["-m"] or _os.path.basename(_sys.argv[0] if _sys.argv else "") == "workbench")
        and _signal.getsignal(_signal.SIGINT) is _signal.default_int_handler):
    try:
        _signal.signal(_signal.SIGINT, _stopped_while_loading)
        SIGINT_BEFORE_LOADING = _signal.default_int_handler
    except ValueError:  # not the main thread
        pass
