"""Diffing two runs pixel by pixel (``refraction-ref compare A.npz B.npz``)."""

from __future__ import annotations

import numpy as np

from .graph import method_blocks
from .status import LABELS

__all__ = ["angular_error_deg", "compare_arrays", "format_comparison", "plot_comparison", "check_comparable",
           "CompareError"]


class CompareError(ValueError):
    """Two runs that cannot be compared (different scenes or resolutions), with the key that differs."""


def _first_difference(a, b, prefix=""):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            name = f"{prefix}.{k}" if prefix else str(k)
            if k not in a or k not in b:
                return name
            d = _first_difference(a[k], b[k], name)
            if d:
                return d
        return None
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{prefix} (lengths {len(a)} and {len(b)})"
        for k, (x, y) in enumerate(zip(a, b)):
            d = _first_difference(x, y, f"{prefix}.{k}")
            if d:
                return d
        return None
    return None if a == b else prefix


def check_comparable(meta_a, meta_b, force=False):
    """Refuse to compare runs of different scenes: the method-independent inputs must agree.

    Everything in the resolved scenes (``meta.scene``) but the methods' knob
    blocks (:func:`refraction_ref.graph.method_blocks`) must be equal: the
    camera, objects, materials, environment, lights, receivers, water and
    volume. The first key that differs is named. With ``force`` a difference
    is returned instead of raised (the caller warns); different image sizes
    are refused even then, since pixels could not be paired.

    Parameters
    ----------
    meta_a, meta_b : dict
        The two runs' ``meta`` (:attr:`refraction_ref.result.Result.meta`).
    force : bool
        Return the first difference instead of raising it.

    Returns
    -------
    str or None
        The first differing key (only with ``force``), or None.

    Raises
    ------
    CompareError
    """
    sa, sb = meta_a.get("scene"), meta_b.get("scene")
    if not isinstance(sa, dict) or not isinstance(sb, dict):
        if force:
            return "meta.scene (missing)"
        raise CompareError("compare: a run has no resolved scene in its meta (not written by refraction-ref?); "
                           "pass --force to compare the arrays anyway")
    ca, cb = sa.get("camera", {}), sb.get("camera", {})
    for k in ("width", "height"):
        if ca.get(k) != cb.get(k):
            raise CompareError(f"compare: the runs have different resolutions ({ca.get('width')}x{ca.get('height')} "
                               f"and {cb.get('width')}x{cb.get('height')}); render both with the same camera.width "
                               "and camera.height")
    keep = sorted((set(sa) | set(sb)) - set(method_blocks()))
    diff = _first_difference({k: sa.get(k) for k in keep}, {k: sb.get(k) for k in keep})
    if diff and not force:
        raise CompareError(f"compare: the runs are of different scenes: '{diff}' differs; compare runs of one scene "
                           "(only the methods' knob blocks may differ), or pass --force")
    return diff


