"""The one pinhole camera model shared by every method.

View space is right-handed and looks down -z (OpenGL); "depth" is the
view-space distance along the view axis, ``d = -z_view > 0``. Pixel (row i,
column j) is sampled at its centre, normalised screen coordinates
``((j + 0.5) / W, (i + 0.5) / H)`` with row 0 at the top (docs/oracle.md).

Screen coordinates used by the kernels are continuous pixel units:
``col = j + 0.5`` and ``row = i + 0.5`` at pixel centres. The projection of
a view-space point ``(x, y, z)`` with ``d = -z`` is::

    col = (x / (d * sx) * 0.5 + 0.5) * W
    row = (0.5 - y / (d * sy) * 0.5) * H

with ``sy = tan(fov_y / 2)`` and ``sx = sy * W / H``; it is the texture
coordinate mapping of Chaudhari (2008), §3.6, scaled to pixels.

An *orthographic* camera (``projection='orthographic'``, the view of a
directional light in caustics mapping) uses the same formulas with ``d``
replaced by 1 and ``sy = ortho_height / 2``, ``sx = sy * W / H`` the half
extents of the view window: every numba helper takes the flag ``ortho``
(``Camera.ortho``), so one set of image-space passes serves both views.
Depth stays the view-space distance ``-z`` along the view axis.

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §3.5 (unprojection of a pixel with a
   known view-space depth) and §3.6 (texture coordinates of a point).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .vec3 import affine

__all__ = ["Camera", "project_point", "unproject_pixel"]


_FRAME_DOC = """{verb} {src}-space {what} (..., 3) into {dst} space{note}.

Parameters
----------
p : (..., 3) array_like
    {Src}-space {what}{trans}.

Returns
-------
(..., 3) float64 ndarray
    {Dst}-space {what}.
"""


def _frame_method(to_world, points, note):
    """One of the camera's four frame maps (points or directions, view to world or back), documented."""
    src, dst = ("view", "world") if to_world else ("world", "view")
    what = "points" if points else "directions"

    def frame_map(self, p):
        return self._frame_map(p, to_world, points)

    frame_map.__name__ = f"{'' if points else 'dir_'}{src}_to_{dst}"
    frame_map.__qualname__ = "Camera." + frame_map.__name__
    frame_map.__doc__ = _FRAME_DOC.format(
        verb="Transform" if points else "Rotate", src=src, dst=dst, Src=src.capitalize(), Dst=dst.capitalize(),
        what=what, note=note, trans="" if points else " (no translation applied)")
    return frame_map


