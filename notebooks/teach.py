"""Small helpers the teaching notebooks share (imported from the notebooks' folder).

:func:`sliders` gives a cell interactive controls when ``ipywidgets`` is
installed (``pip install refraction_ref[notebooks]``) and a person is reading;
otherwise (no ipywidgets, or ``notebooks/build.py`` storing outputs, which sets
:data:`STATIC_ENV`) it calls the function once at the controls' first values,
so the stored notebook shows a plain figure, never a widget's repr.
"""

from __future__ import annotations

import os

#: set by ``notebooks/build.py`` while it executes a notebook: store figures, not widgets
STATIC_ENV = "REFRACTION_REF_NOTEBOOK_STATIC"


def widgets_available():
    """True when ipywidgets imports and the notebook is not being built (:data:`STATIC_ENV`)."""
    if os.environ.get(STATIC_ENV):
        return False
    try:
        import ipywidgets  # noqa: F401
    except ImportError:
        return False
    return True


def sliders(fn, **controls):
    """Call ``fn(**values)`` under sliders and drop-downs, or once at the first values without ipywidgets.

    Parameters
    ----------
    fn : callable
        Draws (and prints) for one setting of its keyword arguments.
    **controls
        Per argument either ``(default, lo, hi, step)`` for a number (a slider) or a list of choices
        (a drop-down; its first item is the default).

    Returns
    -------
    bool
        True when sliders are shown, False when ``fn`` ran once with the defaults.
    """
    defaults = {k: (c[0] if isinstance(c, tuple) else list(c)[0]) for k, c in controls.items()}
    if not widgets_available():
        fn(**defaults)
        print("(static: the defaults " + ", ".join(f"{k} = {v!r}" for k, v in defaults.items())
              + "; with `pip install refraction_ref[notebooks]` this cell shows sliders)")
        return False
    import ipywidgets as W
    from IPython.display import display

    made = {}
    for k, c in controls.items():
        if isinstance(c, tuple):
            d, lo, hi, step = c
            cls = W.IntSlider if all(isinstance(x, int) for x in c) else W.FloatSlider
            made[k] = cls(value=d, min=lo, max=hi, step=step, description=k, continuous_update=False)
        else:
            made[k] = W.Dropdown(options=list(c), value=defaults[k], description=k)
    out = W.interactive_output(fn, made)
    display(W.VBox([W.HBox(list(made.values())), out]))
    return True
