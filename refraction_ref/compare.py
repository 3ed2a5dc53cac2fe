"""Diffing two runs pixel by pixel (``refraction-ref compare A.npz B.npz``)."""

from __future__ import annotations

import numpy as np

__all__ = ["angular_error_deg", "compare_arrays", "format_comparison", "plot_comparison"]


def angular_error_deg(a, b):
    """Angle in degrees between unit direction fields (..., 3); NaN where either is NaN."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c = np.sum(a * b, axis=-1)
    s = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.degrees(np.arctan2(s, c))


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
        pixels where both exited (``both_exited``); ``interfaces_agree``
        and ``status_agree`` (fractions); ``status_a`` / ``status_b``
        histograms; ``image_rmse`` over all pixels; ``hit_agree``;
        ``caustic_rel_l1`` per shared ``caustic_map_r`` (relative L1, both
        blurred by one texel). Runs without per-pixel keys (water caustics)
        get only the caustic and image statistics.
    """
    caustics = {}
    for k in sorted(a):
        if k.startswith("caustic_map_") and k in b:
            from .levelmap.metrics import relative_l1

            caustics[k] = relative_l1(a[k], b[k], blur=1.0)
    if "status" not in a or "status" not in b:  # e.g. water caustics: no per-pixel refraction keys
        out = {"caustic_rel_l1": caustics}
        if "image" in a and "image" in b and np.shape(a["image"]) == np.shape(b["image"]):
            out["image_rmse"] = float(np.sqrt(np.mean((np.asarray(a["image"], np.float64)
                                                       - np.asarray(b["image"], np.float64)) ** 2)))
        return out
    if a["status"].shape != b["status"].shape:
        raise ValueError(f"compare: image shapes differ {a['status'].shape} vs {b['status'].shape}; "
                         "render both runs with the same camera")
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
    extra = [f"{k}: relative L1 (both blurred one texel) {v:.4f}" for k, v in c.get("caustic_rel_l1", {}).items()]
    if "exit_dir_deg" not in c:
        if "image_rmse" in c:
            extra.append(f"image RMSE: {c['image_rmse']:.4f}")
        return "\n".join(extra) if extra else "nothing comparable: neither per-pixel nor caustic keys in common"
    e = c["exit_dir_deg"]
    lines = [
        f"compared {c['pixels']} pixels hit in {name_b}; both exited: {c['both_exited']}",
        f"exit direction error (deg): median {e['median']:.3f}  p90 {e['p90']:.3f}  p99 {e['p99']:.3f}  "
        f"max {e['max']:.3f}",
        f"interfaces agree: {100 * c['interfaces_agree']:.1f}%   status agree: {100 * c['status_agree']:.1f}%   "
        f"hit agree: {100 * c['hit_agree']:.2f}%",
        f"status histogram 0..4: {name_a} {c['status_a']}  {name_b} {c['status_b']}",
    ]
    if "image_rmse" in c:
        lines.append(f"image RMSE: {c['image_rmse']:.4f}")
    return "\n".join(lines + extra)


def plot_comparison(a, b, path, name_a="A", name_b="B"):
    """Write a PNG: both images, the per-pixel exit-direction error map and both status maps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    from .result import tonemap

    err = angular_error_deg(a["exit_dir"], b["exit_dir"])
    err[~(np.asarray(b["hit"], bool) & (a["status"] == 1) & (b["status"] == 1))] = np.nan
    cmap = ListedColormap(["#ffffff", "#4caf50", "#2196f3", "#ff9800", "#e91e63"])
    fig, ax = plt.subplots(1, 5, figsize=(20, 4.4))
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
    handles = [plt.Rectangle((0, 0), 1, 1, color=cmap(i)) for i in range(5)]
    fig.legend(handles, ["0 missed", "1 exited", "2 limit", "3 TIR", "4 lost"], loc="lower center", ncol=5)
    for x in ax:
        x.set_xticks([])
        x.set_yticks([])
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