@dataclass(frozen=True)
class Camera:
    """A pinhole (perspective) or orthographic camera.

    Parameters
    ----------
    eye, target, up : (3,) array_like
        Position, look-at point and up hint in world space.
    fov_y : float
        Full vertical field of view in degrees (perspective).
    width, height : int
        Image size in pixels.
    near, far : float
        Clip distances along the view axis (depth).
    projection : {'perspective', 'orthographic'}
        The orthographic view is that of a directional light (caustics
        mapping, Chaudhari 2008 §4.1): parallel rays along the view axis,
        starting on the plane through ``eye``.
    ortho_height : float
        Full height of the orthographic view window in world units.
    """

    eye: tuple
    target: tuple
    up: tuple
    fov_y: float
    width: int
    height: int
    near: float
    far: float
    projection: str = "perspective"
    ortho_height: float = 0.0

    def __post_init__(self):
        if self.projection not in ("perspective", "orthographic"):
            raise ValueError(f"Camera: projection must be 'perspective' or 'orthographic', got {self.projection!r}")
        if self.projection == "orthographic" and not self.ortho_height > 0:
            raise ValueError(f"Camera: an orthographic camera needs ortho_height > 0, got {self.ortho_height}")

    @property
    def ortho(self):
        """True for an orthographic camera (the ``ortho`` flag of the numba helpers)."""
        return self.projection == "orthographic"

    @classmethod
    def from_dict(cls, c):
        """Build a camera from the scene's ``camera`` block.

        Parameters
        ----------
        c : dict
            Keys ``eye``, ``target``, ``up`` (3 numbers each), ``fov_y``
            (degrees), ``width``, ``height`` (pixels), ``near``, ``far``, and
            optionally ``projection`` (default ``'perspective'``) and
            ``ortho_height`` (default 0).

        Returns
        -------
        Camera
        """
        return cls(
            eye=tuple(float(v) for v in c["eye"]),
            target=tuple(float(v) for v in c["target"]),
            up=tuple(float(v) for v in c["up"]),
            fov_y=float(c["fov_y"]),
            width=int(c["width"]),
            height=int(c["height"]),
            near=float(c["near"]),
            far=float(c["far"]),
            projection=str(c.get("projection", "perspective")),
            ortho_height=float(c.get("ortho_height", 0.0)),
        )

    # -- frames ---------------------------------------------------------
    @property
    def basis(self):
        """(3, 3) rows: camera right, up and backward (+z view) axes in world space."""
        eye = np.asarray(self.eye)
        f = np.asarray(self.target) - eye
        f = f / np.linalg.norm(f)
        r = np.cross(f, np.asarray(self.up))
        r = r / np.linalg.norm(r)
        u = np.cross(r, f)
        return np.stack([r, u, -f])

    @property
    def sx(self):
        """Horizontal half extent: of the image plane at unit depth, or of the orthographic window."""
        return float(self.sy * self.width / self.height) if self.ortho else \
            float(np.tan(np.radians(self.fov_y) / 2.0) * self.width / self.height)

    @property
    def sy(self):
        """Vertical half extent: ``tan(fov_y / 2)``, or half the orthographic window."""
        return float(self.ortho_height / 2.0) if self.ortho else float(np.tan(np.radians(self.fov_y) / 2.0))

    @property
    def shape(self):
        return (self.height, self.width)

    def _frame_map(self, p, to_world, points):
        """``p`` (..., 3) from view to world space (``to_world``) or back; translated when ``points``."""
        b = self.basis
        eye = np.asarray(self.eye, dtype=np.float64)
        if not points:
            return affine(p, b if to_world else b.T, np.zeros(3))
        return affine(p, b, eye) if to_world else affine(p, b.T, -eye @ b.T)

    world_to_view = _frame_method(False, True, "")
    view_to_world = _frame_method(True, True, " (NaN stays NaN)")
    dir_world_to_view = _frame_method(False, False, "")
    dir_view_to_world = _frame_method(True, False, "")

    def projection_matrix(self):
        """The OpenGL projection matrix M_p (view to clip space), perspective or orthographic."""
        n, f = self.near, self.far
        m = np.zeros((4, 4))
        if self.ortho:
            m[0, 0] = 1.0 / self.sx
            m[1, 1] = 1.0 / self.sy
            m[2, 2] = -2.0 / (f - n)
            m[2, 3] = -(f + n) / (f - n)
            m[3, 3] = 1.0
            return m
        m[0, 0] = 1.0 / self.sx
        m[1, 1] = 1.0 / self.sy
        m[2, 2] = -(f + n) / (f - n)
        m[2, 3] = -2.0 * f * n / (f - n)
        m[3, 2] = -1.0
        return m

    def primary_rays_view(self):
        """Unit view-space directions through every pixel centre, (H, W, 3) (all ``-z`` when orthographic)."""
        d = np.empty((self.height, self.width, 3))
        _primary_rays(self.width, self.height, self.sx, self.sy, np.eye(3), np.zeros(3), np.empty((0, 0, 3)), d,
                      self.ortho)
        return d

    def primary_rays(self):
        """World-space origins and unit directions of the primary rays, each (H, W, 3).

        Perspective rays start at the eye; orthographic ones at the pixel
        centres of the window on the plane through the eye.
        """
        d = np.empty((self.height, self.width, 3))
        o = np.empty_like(d)
        _primary_rays(self.width, self.height, self.sx, self.sy, self.basis,
                      np.asarray(self.eye, dtype=np.float64), o, d, self.ortho)
        return o, d

    def to_screen(self, p_view):
        """Project view-space points (..., 3) to (col, row, depth) in pixel units.

        Parameters
        ----------
        p_view : (..., 3) array_like
            View-space points.

        Returns
        -------
        col, row : (...) float64 ndarray
            Continuous screen position in pixels (pixel centres at ``j + 0.5``,
            ``i + 0.5``; row 0 at the top); inf/NaN at depth 0 (perspective).
        depth : (...) float64 ndarray
            View-space depth ``-z``.

        References
        ----------
        .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
           Objects", M.S. thesis, UMBC, 2008, §3.6 (texture coordinates of a point).
        """
        p = np.asarray(p_view, dtype=np.float64)
        d = -p[..., 2]
        s = np.ones_like(d) if self.ortho else d
        with np.errstate(divide="ignore", invalid="ignore"):
            col = (p[..., 0] / (s * self.sx) * 0.5 + 0.5) * self.width
            row = (0.5 - p[..., 1] / (s * self.sy) * 0.5) * self.height
        return col, row, d

    def kernel_args(self):
        """Scalars the Numba kernels need: (W, H, sx, sy); pass ``ortho`` along with them.

        Returns
        -------
        W, H : int
            Image width and height in pixels.
        sx, sy : float
            Half extents of the image plane at unit depth (:attr:`sx`,
            :attr:`sy`), or of the orthographic window.
        """
        return self.width, self.height, self.sx, self.sy


