"""The cross-check report's figures: ours, Mitsuba's and their difference side by side (PNG per case and part)."""

from __future__ import annotations

import os

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["paths_figure", "images_figure", "caustics_figure"]


def _panels(n):
    """A row of ``n`` square panels (the report's figures: A, B, A-B, ...) on an Agg canvas."""
    fig = Figure(figsize=(4 * n, 4))
    FigureCanvasAgg(fig)
    return fig, fig.subplots(1, n)


def _save_panels(fig, ax, path, title):
    """Write a figure of :func:`_panels` to ``path``; its file name, as the report links it."""
    for a in ax:
        a.axis("off")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    return os.path.basename(path)


def paths_figure(f, path, name, what="status"):
    """The paths part's figure: the status (or ``what``) of ours and Mitsuba's, and the exit angle between them.

    Parameters
    ----------
    f : dict
        ``status_ours``, ``status_mitsuba`` (H, W) and ``angle`` (H, W) degrees
        (:func:`~refraction_ref.interop.paths.paths_case`,
        :func:`~refraction_ref.interop.water.water_paths_case`).
    path : str
        The PNG file.
    name : str
        The case name (the title).
    what : str
        What the status panels show (``'status'``, or ``'meets the water'``).

    Returns
    -------
    str
        The file's name.
    """
    fig, ax = _panels(3)
    ax[0].imshow(f["status_ours"], vmin=0, vmax=4, cmap="tab10", interpolation="nearest")
    ax[0].set_title(f"A: {what}, ours (exact)")
    ax[1].imshow(f["status_mitsuba"], vmin=0, vmax=4, cmap="tab10", interpolation="nearest")
    ax[1].set_title(f"B: {what}, Mitsuba paths")
    im = ax[2].imshow(np.log10(np.maximum(f["angle"], 1e-7)), vmin=-6, vmax=1, cmap="magma", interpolation="nearest")
    ax[2].set_title("A-B: " + ("refracted" if what != "status" else "exit") + " angle, log10 deg")
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    return _save_panels(fig, ax, path, name)


def images_figure(f, path, name):
    """The images part's figure: ours, Mitsuba's parts, their difference (grey: not judged), ``path``, Fresnel.

    Parameters
    ----------
    f : dict
        ``ours``, ``mitsuba``, ``path``, ``fresnel`` (H, W, 3) and ``judged``
        (H, W) (:func:`~refraction_ref.interop.images.images_case`).
    path, name
        As :func:`paths_figure`.

    Returns
    -------
    str
        The file's name.
    """
    fig, ax = _panels(5)
    ax[0].imshow(np.clip(f["ours"], 0, 1), interpolation="nearest")
    ax[0].set_title("A: ours (exact)")
    ax[1].imshow(np.clip(f["mitsuba"], 0, 1), interpolation="nearest")
    ax[1].set_title("B: Mitsuba parts, Fresnel-free")
    d = (f["ours"] - f["mitsuba"]).mean(-1)
    im = ax[2].imshow(d, vmin=-0.5, vmax=0.5, cmap="RdBu", interpolation="nearest")
    ax[2].set_title("A-B (grey: not judged)")
    ax[2].contourf(~f["judged"], levels=[0.5, 1.5], colors=["0.6"], alpha=0.35)
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    ax[3].imshow(np.clip(f["path"], 0, 1), interpolation="nearest")
    ax[3].set_title("Mitsuba path integrator")
    ax[4].imshow(np.clip(f["fresnel"], 0, 1), interpolation="nearest")
    ax[4].set_title("Mitsuba dielectric (Fresnel)")
    return _save_panels(fig, ax, path, name)


def caustics_figure(figs, path, name):
    """The caustics part's figure: receiver 0's K-batch means, ours and Mitsuba's, and their difference.

    Parameters
    ----------
    figs : list of dict
        Per receiver ``ours`` and ``mitsuba`` (:func:`~refraction_ref.interop.caustics.caustics_case`).
    path, name
        As :func:`paths_figure`.

    Returns
    -------
    str
        The file's name.
    """
    f = figs[0]
    vmax = float(np.percentile(f["ours"], 99.5)) or 1.0
    fig, ax = _panels(3)
    ax[0].imshow(f["ours"], vmin=0, vmax=vmax, cmap="inferno", interpolation="nearest")
    ax[0].set_title("A: ours (exact), K-batch mean")
    ax[1].imshow(f["mitsuba"], vmin=0, vmax=vmax, cmap="inferno", interpolation="nearest")
    ax[1].set_title("B: photons on Mitsuba's intersector")
    im = ax[2].imshow(f["ours"] - f["mitsuba"], vmin=-vmax / 4, vmax=vmax / 4, cmap="RdBu", interpolation="nearest")
    ax[2].set_title("A-B")
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    return _save_panels(fig, ax, path, name + ": caustic_map_0")
