"""The ``volumetric`` knobs and the ``volume`` input block (Sun et al. 2008), each declared once.

Every knob is one :class:`~refraction_ref.knobs.Knob`: its type, range or
choices, default (Sun et al. 2008's own setting where the paper gives one),
meaning and section. The block's defaults, checks and the knob tables of
``docs/oracle.md`` are derived from these declarations, and
:func:`refraction_ref.scene.load_scene` runs the checks, so a bad knob is
refused when the scene is loaded, before any work starts.

The typed values the passes take are built here, from a checked block, with
the choices resolved to the integer codes the kernels read:

* :class:`MarchKnobs` (:func:`march_knobs`) for the photon march (§4.4);
* :class:`ViewKnobs` (:func:`view_knobs`) for the viewing pass (§4.5);
* :func:`octree_dilations`: which octree (level-0 ranges dilated or not) the
  march and the viewing pass read, from the stepping.

Importing this module is cheap (no kernels).
"""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np

from ..knobs import Knob, check_knob, code_of, declare_block

__all__ = ["MarchKnobs", "ViewKnobs", "march_knobs", "view_knobs", "octree_dilations", "INTEGRATORS",
           "STEPPINGS", "PROXIES", "VOLUME_KEYS", "VOLUMETRIC_DEFAULTS", "EULER", "RK4", "PAPER", "ROBUST",
           "BLOCK", "VOLUME_BLOCK"]

INTEGRATORS = ("euler", "rk4")
STEPPINGS = ("paper", "robust")
PROXIES = ("inflated", "box")


def _error(message):
    from ..validation import SceneError

    return SceneError(message)


def _rgb(x, where, data=None):
    """A scattering or absorption coefficient: a number or [r, g, b], finite and >= 0."""

    def number(v):
        # bool is an int to Python; a colour of `true` is a typo, not 1.0
        return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))

    ok = number(x) or (isinstance(x, (list, tuple)) and len(x) == 3 and all(number(v) for v in x))
    a = np.asarray(x, dtype=np.float64) if ok else None
    if a is None or a.shape not in ((), (3,)) or not np.all(np.isfinite(a)):
        raise _error(f"scene: '{where}' must be a finite number or a list [r, g, b], got {x!r}")
    if np.any(a < 0):
        raise _error(f"scene: '{where}' is {x!r}; coefficients must be >= 0")
    return np.broadcast_to(a, (3,)).copy()


