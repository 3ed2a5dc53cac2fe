"""Validation of the ``volumetric`` knobs and of the ``volume`` input block.

Defaults (:data:`VOLUMETRIC_DEFAULTS`, Sun et al. 2008's own settings) and
checks live here side by side; the blocks register themselves, and
:func:`refraction_ref.scene.load_scene` calls :func:`validate_volumetric`,
so a bad knob is refused when the scene is loaded, before any work starts.
Importing this module is cheap (no kernels).

Knobs (scene block ``volumetric``)
----------------------------------
resolution : int
    N, voxels per side of the cubic grid made by voxelization (default 128,
    as in Sun et al. 2008, Table 2). Ignored for volumetric input, whose
    arrays set the grid.
photons : int
    Photon texture side per light: up to ``photons**2`` photons, one per
    covered texel (default 1024, §4.3).
ds_min, ds_max : float
    Minimum photon step and the step limit of "almost constant" octree
    nodes (eps <= variation < eps2), in voxels (defaults 1 and 8, §4.4, §5.3).
eps, eps2 : float
    Octree tolerances epsilon and epsilon' (defaults 0.005 and 0.02, §5.3):
    a voxel's leaf is the coarsest node whose index range is below eps2,
    and its step limit is infinite when that range is also below eps.
integrator : {'euler', 'rk4'}
    'euler' is the paper's forward difference (eqs. 4-5); 'rk4' the classic
    fourth-order Runge-Kutta on the same system (eqs. 2-3), for photons and
    viewing rays.
phase_g : float
    Henyey-Greenstein asymmetry in (-1, 1); 0 is isotropic (§4.5).
scattering, absorption : float or [r, g, b]
    Scattering coefficient sigma and absorption alpha of the medium that
    fills the whole volume, per scene unit; extinction kappa = sigma + alpha
    (+ each object's ``material.absorption`` weighted by its coverage).
supersample : int
    Supersampling per axis of boundary voxels (default 4, §4.1).
blur : int
    Gaussian window in voxels, odd, sigma = blur / 6 (default 9, §4.1);
    0 or 1 keeps the sharp coverage.
padding : int
    Empty voxels kept around the objects on every side (default 6).
bounds : None or [[x0, y0, z0], [x1, y1, z1]]
    Explicit volume bounds for voxelization (None: a cube around the objects).
max_steps : int
    Per-photon step limit (0: automatic, 8 N / ds_min).
min_radiance : float
    A photon dies when its radiance falls below this fraction of its
    initial radiance (default 1e-3, §4.4).
stop_fraction : float
    Marching stops when fewer than this fraction of photons are active
    (default 1/1000, §4.4).
stiff : float
    Stiffness bound of ``stepping = 'robust'``: a step never changes ``|v|``
    by more than this fraction of n, i.e. ``ds <= stiff * n / |grad n|``
    (default 0.25). It overrides ``ds_min`` at sharp index steps. Not read
    by ``stepping = 'paper'``.
stepping : {'paper', 'robust'}
    'paper' (default) is §4.4 and §5.3 as written: the step is the distance
    to the octree node's boundary clamped to ``[ds_min, step_max]``, the
    voxel's step limit (infinite in nodes whose index range is below eps,
    ``ds_max`` where it lies in [eps, eps2)), every step applies eqs. 4-5,
    and a voxel's level-0 octree range is its own value. 'robust' adds this
    package's extensions: the ``stiff`` cap and step halving at index jumps,
    and a 26-neighbour dilation of the level-0 ranges so that constant nodes
    (range below eps over each voxel's neighbourhood; their small gradient is
    taken as zero) are crossed in one straight step.
proxy : {'inflated', 'box'}
    Where photons start (§4.3). 'inflated' (default): the light's texture
    records the proxy geometry, an inflated copy of every mesh (for
    ``volume`` input: the box of the voxels whose index differs from
    ``outside_ior``, grown by ``proxy_inflate`` voxels); texels that miss the
    proxy make no photon. 'box': the volume's bounding box (every covered
    texel makes a photon).
proxy_inflate : float
    Inflation distance of the proxy, in voxels (default 6: the 9^3 blur's
    half-width of 4 voxels, plus 2 for the trilinear and central-difference
    stencils). Must be >= 0.
"""

