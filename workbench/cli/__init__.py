"""The `workbench` command line: argument parsing and printing only (`main.main` is the entry point)."""


def warn(message: str) -> None:
    """A valid run with nothing to show: one warning line on stderr (the command still exits 0)."""
    import sys

    print(f"warning: {message}", file=sys.stderr)