def _bounds(b, where, data=None):
    """A world box [[x0, y0, z0], [x1, y1, z1]] with every upper bound above the lower one."""
    try:
        a = np.asarray(b, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != (2, 3) or not np.all(np.isfinite(a)):
        raise _error(f"scene: '{where}' must be [[x0, y0, z0], [x1, y1, z1]] with finite numbers, got {b!r}")
    if np.any(a[1] <= a[0]):
        raise _error(f"scene: '{where}' is {b!r}; every upper bound must exceed the lower one")
    return a


def _ds_max_at_least_ds_min(value, where, data):
    v = data["volumetric"]
    if value < v["ds_min"]:
        raise _error(f"scene: volumetric.ds_max ({value}) is below volumetric.ds_min "
                     f"({v['ds_min']}); the step is clamped between them, so raise ds_max")


def _eps2_at_least_eps(value, where, data):
    v = data["volumetric"]
    if value < v["eps"]:
        raise _error(f"scene: volumetric.eps2 ({value}) is below volumetric.eps ({v['eps']}); "
                     "the secondary tolerance must be the larger one (§5.3)")


def _blur_odd(value, where, data):
    if value > 1 and value % 2 == 0:
        raise _error(f"scene: volumetric.blur is {value}; the Gaussian window must be odd (e.g. 9), "
                     "or 0 for no blur")


def _padding_fits(value, where, data):
    resolution = data["volumetric"]["resolution"]
    if 2 * value + 2 > resolution:
        raise _error(f"scene: volumetric.padding {value} leaves no voxels for the objects at "
                     f"resolution {resolution}; lower padding or raise resolution")


def _stepping_known(value, where, data):
    if value not in STEPPINGS:
        raise _error(f"scene: 'volumetric.stepping' is {value!r}; choose 'paper' (Sun et al. 2008 "
                     "§4.4/§5.3 as written) or 'robust' (stiffness cap, step halving, dilated octree)")


def _proxy_known(value, where, data):
    if value not in PROXIES:
        raise _error(f"scene: 'volumetric.proxy' is {value!r}; choose 'inflated' (photons start on an "
                     "inflated copy of the objects, §4.3) or 'box' (on the volume's bounding box)")


KNOBS = (
    Knob("resolution", 128, "N, voxels per side of the cubic voxelization grid (ignored with a `volume` block)",
         "§4.1, Table 2", kind="int", lo=8, hi=1024),
    Knob("photons", 1024, "photon texture side per light (up to `photons^2` photons, one per covered texel)",
         "§4.3", kind="int", lo=1, hi=8192),
    Knob("ds_min", 1.0, "minimum photon step, in voxels", "§4.4", kind="float", lo=0.0, hi=1e6, lo_open=True,
         allowed="> 0"),
    Knob("ds_max", 8.0, 'step limit in "almost constant" octree nodes, in voxels', "§4.4, §5.3", kind="float",
         lo=0.0, hi=1e9, lo_open=True, allowed=">= ds_min", check=_ds_max_at_least_ds_min),
    Knob("eps", 0.005, "octree tolerance epsilon", "§5.3", kind="float", lo=0.0, lo_open=True),
    Knob("eps2", 0.02, "octree tolerance epsilon'", "§5.3", kind="float", lo=0.0, lo_open=True, allowed=">= eps",
         check=_eps2_at_least_eps),
    Knob("integrator", "euler", "forward differences (eqs. 4-5), or classic RK4 on the same system (beyond the "
         "paper)", "§4.4", kind="choice", choices=INTEGRATORS),
    Knob("phase_g", 0.0, "Henyey-Greenstein asymmetry; 0 is isotropic", "§4.5", kind="float", lo=-0.999, hi=0.999,
         allowed="[-0.999, 0.999]"),
    Knob("scattering", 0.2, "scattering coefficient sigma of the medium filling the volume, per scene unit",
         "§4.4, §4.5", allowed="number or [r, g, b], >= 0", check=_rgb),
    Knob("absorption", 0.0, "absorption alpha of that medium; extinction kappa = sigma + alpha (+ each object's "
         "`material.absorption` weighted by its coverage)", "eq. 6", allowed="number or [r, g, b], >= 0",
         check=_rgb),
    Knob("supersample", 4, "supersampling per axis of boundary voxels", "§4.1", kind="int", lo=1, hi=16),
    Knob("blur", 9, "Gaussian window in voxels, sigma = blur/6; 0 or 1 keeps the sharp coverage", "§4.1",
         kind="int", lo=0, hi=63, allowed="integer 0..63, odd or 0/1", check=_blur_odd),
    Knob("padding", 6, "empty voxels around the objects on every side", kind="int", lo=0, hi=1000,
         allowed="integer 0..1000, 2 padding + 2 <= resolution", check=_padding_fits),
    Knob("bounds", None, "explicit voxelization bounds (null: a cube around the objects)", nullable=True,
         allowed="null or [[x0, y0, z0], [x1, y1, z1]], upper > lower", check=_bounds),
    Knob("max_steps", 0, "per-photon step limit; 0 = automatic, about 8 N / ds_min", kind="int", lo=0, hi=10**8,
         allowed="integer 0..10^8"),
    Knob("min_radiance", 1e-3, "a photon dies below this fraction of its initial radiance", "§4.4", kind="float",
         lo=0.0, hi=1.0, allowed="[0, 1]"),
    Knob("stop_fraction", 1e-3, "marching stops when fewer than this fraction of photons are active; 0: no "
         "stopping rule", "§4.4", kind="float", lo=0.0, hi=1.0, allowed="[0, 1]"),
    Knob("stiff", 0.25, 'stiffness bound of `stepping = "robust"`: one step never changes `|v|` by more than this '
         'fraction of n (beyond the paper); not read by `"paper"`', kind="float", lo=0.0, hi=10.0, lo_open=True,
         allowed="(0, 10]"),
    Knob("stepping", "paper", '`"paper"`: §4.4/§5.3 as written: the step is the distance to the octree node\'s '
         "boundary clamped to [`ds_min`, the voxel's `step_max`] (`step_max` is infinite in nodes whose index range "
         "is below `eps` and `ds_max` where it lies in [`eps`, `eps2`); §5.3's node Δs_max, not the knob `ds_max` "
         "everywhere), every step applies eqs. 4-5, a voxel's level-0 octree range is its own value; `\"robust\"` "
         "(beyond the paper): the `stiff` cap, step halving at index jumps, and the octree's level-0 ranges dilated "
         "over the 26 neighbours, so that constant nodes (range below `eps` over each voxel's neighbourhood; their "
         "small gradient is taken as zero) are crossed in one straight step", "§4.2, §4.4, §5.3",
         choices=STEPPINGS, allowed='"paper", "robust"', check=_stepping_known),
    Knob("proxy", "inflated", 'where photons start: `"inflated"`: only texels whose ray meets the proxy geometry '
         "make photons, starting on it: the objects' meshes inflated by `proxy_inflate` voxels (nearest front face "
         "per texel; a back face: the box), or for `volume` input the box of the voxels whose index differs from "
         "`outside_ior` by at least 1e-6 (`>= 1e-6`) grown by `proxy_inflate` voxels; `\"box\"`: the volume's "
         "bounding box. The light's texture keeps the box's window either way", "§4.3",
         choices=PROXIES, allowed='"inflated", "box"', check=_proxy_known),
    Knob("proxy_inflate", 6.0, "inflation of the proxy, in voxels (6: the 9^3 blur's half-width of 4, plus 2 for "
         "the interpolation and gradient stencils)", "§4.3", kind="float", lo=0.0, hi=1000.0, allowed="[0, 1000]"),
)

_BY_NAME = {k.name: k for k in KNOBS}


def _memory_fits(data, base_dir="."):
    """The voxelization's buffers (about 200 bytes per voxel) fit in memory."""
    N = int(data["volumetric"]["resolution"])
    need = N ** 3 * 200
    if data["volume"] is None and need > 12 * 2**30:
        raise _error(f"scene: volumetric.resolution {N} needs about {need / 2**30:.1f} GiB; lower it")


BLOCK = declare_block("volumetric", KNOBS, owner="volumetric", extra=_memory_fits)
VOLUMETRIC_DEFAULTS = BLOCK.defaults


# --------------------------------------------------------------------- the volume block
def _npy_path(x, where, data, base_dir):
    """A ``volume`` entry given as a path names an existing ``.npy`` file (its contents are read by
    :func:`refraction_ref.volumetric.pipeline.load_volume` before any work starts)."""
    if not isinstance(x, (str, os.PathLike)):
        return
    p = os.fspath(x)
    p = p if os.path.isabs(p) else os.path.join(base_dir, p)
    if not os.path.isfile(p):
        raise _error(f"scene: '{where}' names '{x}', which does not exist (looked for {p}); "
                     "give an existing .npy file or an array")
    with open(p, "rb") as f:
        npy = f.read(6) == b"\x93NUMPY"
    if not npy:  # NumPy would read it as a pickle, and advise loading it unsafely
        from ..files import file_kind

        raise _error(f"scene: '{where}' names '{x}', which is not a .npy array ({file_kind(p)}); "
                     "save the array with numpy.save")


def _ior_given(value, where, data):
    if value is None:
        raise _error("scene: 'volume.ior' is missing; give an (nx, ny, nz) array or a .npy path")


def _bounds_given(value, where, data):
    if value is None:
        raise _error("scene: 'volume.bounds' is missing; give [[x0, y0, z0], [x1, y1, z1]]")
    _bounds(value, where)


VOLUME_KNOBS = (
    Knob("ior", None, "index of refraction per voxel; **required**", "§3",
         allowed="(nx, ny, nz) array or `.npy` path; every axis >= 4; finite, > 0", check=_ior_given),
    Knob("bounds", None, "world box of the grid; **required**", "§3",
         allowed="[[x0, y0, z0], [x1, y1, z1]], upper > lower", check=_bounds_given),
    Knob("extinction", None, "kappa per scene unit (null: from the `volumetric` knobs)", "§3",
         allowed="null, number, [r, g, b], (nx, ny, nz) or (nx, ny, nz, 3); >= 0"),
    Knob("scattering", None, "sigma per scene unit (null: `volumetric.scattering`); a number or [r, g, b] fills "
         "every voxel, an (nx, ny, nz) array every channel, as `extinction`'s shapes do. It is the viewing pass's "
         "sigma; with `extinction` null, kappa is built from it (`march`, Extinction kappa)", "§3",
         allowed="same shapes (null, a number, [r, g, b], (nx, ny, nz) or (nx, ny, nz, 3)); >= 0"),
)
VOLUME_KEYS = tuple(k.name for k in VOLUME_KNOBS)


def _merge_volume(data):
    """Fill a given ``volume`` block with its keys (all None); a null block stays null."""
    from ..validation import merge_defaults

    vol = data.get("volume")
    if vol is None:
        return
    if not isinstance(vol, dict):
        raise _error("scene: 'volume' must be an object {ior, extinction, scattering, bounds} or null")
    data["volume"] = merge_defaults(dict.fromkeys(VOLUME_KEYS), vol, "volume")


def _volume_files(data, base_dir="."):
    """Paths of ``volume`` name existing ``.npy`` files, resolved against ``base_dir``."""
    vol = data["volume"]
    for k in ("ior", "extinction", "scattering"):
        _npy_path(vol[k], f"volume.{k}", data, base_dir)


VOLUME_BLOCK = declare_block("volume", VOLUME_KNOBS, owner="volumetric", extra=_volume_files,
                             merge=_merge_volume, present=False)


# --------------------------------------------------------------------- typed values for the passes
EULER, RK4 = (code_of(_BY_NAME["integrator"], c) for c in INTEGRATORS)
PAPER, ROBUST = (code_of(_BY_NAME["stepping"], c) for c in STEPPINGS)


class MarchKnobs(NamedTuple):
    """The photon march's knobs, choices resolved to codes (:func:`march_knobs`).

    Attributes
    ----------
    ds_min : float
        Minimum step, in voxels of the smallest side (§4.4).
    stiff : float
        Stiffness bound of the 'robust' stepping.
    integrator : int
        :data:`EULER` (eqs. 4-5) or :data:`RK4`.
    max_steps : int
        Per-photon step limit; 0: ``8 * max(shape) / ds_min`` (+ 16).
    min_radiance : float
        A photon dies below this fraction of its start radiance (§4.4).
    stop_fraction : float
        The stopping rule's fraction of active photons (§4.4); 0: none.
    stepping : int
        :data:`PAPER` (§4.4 / §5.3 as written) or :data:`ROBUST`.
    """

    ds_min: float
    stiff: float
    integrator: int
    max_steps: int
    min_radiance: float
    stop_fraction: float
    stepping: int


class ViewKnobs(NamedTuple):
    """The viewing pass's knobs (:func:`view_knobs`): :data:`EULER` or :data:`RK4`, and the phase's asymmetry g."""

    integrator: int
    phase_g: float


def _resolved(block):
    """The ``volumetric`` block over its declared defaults, each given knob checked by its declaration."""
    v = dict(VOLUMETRIC_DEFAULTS, **(block or {}))
    data = {"volumetric": v, "volume": None}
    for name in (block or {}):
        if name in _BY_NAME:
            check_knob(_BY_NAME[name], v[name], f"volumetric.{name}", data)
    return v


def march_knobs(block=None):
    """The march's :class:`MarchKnobs` from a ``volumetric`` block (None or missing keys: the defaults).

    Parameters
    ----------
    block : dict, optional
        The scene's ``volumetric`` block, or some of its keys
        (``{"stepping": "robust"}``) over the declared defaults.

    Returns
    -------
    MarchKnobs

    References
    ----------
    Sun et al. (2008), §4.4 (photon marching) and §5.3 (step control).
    """
    v = _resolved(block)
    return MarchKnobs(float(v["ds_min"]), float(v["stiff"]), code_of(_BY_NAME["integrator"], v["integrator"]),
                      int(v["max_steps"]), float(v["min_radiance"]), float(v["stop_fraction"]),
                      code_of(_BY_NAME["stepping"], v["stepping"]))


def view_knobs(block=None):
    """The viewing pass's :class:`ViewKnobs` from a ``volumetric`` block (None or missing keys: the defaults).

    Parameters
    ----------
    block : dict, optional
        The scene's ``volumetric`` block, or some of its keys.

    Returns
    -------
    ViewKnobs

    References
    ----------
    Sun et al. (2008), §4.5 (viewing pass).
    """
    v = _resolved(block)
    return ViewKnobs(code_of(_BY_NAME["integrator"], v["integrator"]), float(v["phase_g"]))


def octree_dilations(stepping):
    """Whether the octree the march reads, and the one the viewing pass reads, dilate their level-0 ranges.

    'paper' stepping reads the octree as §4.2 builds it (a voxel's level-0
    range is its own value; every step applies eqs. 4-5); 'robust' reads the
    level-0 ranges dilated over the 26 neighbours, whose constant nodes it
    crosses in one straight step. The viewing pass always reads the dilated
    one: it crosses nodes whose gradient is zero in straight steps (an exact
    shortcut of §4.5's fixed step), whatever the photons' stepping.

    Parameters
    ----------
    stepping : str or int
        ``volumetric.stepping`` ('paper', 'robust') or its code.

    Returns
    -------
    march, view : bool
        ``dilate`` of :func:`~refraction_ref.volumetric.octree.build_octree`
        for each pass; equal values share one octree.

    References
    ----------
    Sun et al. (2008), §4.2, §4.4, §4.5 and §5.3.
    """
    code = stepping if isinstance(stepping, (int, np.integer)) else code_of(_BY_NAME["stepping"], stepping)
    return code == ROBUST, True
