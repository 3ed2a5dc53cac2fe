"""The version of the oracle contract (``docs/oracle.md``) and the software a run used.

``CONTRACT_VERSION`` is written into every run's ``meta``. It is bumped
whenever what an oracle array means or holds changes (a default that moves
an output, a key whose meaning changes), so a backend author can tell which
version of the truth a stored result was diffed against. Keys are only ever
added, never renamed or re-meant; ``docs/oracle.md`` keeps the changelog.
"""

from __future__ import annotations

import functools
import platform

__all__ = ["CONTRACT_VERSION", "software_versions"]

#: Version of ``docs/oracle.md``; see its changelog.
CONTRACT_VERSION = 6


def _cpu_name():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


@functools.lru_cache(maxsize=1)
def software_versions():
    """Versions of the libraries whose arithmetic a result depends on, and the CPU.

    Returns
    -------
    dict
        ``refraction_ref``, ``python``, ``numpy``, ``numba``, ``trimesh``,
        ``embreex`` (None where not importable), ``cpu`` (model name),
        ``cpu_count`` and ``machine``.
    """
    import os
    import sys

    # the package's version, read from the package already imported (this module is imported by it,
    # so an import of it here would tie the two into a circle)
    version = getattr(sys.modules.get(__package__), "__version__", None)
    out = {"refraction_ref": version, "python": platform.python_version()}
    for mod in ("numpy", "numba", "trimesh", "embreex"):
        try:
            m = __import__(mod)
            out[mod] = getattr(m, "__version__", None)
        except ImportError:
            out[mod] = None
    if out["embreex"] is None:
        try:
            from importlib.metadata import version

            out["embreex"] = version("embreex")
        except Exception:  # not installed: the exact method refuses to run anyway
            pass
    out["cpu"] = _cpu_name()
    out["cpu_count"] = os.cpu_count()
    out["machine"] = platform.machine()
    return dict(out)