def angular_error_deg(a, b):
    """Angle in degrees between unit direction fields; NaN where either is NaN.

    ``atan2(|a x b|, a . b)``: accurate at small angles, where ``acos`` of the dot product is not.

    Parameters
    ----------
    a, b : (..., 3) array_like
        Unit directions.

    Returns
    -------
    (...,) float64 ndarray
        Degrees.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c = np.sum(a * b, axis=-1)
    s = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.degrees(np.arctan2(s, c))


#: The per-pixel keys compared, with the trailing shape and the dtype kinds each must have (docs/oracle.md)
_PER_PIXEL = {"status": ((), "iu"), "hit": ((), "bui"), "exit_dir": ((3,), "f"), "interfaces": ((), "iu")}


def _check_arrays(arrays, name):
    """Refuse (CompareError, naming the key) the arrays of a run that the comparison cannot read: a per-pixel
    key missing beside ``status``, or of the wrong shape or dtype; an ``image`` that is not (H, W, 3) numbers."""
    if "status" in arrays:
        shape = np.shape(arrays["status"])
        if len(shape) != 2:
            raise CompareError(f"compare: run {name}'s 'status' has shape {shape}; give (H, W) status codes")
        for k, (tail, kinds) in _PER_PIXEL.items():
            if k not in arrays:
                raise CompareError(f"compare: run {name} has 'status' but no '{k}'; write every per-pixel key "
                                   "(docs/oracle.md, Per-pixel keys)")
            x = np.asarray(arrays[k])
            if x.shape != shape + tail or x.dtype.kind not in kinds:
                raise CompareError(f"compare: run {name}'s '{k}' is {x.dtype} {x.shape}; docs/oracle.md has "
                                   f"{shape + tail} of kind {kinds!r}")
    for k, v in arrays.items():
        if (k == "image" or k.startswith("caustic_map_")) and np.asarray(v).dtype.kind not in "fiub":
            raise CompareError(f"compare: run {name}'s '{k}' holds {np.asarray(v).dtype} values; give numbers")
    if "image" in arrays and (np.ndim(arrays["image"]) != 3 or np.shape(arrays["image"])[-1] != 3):
        raise CompareError(f"compare: run {name}'s 'image' has shape {np.shape(arrays['image'])}; give (H, W, 3)")


def compare_arrays(a, b, mask=None):
    """Statistics of run ``a`` against run ``b`` (the reference).

    Parameters
    ----------
    a, b : dict
        docs/oracle.md arrays of two runs of the same scene and camera.
    mask : (H, W) bool, optional
        Pixels to compare; default: pixels whose primary ray hit in ``b``.

    Returns
    -------
    dict
        ``pixels`` compared; ``exit_dir_deg`` median / p90 / p99 / max over
        pixels where both exited (``both_exited``); ``a_stopped_b_exited`` and
        ``a_exited_b_stopped``: fractions of the compared pixels where one run
        exits (status 1) and the other stopped (status 2-4), which the angle
        cannot see; ``interfaces_agree``
        and ``status_agree`` (fractions); ``status_a`` / ``status_b``
        histograms; ``image_rmse`` over all pixels; ``hit_agree``;
        ``caustic_rel_l1`` per shared ``caustic_map_r`` (relative L1, both
        blurred by one texel). Runs without per-pixel keys (water caustics)
        get only the caustic and image statistics.
    """
    _check_arrays(a, "A")
    _check_arrays(b, "B")
    caustics = {}
    for k in sorted(a):
        if k.startswith("caustic_map_") and k in b and np.shape(a[k]) == np.shape(b[k]):
            from .metrics import relative_l1

            caustics[k] = relative_l1(a[k], b[k], blur=1.0)
    if "status" not in a or "status" not in b:  # e.g. water caustics: no per-pixel refraction keys
        out = {"caustic_rel_l1": caustics}
        if "image" in a and "image" in b and np.shape(a["image"]) == np.shape(b["image"]):
            out["image_rmse"] = float(np.sqrt(np.mean((np.asarray(a["image"], np.float64)
                                                       - np.asarray(b["image"], np.float64)) ** 2)))
        return out
    if a["status"].shape != b["status"].shape:
        raise CompareError(f"compare: image shapes differ {a['status'].shape} vs {b['status'].shape}; "
                           "render both runs with the same camera.width and camera.height")
    if mask is None:
        mask = np.asarray(b["hit"], bool)
    both = mask & (a["status"] == 1) & (b["status"] == 1)
    err = angular_error_deg(a["exit_dir"][both], b["exit_dir"][both])
    n = int(mask.sum())

    def pct(q):
        return float(np.percentile(err, q)) if err.size else float("nan")

    out = {
        "pixels": n,
        "both_exited": int(both.sum()),
        "exit_dir_deg": {"median": pct(50), "p90": pct(90), "p99": pct(99),
                         "max": float(err.max()) if err.size else float("nan"),
                         "mean": float(err.mean()) if err.size else float("nan")},
        "interfaces_agree": float(np.mean(a["interfaces"][mask] == b["interfaces"][mask])) if n else float("nan"),
        "status_agree": float(np.mean(a["status"][mask] == b["status"][mask])) if n else float("nan"),
        "hit_agree": float(np.mean(np.asarray(a["hit"]) == np.asarray(b["hit"]))),
        # where one run exits and the other stopped (status 2-4): the angle above cannot see these pixels
        "a_stopped_b_exited": float(np.mean((a["status"][mask] >= 2) & (b["status"][mask] == 1))) if n
        else float("nan"),
        "a_exited_b_stopped": float(np.mean((a["status"][mask] == 1) & (b["status"][mask] >= 2))) if n
        else float("nan"),
        "status_a": np.bincount(a["status"][mask].astype(np.int64), minlength=5).tolist(),
        "status_b": np.bincount(b["status"][mask].astype(np.int64), minlength=5).tolist(),
    }
    if caustics:
        out["caustic_rel_l1"] = caustics
    if "image" in a and "image" in b:
        out["image_rmse"] = float(np.sqrt(np.mean((np.asarray(a["image"], np.float64)
                                                   - np.asarray(b["image"], np.float64)) ** 2)))
    return out


def format_comparison(c, name_a="A", name_b="B"):
    """The statistics of :func:`compare_arrays` as lines of text (``refraction-ref compare``).

    Parameters
    ----------
    c : dict
        :func:`compare_arrays`'s output.
    name_a, name_b : str
        The runs' names in the text.

    Returns
    -------
    str
    """
    extra = [f"{k}: relative L1 (both blurred one texel) {v:.4f}" for k, v in c.get("caustic_rel_l1", {}).items()]
    if "exit_dir_deg" not in c:
        if "image_rmse" in c:
            extra.append(f"image RMSE: {c['image_rmse']:.4f}")
        return "\n".join(extra) if extra else "nothing comparable: neither per-pixel nor caustic keys in common"
    e = c["exit_dir_deg"]
    lines = [
        f"compared {c['pixels']} pixels hit in {name_b}; both exited: {c['both_exited']}",
        f"exit direction error (deg, where both exited): median {e['median']:.3f}  p90 {e['p90']:.3f}  "
        f"p99 {e['p99']:.3f}  max {e['max']:.3f};  stopped in {name_a} but exited in {name_b}: "
        f"{100 * c.get('a_stopped_b_exited', float('nan')):.1f}%, exited in {name_a} but stopped in {name_b}: "
        f"{100 * c.get('a_exited_b_stopped', float('nan')):.1f}%",
        f"interfaces agree: {100 * c['interfaces_agree']:.1f}%   status agree: {100 * c['status_agree']:.1f}%   "
        f"hit agree: {100 * c['hit_agree']:.2f}%",
        f"status histogram {min(LABELS)}..{max(LABELS)} over the {c['pixels']} pixels hit in {name_b}: "
        f"{name_a} {c['status_a']}  {name_b} {c['status_b']}",
    ]
    if "image_rmse" in c:
        lines.append(f"image RMSE: {c['image_rmse']:.4f}")
    return "\n".join(lines + extra)


def _figure(ncols, width=4.0, height=4.4, nrows=1):
    """A figure and axes without pyplot, so the caller's matplotlib back-end is left alone."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width * ncols, height * nrows))
    FigureCanvasAgg(fig)
    return fig, fig.subplots(nrows, ncols)


