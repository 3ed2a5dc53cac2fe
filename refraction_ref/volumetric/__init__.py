"""Volumetric relighting of refractive objects (Sun et al. 2008), one module per pass.

=========================  ==============================================  ===========
stage (``timings_ms``)     pass (module)                                   section
=========================  ==============================================  ===========
``voxelize``               solid voxelization, coverage -> IOR, blur        §4.1
                           (:mod:`.voxelize`)
``gradient``               central differences of n (:mod:`.gradient`)      §3, eq. 3
``octree``                 min/max pyramid, leaf levels, max steps          §4.2, §5.3
                           (:mod:`.octree`)
``photons``                one photon per light texel covered by the        §4.3
                           proxy geometry (:mod:`.photons`)
``receivers``              diffuse receivers the photons stop on (only      Fig. 9
                           with lights and receivers; :mod:`.receivers`)
``march``                  adaptive marching (:mod:`.march`), deposition    §4.4, eqs 4-6
                           (:mod:`.deposit`), eq. 6 (:mod:`.extinction`)
``smooth``                 3x3x3 smoothing of the radiance (:mod:`.smooth`) §4.4
``view``                   curved viewing rays, HG phase (:mod:`.view`)     §4.5
``caustics``               receivers' caustic maps (only with receivers)    Fig. 9
=========================  ==============================================  ===========

The knobs are declared once in :mod:`.knobs`, which builds the typed values
the passes take (:class:`~.knobs.MarchKnobs`, :class:`~.knobs.ViewKnobs`);
:mod:`.grid` places the voxel grid and samples n and its gradient there,
:mod:`.integrate` steps eqs. 4-5 (or RK4) for photons and viewing rays alike.

:func:`render_volumetric` in :mod:`.pipeline` puts the passes together;
:class:`refraction_ref.session.Session` caches them between renders.

Importing this package is cheap: the passes are imported on first use.
"""

__all__ = ["render_volumetric"]


def __getattr__(name):  # lazy: scene loading imports .knobs without the kernels
    if name == "render_volumetric":
        from .pipeline import render_volumetric

        return render_volumetric
    raise AttributeError(name)