@nb.njit(cache=True, inline="always")
def _pixel_xy(i, j, W, H, sx, sy):
    """(x, y) of pixel (row i, col j)'s centre on the image plane at unit depth (on the window, orthographic)."""
    return ((j + 0.5) / W * 2.0 - 1.0) * sx, (1.0 - (i + 0.5) / H * 2.0) * sy


@nb.njit(cache=True, inline="always")
def primary_dir(i, j, W, H, sx, sy, ortho=False):
    """Unit view-space direction of the primary ray through pixel (row i, col j)'s centre.

    Parameters
    ----------
    i, j : int
        Pixel row (0 at the top) and column.
    W, H : int
        Image width and height in pixels.
    sx, sy : float
        Half extents of the image plane at unit depth (``Camera.sx``, ``Camera.sy``).
    ortho : bool
        Orthographic camera: every ray is ``(0, 0, -1)``.

    Returns
    -------
    x, y, z : float
        Unit direction in view space (z < 0).

    References
    ----------
    .. [1] P. Shirley, S. Marschner, *Fundamentals of Computer Graphics*, 3rd
       ed., §4.3 (perspective viewing rays of a pinhole camera).
    """
    if ortho:
        return 0.0, 0.0, -1.0
    x, y = _pixel_xy(i, j, W, H, sx, sy)
    s = 1.0 / np.sqrt(x * x + y * y + 1.0)
    return x * s, y * s, -s


@nb.njit(cache=True, parallel=True)
def _primary_rays(W, H, sx, sy, basis, eye, origin, out, ortho=False):
    """Directions through pixel centres rotated by ``basis`` (rows: right, up, back), and their
    origins moved by ``eye`` (skipped when ``origin`` is empty)."""
    with_origin = origin.shape[0] > 0
    for i in nb.prange(H):
        for j in range(W):
            x, y, z = primary_dir(i, j, W, H, sx, sy, ortho)
            for k in range(3):
                out[i, j, k] = x * basis[0, k] + y * basis[1, k] + z * basis[2, k]
            if not with_origin:
                continue
            if ortho:
                xw, yw = _pixel_xy(i, j, W, H, sx, sy)
                for k in range(3):
                    origin[i, j, k] = eye[k] + xw * basis[0, k] + yw * basis[1, k]
            else:
                for k in range(3):
                    origin[i, j, k] = eye[k]


@nb.njit(cache=True, inline="always")
def project_point(x, y, z, W, H, sx, sy, ortho=False):
    """Project a view-space point to (col, row, depth); Chaudhari (2008) §3.6.

    With ``ortho`` the division by the depth is dropped (orthographic view).

    Parameters
    ----------
    x, y, z : float
        View-space point (``z < 0`` in front of the camera).
    W, H, sx, sy, ortho : int, int, float, float, bool
        The camera's :meth:`Camera.kernel_args` and :attr:`Camera.ortho`.

    Returns
    -------
    col, row : float
        Continuous screen position in pixels (row 0 at the top).
    d : float
        View-space depth ``-z``.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §3.6 (texture coordinates of a point).
    """
    # written with the factors W / (2 sx) etc. apart, so that a loop over
    # pixels computes them once: one division per point, not two
    d = -z
    if ortho:
        col = x * (0.5 * W / sx) + 0.5 * W
        row = 0.5 * H - y * (0.5 * H / sy)
        return col, row, d
    inv = 1.0 / d
    col = x * inv * (0.5 * W / sx) + 0.5 * W
    row = 0.5 * H - y * inv * (0.5 * H / sy)
    return col, row, d


@nb.njit(cache=True, inline="always")
def unproject_pixel(col, row, d, W, H, sx, sy, ortho=False):
    """View-space point at depth ``d`` seen at screen position (col, row); §3.5.

    With ``ortho`` the lateral position does not scale with the depth.

    Parameters
    ----------
    col, row : float
        Continuous screen position in pixels (pixel centres at ``j + 0.5``, ``i + 0.5``).
    d : float
        View-space depth (distance along the view axis, > 0).
    W, H, sx, sy, ortho : int, int, float, float, bool
        The camera's :meth:`Camera.kernel_args` and :attr:`Camera.ortho`.

    Returns
    -------
    x, y, z : float
        View-space point, ``z = -d``.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §3.5 (unprojection of a pixel with a
       known view-space depth).
    """
    if ortho:
        return (col * (2.0 / W) - 1.0) * sx, (1.0 - row * (2.0 / H)) * sy, -d
    x = (col * (2.0 / W) - 1.0) * sx * d
    y = (1.0 - row * (2.0 / H)) * sy * d
    return x, y, -d
