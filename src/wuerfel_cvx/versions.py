"""Installed versions of distributions, the one lookup every report and record uses."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

NOT_INSTALLED = "not installed"
"""The version reported for a distribution that is not installed."""

UNKNOWN = "unknown"
"""The version reported for an installed distribution whose metadata has none."""


def package_version(distribution: str) -> str:
    """Installed version of ``distribution`` (e.g. ``"osqp"``), or :data:`NOT_INSTALLED`.

    :data:`UNKNOWN` when its metadata cannot be read or holds no version.
    """
    try:
        found = version(distribution)
    except PackageNotFoundError:
        return NOT_INSTALLED
    except (OSError, ValueError):  # unreadable or malformed metadata
        return UNKNOWN
    return found or UNKNOWN
