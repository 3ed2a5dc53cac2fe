"""Re-execute the teaching notebooks with a real Jupyter kernel and store their outputs.

    python notebooks/build.py                     # every notebook, at its default resolution
    python notebooks/build.py caustics_walkthrough error_vs_time
    python notebooks/build.py --set "N = 48" --dry-run   # a quick run that rewrites nothing

Each notebook is run top to bottom by ``nbclient`` on the ``python3`` kernel
(ipykernel; jupyter_client starts it with this interpreter, ``sys.executable``),
with the notebooks folder as its working directory, and written back
atomically (a temporary file beside it, then ``os.replace``) with its outputs,
so that it reads on a code-hosting site without running it. A notebook that
raises is not rewritten; the error names the cell (index and first line).

The first PNG output of the cell tagged ``learn`` is also written to
``docs/learn/<notebook>.png``: the picture the README's "Learn" section shows.

The cell tagged ``contract`` (right after ``parameters``) prints the package's
``contract_version``; :func:`stored_contract_version` reads it back from the
stored outputs, so a test can tell a notebook built under another version of
``docs/oracle.md`` without running it.

A rebuild also stores the notebook's final ``key`` dict (its key numbers at the
size it was built at) in the notebook's metadata, ``metadata.refraction_ref.key``
(:func:`stored_key`), so that a test can re-run it at that size and compare
(:func:`key_differences`) without trusting the printed outputs.

The tests (``tests/test_notebooks.py``) use :func:`execute` with a small
resolution injected after each notebook's ``parameters`` cell.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
LEARN = os.path.join(os.path.dirname(HERE), "docs", "learn")

#: in reading order (the README's "Learn" section lists them so)
NOTEBOOKS = ["imagespace_walkthrough", "caustics_walkthrough", "volumetric_walkthrough", "levelmap_walkthrough",
             "error_vs_time", "check_a_backend"]

#: what the final injected cell prints before its JSON (see :func:`execute`)
KEY_MARK = "@@KEY_NUMBERS@@"

#: the tag of the cell that prints ``contract_version <n>``
CONTRACT_TAG = "contract"

#: the notebook metadata entry a rebuild writes: ``{"key": ..., "contract_version": ...}``
META = "refraction_ref"

#: key-number names holding wall-clock times (machine- and load-dependent): never compared
TIMING_WORDS = ("_ms", "seconds", "time", "wall")

#: relative tolerance of a re-run's key numbers against the stored ones; the package is deterministic
#: (fixed-point deposits, no RNG without a seed), so this only absorbs float formatting and BLAS order
KEY_RTOL = 1e-6


class NotebookError(RuntimeError):
    """A cell raised; the message names the notebook, the cell index and its first source line."""


def parameters_index(nb):
    """Index of the first code cell tagged ``parameters`` (papermill's convention)."""
    for i, c in enumerate(nb.cells):
        if c.cell_type == "code" and "parameters" in c.get("metadata", {}).get("tags", []):
            return i
    raise NotebookError("no code cell is tagged 'parameters'")


def stored_contract_version(nb):
    """The ``contract_version`` the stored outputs were made under, from the cell tagged ``contract``.

    Returns
    -------
    int or None
        The number its stored output prints as ``contract_version <n>``; None when the notebook has no
        such cell or it was stored without that output.
    """
    for c in nb.cells:
        if c.cell_type == "code" and CONTRACT_TAG in c.get("metadata", {}).get("tags", []):
            text = "".join(o.get("text", "") for o in c.get("outputs", []) if o.get("output_type") == "stream")
            for ln in text.splitlines():
                parts = ln.split()
                if len(parts) == 2 and parts[0] == "contract_version" and parts[1].isdigit():
                    return int(parts[1])
    return None


def stored_key(nb):
    """The ``key`` dict stored by the last rebuild (``metadata.refraction_ref.key``), or None."""
    return nb.metadata.get(META, {}).get("key")


def _is_timing(name):
    return any(w in str(name).lower() for w in TIMING_WORDS)


def key_differences(stored, fresh, rtol=KEY_RTOL, atol=1e-12, path="key"):
    """Where two key dicts differ: a list of ``"path: stored != fresh"`` lines (empty when they agree).

    Numbers agree within ``rtol`` (relative) or ``atol``; booleans, strings and lengths exactly; entries
    whose name holds a timing word (:data:`TIMING_WORDS`) are skipped, as is ``_executable``.
    """
    if isinstance(stored, dict) and isinstance(fresh, dict):
        out = []
        for k in sorted(set(stored) | set(fresh), key=str):
            if k == "_executable" or _is_timing(k):
                continue
            if k not in stored or k not in fresh:
                out.append(f"{path}.{k}: only in the {'stored' if k in stored else 'fresh'} key")
                continue
            out += key_differences(stored[k], fresh[k], rtol, atol, f"{path}.{k}")
        return out
    if isinstance(stored, (list, tuple)) and isinstance(fresh, (list, tuple)):
        if len(stored) != len(fresh):
            return [f"{path}: {len(stored)} items stored, {len(fresh)} fresh"]
        return [d for i, (a, b) in enumerate(zip(stored, fresh)) for d in key_differences(a, b, rtol, atol,
                                                                                         f"{path}[{i}]")]
    num = (int, float)
    if (isinstance(stored, num) and isinstance(fresh, num) and not isinstance(stored, bool)
            and not isinstance(fresh, bool)):
        a, b = float(stored), float(fresh)
        if a == b or (a != a and b != b) or abs(a - b) <= atol + rtol * max(abs(a), abs(b)):
            return []
        return [f"{path}: {a!r} stored != {b!r} fresh"]
    return [] if stored == fresh else [f"{path}: {stored!r} stored != {fresh!r} fresh"]


def _is_injected(cell, injected):
    return any(cell is c for c in injected)


def _first_line(src):
    return next((ln for ln in src.splitlines() if ln.strip()), "")


def execute(path, overrides=None, timeout=600, key_numbers=False, cwd=HERE):
    """Run a notebook with a fresh ``python3`` kernel; returns ``(nb, seconds, key)``.

    Parameters
    ----------
    path : str
        The ``.ipynb`` file (read, never written here).
    overrides : str, optional
        Python source run right after the ``parameters`` cell, as a cell of
        its own tagged ``injected-parameters`` (e.g. ``"N = 48"``).
    timeout : float
        Hang guard for the whole notebook in seconds (not a speed target).
    key_numbers : bool
        Append a cell that prints the notebook's ``key`` dict (and the
        kernel's interpreter) as JSON; it is returned as ``key``, with
        ``key["_executable"]``.
    cwd : str
        The kernel's working directory.

    Raises
    ------
    NotebookError
        When a cell raises or the notebook runs past ``timeout``.
    """
    import nbformat
    from nbclient import NotebookClient
    from nbclient.exceptions import CellExecutionError, CellTimeoutError, DeadKernelError

    nb = nbformat.read(path, as_version=4)
    name = os.path.basename(path)
    # the kernel inherits these: slider cells draw their static figure (notebooks/teach.py), and importing
    # notebooks/*.py leaves no __pycache__ beside the notebooks
    os.environ.setdefault("REFRACTION_REF_NOTEBOOK_STATIC", "1")
    os.environ.setdefault("PYTHONDONTWRITEBYTECODE", "1")
    injected = []
    if overrides:
        i = parameters_index(nb)
        cell = nbformat.v4.new_code_cell(overrides, metadata={"tags": ["injected-parameters"]})
        nb.cells.insert(i + 1, cell)
        injected.append(cell)
    if key_numbers:
        cell = nbformat.v4.new_code_cell(
            "import json as _json, sys as _sys\n"
            f"print({KEY_MARK!r} + _json.dumps({{'key': globals().get('key'), '_executable': _sys.executable}}, "
            "default=float))")
        nb.cells.append(cell)
        injected.append(cell)
    deadline = time.monotonic() + timeout
    running = {}

    def on_start(cell=None, cell_index=None, **_):
        running["index"] = cell_index

    client = NotebookClient(nb, kernel_name="python3", timeout=int(timeout), startup_timeout=120,
                            timeout_func=lambda cell: max(1, int(deadline - time.monotonic())),
                            record_timing=False, resources={"metadata": {"path": cwd}}, on_cell_start=on_start)
    t0 = time.perf_counter()
    try:
        client.execute()
    except (CellExecutionError, CellTimeoutError, DeadKernelError) as e:
        idx = running.get("index")
        if idx is None:
            raise NotebookError(f"{name}: {type(e).__name__}: {str(e)[-500:]}") from None
        cell = nb.cells[idx]
        stored = idx - sum(1 for c in nb.cells[:idx] if _is_injected(c, injected))  # the index as stored
        errs = [o for o in cell.get("outputs", []) if o.get("output_type") == "error"]
        if isinstance(e, DeadKernelError):
            what = "killed the kernel"
        elif isinstance(e, CellTimeoutError) or not errs:
            what = f"did not finish within the hang guard of {timeout:g} s"
        else:
            what = f"raised {errs[0].get('ename')}: {errs[0].get('evalue')}"
        where = "an injected cell" if _is_injected(cell, injected) else f"cell {stored}"
        raise NotebookError(f"{name}: {where} ('{_first_line(cell.source)}') {what}") from None
    seconds = time.perf_counter() - t0
    key = None
    if key_numbers:
        text = "".join(o.get("text", "") for o in nb.cells[-1].get("outputs", []) if o.get("output_type") == "stream")
        line = next((ln for ln in text.splitlines() if ln.startswith(KEY_MARK)), None)
        if line is None:
            raise NotebookError(f"{name}: the key-numbers cell printed nothing")
        d = json.loads(line[len(KEY_MARK):])
        key = d["key"]
        if isinstance(key, dict):
            key["_executable"] = d["_executable"]
    nb.cells = [c for c in nb.cells if not _is_injected(c, injected)]
    return nb, seconds, key


def _umask_mode():
    """The mode an ordinary new file gets (``mkstemp`` makes 0600 files)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def write_atomic(nb, path):
    """Write a notebook through a temporary file in its folder, then ``os.replace``."""
    import nbformat

    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)), prefix=".build-", suffix=".ipynb")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            nbformat.write(nb, f)
        os.chmod(tmp, _umask_mode())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def learn_picture(nb):
    """The first PNG of the cell tagged ``learn`` (bytes), or None."""
    import base64

    for c in nb.cells:
        if c.cell_type == "code" and "learn" in c.get("metadata", {}).get("tags", []):
            for o in c.get("outputs", []):
                png = o.get("data", {}).get("image/png")
                if png:
                    return base64.b64decode(png)
    return None


def write_bytes_atomic(data, path):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path), prefix=".build-")
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.chmod(tmp, _umask_mode())
    os.replace(tmp, path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help=f"notebooks to run (default: all: {', '.join(NOTEBOOKS)})")
    ap.add_argument("--set", dest="overrides", default=None,
                    help="Python source run after the parameters cell, e.g. 'N = 48'")
    ap.add_argument("--dry-run", action="store_true", help="run, but rewrite nothing")
    ap.add_argument("--timeout", type=float, default=900, help="hang guard per notebook, seconds")
    a = ap.parse_args(argv)
    names = [n[:-6] if n.endswith(".ipynb") else n for n in (a.names or NOTEBOOKS)]
    failed = 0
    for n in names:
        path = os.path.join(HERE, n + ".ipynb")
        try:
            nb, s, key = execute(path, a.overrides, a.timeout, key_numbers=True)
        except NotebookError as e:
            print(f"FAIL {e}", file=sys.stderr)
            failed += 1
            continue
        if a.overrides is None and not a.dry_run:
            from refraction_ref.contract import CONTRACT_VERSION

            if isinstance(key, dict):
                key.pop("_executable", None)
            # JSON-safe (numpy scalars, tuples) the same way the key cell printed it
            nb.metadata[META] = {"key": json.loads(json.dumps(key, default=float)),
                                 "contract_version": CONTRACT_VERSION}
            write_atomic(nb, path)
            png = learn_picture(nb)
            if png:
                write_bytes_atomic(png, os.path.join(LEARN, n + ".png"))
            print(f"  {n}: {s:.1f} s, {os.path.getsize(path) / 1e6:.2f} MB written"
                  + (f", docs/learn/{n}.png" if png else ""))
        else:
            print(f"  {n}: {s:.1f} s (not written)")
    total = sum(os.path.getsize(os.path.join(HERE, f)) for f in os.listdir(HERE))
    print(f"notebooks/ holds {total / 1e6:.2f} MB")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