from __future__ import annotations

import os

import numpy as np

from ..graph import KnobBlock, register_block

__all__ = ["validate_volumetric", "INTEGRATORS", "STEPPINGS", "PROXIES", "VOLUME_KEYS", "VOLUMETRIC_DEFAULTS"]

VOLUMETRIC_DEFAULTS = {
    "resolution": 128, "photons": 1024, "ds_min": 1.0, "ds_max": 8.0, "eps": 0.005, "eps2": 0.02,
    "integrator": "euler", "phase_g": 0.0, "scattering": 0.2, "absorption": 0.0,
    "supersample": 4, "blur": 9, "padding": 6, "bounds": None, "max_steps": 0,
    "min_radiance": 1e-3, "stop_fraction": 1e-3, "stiff": 0.25,
    "stepping": "paper", "proxy": "inflated", "proxy_inflate": 6.0,
}

INTEGRATORS = ("euler", "rk4")
STEPPINGS = ("paper", "robust")
PROXIES = ("inflated", "box")
VOLUME_KEYS = ("ior", "extinction", "scattering", "bounds")


def _rgb(x, where):
    from ..validation import SceneError

    def number(v):
        # bool is an int to Python; a colour of `true` is a typo, not 1.0
        return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))

    ok = number(x) or (isinstance(x, (list, tuple)) and len(x) == 3 and all(number(v) for v in x))
    a = np.asarray(x, dtype=np.float64) if ok else None
    if a is None or a.shape not in ((), (3,)) or not np.all(np.isfinite(a)):
        raise SceneError(f"scene: '{where}' must be a finite number or a list [r, g, b], got {x!r}")
    if np.any(a < 0):
        raise SceneError(f"scene: '{where}' is {x!r}; coefficients must be >= 0")
    return np.broadcast_to(a, (3,)).copy()


