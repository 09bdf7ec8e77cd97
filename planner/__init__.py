"""ladder's planning side: OMPL adapters, the ladder pipeline, sweeps and the CLI.

Light on purpose: the `ladder` command starts here (`main`), before numpy, numba or OMPL are
imported, so a Ctrl-C while they load ends as one anywhere else does.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

#: The `ladder` command's exit codes: done, a run or plan that failed, bad input, interrupted.
EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130


def models_problem() -> str:
    """Why `import models` is not ladder's physics package ("" when it is, beside this one): a
    project of one's own with a top-level package named `models` ahead of it on sys.path (a
    pytest rootdir, the working directory under `python -m`) would mix the two."""
    own = Path(__file__).resolve().parent.parent / "models"
    module = sys.modules.get("models")
    if module is not None:
        origin = getattr(module, "__file__", None)
    else:
        found = importlib.util.find_spec("models")
        origin = found.origin if found is not None else None
    if origin is not None and Path(origin).resolve().parent == own:
        return ""
    where = f"is {origin}" if origin else "is not found"
    return (
        f"the package `models` {where}, not ladder's physics package ({own}): a package of your own "
        "named `models` comes first on sys.path; rename it, or keep its folder off sys.path where ladder runs"
    )


def main(argv: list[str] | None = None) -> int:
    """The `ladder` command (`planner.cli.main`); a Ctrl-C that lands while it still imports
    its libraries or reads its arguments is "interrupted", exit 130, as anywhere else, and one
    after the command is done (the process shutting down, 0.3-0.5 s) changes nothing (it had
    made exit 130, once a traceback)."""
    try:
        problem = models_problem()
        if problem:
            print(f"error: {problem}", file=sys.stderr)
            return EXIT_BAD_INPUT
        from planner import cli

        code = cli.main(argv)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    if argv is None:  # the process's own command: a Ctrl-C while it shuts down leaves the command's code
        import signal

        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return code
