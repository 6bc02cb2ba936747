"""Shared by Loom's plotting scripts (imported from the script's own folder: scripts/ in the
repository, share/loom/scripts once installed). matplotlib comes from Debian's
python3-matplotlib, which a pyenv or venv python3 first on the PATH may not see."""
import csv
import os
import sys

SYSTEM_PYTHON = "/usr/bin/python3"


def have_matplotlib(argv=None):
    """True when this interpreter imports matplotlib. When it cannot, the script starts again
    under the system's python3 with `argv` (default: this run's arguments) and this call does
    not return, unless that python3 is missing or is this interpreter: then False."""
    try:
        import matplotlib  # noqa: F401
        return True
    except ImportError:
        if os.path.exists(SYSTEM_PYTHON) and os.path.realpath(sys.executable) != os.path.realpath(SYSTEM_PYTHON):
            os.execv(SYSTEM_PYTHON, [SYSTEM_PYTHON] + (sys.argv if argv is None else argv))
        return False


def require_matplotlib():
    """As have_matplotlib, but raises the ImportError where no python3 can import matplotlib."""
    if not have_matplotlib():
        import matplotlib  # noqa: F401


def pyplot_or_exit(script):
    """matplotlib.pyplot on the Agg backend; where no python3 can import matplotlib, exit 3 with
    "<script>: python3 cannot import matplotlib" (loom then names the package to install)."""
    if not have_matplotlib():
        sys.stderr.write(f"{script}: python3 cannot import matplotlib\n")
        sys.exit(3)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def csv_rows(src, script):
    """The rows of the CSV file `src` as dicts; exits with "<script>: <src> has no rows" when
    it has none."""
    with open(src, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        sys.exit(f"{script}: {src} has no rows")
    return rows
