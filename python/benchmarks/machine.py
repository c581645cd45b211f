"""The machine a measurement ran on, for the reports of ``env_throughput.py`` and
``scripts/validate_mjwarp.py`` (which puts this folder on ``sys.path`` to import it)."""

from __future__ import annotations


def cpu_model() -> str:
    """The CPU's model name from ``/proc/cpuinfo`` ("unknown CPU" where there is none)."""
    try:
        with open("/proc/cpuinfo") as info:
            for line in info:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown CPU"