def plot_comparison(a, b, path, name_a="A", name_b="B"):
    """Write a PNG: both images, the per-pixel exit-direction error map and both status maps.

    Runs without per-pixel keys (water caustics: the level map, the exact
    water reference) get their images, each shared caustic map of both runs
    and their difference instead.

    Parameters
    ----------
    a, b : dict
        ``docs/oracle.md`` arrays of the run to test and the reference run.
    path : str
        The PNG to write.
    name_a, name_b : str
        The runs' names in the titles.

    Returns
    -------
    str
        ``path``.

    Raises
    ------
    CompareError
        When the runs share nothing to plot.
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Rectangle

    from .files import savefig_atomic
    from .result import tonemap

    if "status" not in a or "status" not in b:
        return _plot_maps(a, b, path, name_a, name_b)
    err = angular_error_deg(a["exit_dir"], b["exit_dir"])
    err[~(np.asarray(b["hit"], bool) & (a["status"] == 1) & (b["status"] == 1))] = np.nan
    cmap = ListedColormap(["#ffffff", "#4caf50", "#2196f3", "#ff9800", "#e91e63"])
    fig, ax = _figure(5)
    ax[0].imshow(tonemap(a["image"]))
    ax[0].set_title(f"{name_a}: image")
    ax[1].imshow(tonemap(b["image"]))
    ax[1].set_title(f"{name_b}: image")
    im = ax[2].imshow(err, cmap="magma", vmin=0, vmax=10)
    fin = err[np.isfinite(err)]
    med = float(np.median(fin)) if fin.size else float("nan")
    ax[2].set_title(f"exit-direction error (deg), median {med:.2f}")
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    for k, (r, nm) in enumerate(((a, name_a), (b, name_b))):
        ax[3 + k].imshow(r["status"], cmap=cmap, vmin=-0.5, vmax=4.5, interpolation="nearest")
        ax[3 + k].set_title(f"{nm}: status")
    handles = [Rectangle((0, 0), 1, 1, color=cmap(i)) for i in range(5)]
    fig.legend(handles, [LABELS[k] for k in sorted(LABELS)], loc="lower center", ncol=5)
    for x in ax:
        x.set_xticks([])
        x.set_yticks([])
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return savefig_atomic(fig, path, dpi=80)


def _plot_maps(a, b, path, name_a, name_b):
    """Images and caustic maps of two water-caustics runs: A, B and A - B per map."""
    from .files import savefig_atomic
    from .result import tonemap

    maps = [k for k in sorted(a) if k.startswith("caustic_map_") and k in b and np.shape(a[k]) == np.shape(b[k])]
    has_img = "image" in a and "image" in b
    if not maps and not has_img:
        raise CompareError("compare --plot: the runs share no image and no caustic map of the same shape; "
                           "nothing to plot")
    rows = ([("image", None)] if has_img else []) + [(k, None) for k in maps]
    fig, ax = _figure(3, width=4.0, height=4.0, nrows=len(rows))
    ax = np.atleast_2d(ax)
    for i, (k, _) in enumerate(rows):
        if k == "image":
            ax[i, 0].imshow(tonemap(a["image"]))
            ax[i, 1].imshow(tonemap(b["image"]))
            d = np.abs(np.asarray(a["image"], np.float64) - np.asarray(b["image"], np.float64)).mean(axis=-1)
            im = ax[i, 2].imshow(d, cmap="magma")
        else:
            hi = float(max(np.nanmax(a[k]), np.nanmax(b[k]), 1e-12))
            ax[i, 0].imshow(a[k], cmap="inferno", vmin=0, vmax=hi)
            ax[i, 1].imshow(b[k], cmap="inferno", vmin=0, vmax=hi)
            d = np.asarray(a[k], np.float64) - np.asarray(b[k], np.float64)
            lim = float(np.nanmax(np.abs(d))) or 1.0
            im = ax[i, 2].imshow(d, cmap="coolwarm", vmin=-lim, vmax=lim)
        fig.colorbar(im, ax=ax[i, 2], fraction=0.046)
        ax[i, 0].set_title(f"{name_a}: {k}")
        ax[i, 1].set_title(f"{name_b}: {k}")
        ax[i, 2].set_title(f"{'|A - B| (mean over RGB)' if k == 'image' else 'A - B'}")
        for x in ax[i]:
            x.set_xticks([])
            x.set_yticks([])
    fig.tight_layout()
    return savefig_atomic(fig, path, dpi=80)
