"""A failing key's picture: candidate, golden and their difference, the located failures marked (PNG).

Matplotlib is imported where a panel is drawn: ``refraction_ref.check`` is imported with the package, and a
check that passes (or runs with ``panels=False``) draws none.
"""

from __future__ import annotations

import numpy as np

from ..files import savefig_atomic
from .masks import popcount

__all__ = ["failure_panel"]


def _view(shape, bad, kind, pics):
    """Which 2D picture of an array to show: (index into the array, label), the one with the most failures."""
    bad = np.asarray(bad) if bad is not None else None
    pic_shapes = list(pics)
    if len(shape) >= 3 and tuple(shape[1:3]) in pic_shapes and tuple(shape[:2]) not in pic_shapes:
        counts = bad.reshape(shape[0], -1).sum(axis=1) if bad is not None and bad.shape[:1] == shape[:1] else None
        i = int(np.argmax(counts)) if counts is not None and counts.any() else 0
        return (i,), f"layer {i} of {shape[0]} (the one with the most failures)"
    if len(shape) == 4:  # (H, W, K, 3): interface k
        counts = bad.reshape(shape[0] * shape[1], shape[2], -1).any(-1).sum(0) if bad is not None \
            and bad.ndim >= 3 else None
        i = int(np.argmax(counts)) if counts is not None and counts.any() else 0
        return (slice(None), slice(None), i), f"interface {i} of {shape[2]}"
    return (), ""


def failure_panel(path, key, c, g, bad, kind=None, pics=None):
    """Candidate, golden and their difference for a failing array, the failing elements marked in red.

    Bit words (H, W, K) show the set bits per pixel and the bits that differ
    (popcount of XOR); unit vectors (``kind == 'angle'``, (..., 3)) show the
    directions as colours and the angle between them in degrees; layered
    arrays (L, H, W, ...) and path records (H, W, K, 3) the layer or
    interface with the most failures (named in the titles); 3-vectors
    otherwise their length.

    Parameters
    ----------
    path : str
        The PNG file.
    key : str
        The key (the titles).
    c, g : ndarray
        The candidate's and the golden's arrays.
    bad : bool ndarray or None
        The located failures.
    kind : str, optional
        The tolerance's kind (``'angle'``: unit vectors).
    pics : dict, optional
        The case's pictures (:func:`~refraction_ref.golden.masks.ambiguity_context`): which axes are a layer's.

    Returns
    -------
    str or None
        The file written, or None when the arrays cannot be pictured.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    c, g = np.asarray(c), np.asarray(g)
    if c.shape != g.shape or c.ndim < 2:
        return None
    idx, label = _view(c.shape, bad, kind, pics or {})
    if idx:
        c, g = c[idx], g[idx]
        bad = np.asarray(bad)[idx] if bad is not None and np.ndim(bad) >= len(idx) else bad
    bad2 = None
    if bad is not None:
        b = np.asarray(bad)
        while b.ndim > 2:
            b = b.any(axis=-1)
        bad2 = b if b.shape == c.shape[:2] else None

    def img(a):
        a = np.asarray(a, np.float64)
        while a.ndim > 3 or (a.ndim == 3 and a.shape[-1] not in (3,)):
            a = a[a.shape[0] // 2] if a.ndim > 3 or a.shape[0] > 3 else a[0]
        if a.ndim == 3:
            a = np.linalg.norm(np.nan_to_num(a), axis=-1)
        return np.atleast_2d(a)

    rgb = None
    comp = ""
    if np.issubdtype(c.dtype, np.unsignedinteger) and c.ndim == 3:
        ci, gi, diff = popcount(c), popcount(g), popcount(c ^ g)
        names = ("set bits per pixel", "bits that differ")
    elif kind == "angle" and c.shape[-1] == 3 and c.ndim in (2, 3):
        cf, gf = np.asarray(c, np.float64), np.asarray(g, np.float64)
        if c.ndim == 2:  # (N, 3): a strip
            cf, gf = cf[None], gf[None]
            bad2 = None
        unit = lambda a: a / np.maximum(np.linalg.norm(np.nan_to_num(a), axis=-1, keepdims=True), 1e-300)  # noqa: E731
        cos = np.clip(np.sum(unit(np.nan_to_num(cf)) * unit(np.nan_to_num(gf)), axis=-1), -1.0, 1.0)
        diff = np.degrees(np.arccos(cos))
        diff[~(np.all(np.isfinite(cf), -1) & np.all(np.isfinite(gf), -1))] = np.nan
        rgb = [np.clip(0.5 + 0.5 * np.nan_to_num(unit(a)), 0.0, 1.0) for a in (cf, gf)]
        ci = gi = None
        names = ("direction as colour (x, y, z -> r, g, b)", "angle between them (deg)")
    else:
        if c.ndim == 3 and c.shape[-1] == 3:
            comp = "length of the 3-vector"
        ci, gi = img(c), img(g)
        if ci.ndim != 2 or ci.shape != gi.shape:
            return None
        with np.errstate(invalid="ignore"):  # inf - inf where both are absent: shown blank
            diff = np.abs(ci - gi)
        names = (comp, "|candidate - golden|")
    sub = "; ".join(x for x in (label, names[0]) if x)
    fig = Figure(figsize=(12, 4.4))
    FigureCanvasAgg(fig)
    ax = fig.subplots(1, 3)
    if rgb is not None:
        for x, a, t in ((ax[0], rgb[0], "candidate"), (ax[1], rgb[1], "golden")):
            x.imshow(a, interpolation="nearest")
            x.set_title(f"{t}: {key}\n{sub}", fontsize=9)
    else:
        fin = np.isfinite(gi)
        lo, hi = (float(np.min(gi[fin])), float(np.max(gi[fin]))) if fin.any() else (0.0, 1.0)
        for x, a, t in ((ax[0], ci, "candidate"), (ax[1], gi, "golden")):
            im = x.imshow(a, vmin=lo, vmax=hi if hi > lo else lo + 1, cmap="viridis", interpolation="nearest")
            x.set_title(f"{t}: {key}" + (f"\n{sub}" if sub else ""), fontsize=9)
            fig.colorbar(im, ax=x, fraction=0.046)
    im = ax[2].imshow(diff, cmap="magma", interpolation="nearest")
    title = names[1]
    if bad2 is not None and bad2.shape == np.shape(diff) and bad2.any():
        ax[2].imshow(np.ma.masked_where(~bad2, np.ones(bad2.shape)), cmap="autumn", vmin=0, vmax=1,
                     interpolation="nearest", alpha=0.8)
        title += f"\nred: {int(bad2.sum())} failing outside the ambiguity mask"
    ax[2].set_title(title, fontsize=9)
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    for x in ax:
        x.set_xticks([])
        x.set_yticks([])
    fig.tight_layout()
    return savefig_atomic(fig, path, dpi=70)
