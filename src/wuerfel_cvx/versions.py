"""Installed versions of distributions, the one lookup every report and record uses."""

from __future__ import annotations

import subprocess
from functools import cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

NOT_INSTALLED = "not installed"
"""The version reported for a distribution that is not installed."""

UNKNOWN = "unknown"
"""The version reported for an installed distribution whose metadata has none."""


@cache
def package_version(distribution: str) -> str:
    """Installed version of ``distribution`` (e.g. ``"osqp"``), or :data:`NOT_INSTALLED`.

    :data:`UNKNOWN` when its metadata cannot be read or holds no version.  Read once per
    process: the modules a process loaded keep their version when another is installed
    beside them, and every run records its versions (reading the metadata took about a
    millisecond a package, four a run).
    """
    try:
        found = version(distribution)
    except PackageNotFoundError:
        return NOT_INSTALLED
    except (OSError, ValueError):  # unreadable or malformed metadata
        return UNKNOWN
    return found or UNKNOWN


@cache
def code_version() -> str:
    """The code this process runs: the git commit of its source tree if it is a checkout.

    ``<10-digit commit>`` (``+changes`` when the tree differs from it), else the installed
    package's version (a wheel carries no commit).
    """
    source = Path(__file__).resolve().parent
    try:
        commit = subprocess.run(["git", "-C", str(source), "rev-parse", "--short=10", "HEAD"],
                                capture_output=True, text=True, timeout=10, check=True)
        changed = subprocess.run(["git", "-C", str(source), "status", "--porcelain",
                                  "--untracked-files=no", "--", "."],
                                 capture_output=True, text=True, timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return package_version("wuerfel_cvx")
    return commit.stdout.strip() + ("+changes" if changed.stdout.strip() else "")
