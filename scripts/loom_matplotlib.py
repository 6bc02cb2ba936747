"""Shared by Loom's plotting scripts (imported from the script's own folder: scripts/ in the
repository, share/loom/scripts once installed). matplotlib comes from Debian's
python3-matplotlib, which a pyenv or venv python3 first on the PATH may not see."""
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