def _bounds(b, where):
    from ..validation import SceneError

    try:
        a = np.asarray(b, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != (2, 3) or not np.all(np.isfinite(a)):
        raise SceneError(f"scene: '{where}' must be [[x0, y0, z0], [x1, y1, z1]] with finite numbers, got {b!r}")
    if np.any(a[1] <= a[0]):
        raise SceneError(f"scene: '{where}' is {b!r}; every upper bound must exceed the lower one")
    return a


def validate_volumetric(data, base_dir="."):
    """Check ``data['volumetric']`` and ``data['volume']``; raise SceneError on the first problem.

    The ``volume`` block is merged over ``{ior, extinction, scattering,
    bounds}`` (all None) in place; ``.npy`` paths must exist here, their
    contents are checked by :func:`refraction_ref.volumetric.pipeline.load_volume`
    before any work starts.

    Parameters
    ----------
    data : dict
        The scene's data, with ``volumetric`` (resolved knobs) and ``volume``
        blocks; ``volume`` is completed in place.
    base_dir : str
        Folder that relative ``.npy`` paths of ``volume`` are resolved against.

    Returns
    -------
    None

    Raises
    ------
    SceneError
        On the first knob or volume entry out of range.
    """
    from ..validation import SceneError, merge_defaults, check_number

    v = data["volumetric"]
    check_number(v["resolution"], "volumetric.resolution", 8, 1024, integer=True)
    check_number(v["photons"], "volumetric.photons", 1, 8192, integer=True)
    check_number(v["ds_min"], "volumetric.ds_min", 0.0, 1e6, lo_open=True)
    check_number(v["ds_max"], "volumetric.ds_max", 0.0, 1e9, lo_open=True)
    if v["ds_max"] < v["ds_min"]:
        raise SceneError(f"scene: volumetric.ds_max ({v['ds_max']}) is below volumetric.ds_min "
                         f"({v['ds_min']}); the step is clamped between them, so raise ds_max")
    check_number(v["eps"], "volumetric.eps", 0.0, lo_open=True)
    check_number(v["eps2"], "volumetric.eps2", 0.0, lo_open=True)
    if v["eps2"] < v["eps"]:
        raise SceneError(f"scene: volumetric.eps2 ({v['eps2']}) is below volumetric.eps ({v['eps']}); "
                         "the secondary tolerance must be the larger one (§5.3)")
    if v["integrator"] not in INTEGRATORS:
        raise SceneError(f"scene: 'volumetric.integrator' is {v['integrator']!r}; choose one of "
                         f"{', '.join(INTEGRATORS)}")
    check_number(v["phase_g"], "volumetric.phase_g", -0.999, 0.999)
    _rgb(v["scattering"], "volumetric.scattering")
    _rgb(v["absorption"], "volumetric.absorption")
    check_number(v["supersample"], "volumetric.supersample", 1, 16, integer=True)
    check_number(v["blur"], "volumetric.blur", 0, 63, integer=True)
    if v["blur"] > 1 and v["blur"] % 2 == 0:
        raise SceneError(f"scene: volumetric.blur is {v['blur']}; the Gaussian window must be odd (e.g. 9), "
                         "or 0 for no blur")
    check_number(v["padding"], "volumetric.padding", 0, 1000, integer=True)
    if 2 * v["padding"] + 2 > v["resolution"]:
        raise SceneError(f"scene: volumetric.padding {v['padding']} leaves no voxels for the objects at "
                         f"resolution {v['resolution']}; lower padding or raise resolution")
    if v["bounds"] is not None:
        _bounds(v["bounds"], "volumetric.bounds")
    check_number(v["max_steps"], "volumetric.max_steps", 0, 10**8, integer=True)
    check_number(v["min_radiance"], "volumetric.min_radiance", 0.0, 1.0)
    check_number(v["stop_fraction"], "volumetric.stop_fraction", 0.0, 1.0)
    check_number(v["stiff"], "volumetric.stiff", 0.0, 10.0, lo_open=True)
    if v["stepping"] not in STEPPINGS:
        raise SceneError(f"scene: 'volumetric.stepping' is {v['stepping']!r}; choose 'paper' (Sun et al. 2008 "
                         "§4.4/§5.3 as written) or 'robust' (stiffness cap, step halving, dilated octree)")
    if v["proxy"] not in PROXIES:
        raise SceneError(f"scene: 'volumetric.proxy' is {v['proxy']!r}; choose 'inflated' (photons start on an "
                         "inflated copy of the objects, §4.3) or 'box' (on the volume's bounding box)")
    check_number(v["proxy_inflate"], "volumetric.proxy_inflate", 0.0, 1000.0)
    N = int(v["resolution"])
    need = N ** 3 * 200
    if data["volume"] is None and need > 12 * 2**30:
        raise SceneError(f"scene: volumetric.resolution {N} needs about {need / 2**30:.1f} GiB; lower it")

    vol = data["volume"]
    if vol is None:
        return data
    if not isinstance(vol, dict):
        raise SceneError("scene: 'volume' must be an object {ior, extinction, scattering, bounds} or null")
    vol = merge_defaults(dict.fromkeys(VOLUME_KEYS), vol, "volume")
    data["volume"] = vol
    if vol["ior"] is None:
        raise SceneError("scene: 'volume.ior' is missing; give an (nx, ny, nz) array or a .npy path")
    if vol["bounds"] is None:
        raise SceneError("scene: 'volume.bounds' is missing; give [[x0, y0, z0], [x1, y1, z1]]")
    _bounds(vol["bounds"], "volume.bounds")
    for k in ("ior", "extinction", "scattering"):
        x = vol[k]
        if isinstance(x, (str, os.PathLike)):
            p = os.fspath(x)
            p = p if os.path.isabs(p) else os.path.join(base_dir, p)
            if not os.path.isfile(p):
                raise SceneError(f"scene: 'volume.{k}' names '{x}', which does not exist (looked for {p}); "
                                 "give an existing .npy file or an array")
            with open(p, "rb") as f:
                npy = f.read(6) == b"\x93NUMPY"
            if not npy:  # NumPy would read it as a pickle, and advise loading it unsafely
                from ..files import file_kind

                raise SceneError(f"scene: 'volume.{k}' names '{x}', which is not a .npy array ({file_kind(p)}); "
                                 "save the array with numpy.save")
    return data


BLOCK = register_block(KnobBlock("volumetric", VOLUMETRIC_DEFAULTS, validate_volumetric, owner="volumetric"))
VOLUME_BLOCK = register_block(KnobBlock("volume", None, lambda data, base_dir=".": data, owner="volumetric"))
