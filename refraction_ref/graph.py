"""Methods as registered graphs of stages, knob blocks owned by the code that reads them.

Every method (``imagespace``, ``exact``, ``levelmap``, ``volumetric``) is a
:class:`Method`: an ordered tuple of :class:`Stage` s, each declaring the
scene keys and knobs it ``reads``, the upstream stages whose buffers it uses
(``after``) and the buffers it ``makes``. :func:`run_graph` runs the graph
with a cache: a stage re-runs when a key it reads changed or an upstream
stage re-ran, and is reused otherwise. ``render`` is the graph run with an
empty cache, :class:`~refraction_ref.session.Session` keeps one between
renders. ``meta["plan"]`` records, per stage, whether it ran or was reused
and why; ``keep`` returns the stages' buffers as ``stage.<stage>.<buffer>``.

A stage sees only what it declares: its ``ctx.scene`` is the scene
*projected* onto its ``reads`` (every other key raises
:class:`UndeclaredRead`), so a stage cannot silently depend on a knob that
is missing from its cache key.

Knob blocks (``imagespace``, ``exact``, ``volumetric``, ``volume``,
``levelmap``, ``water``) are :class:`KnobBlock` s registered by the
method's ``knobs`` module, which holds the defaults (the seed's own
settings) and the validation beside each other; each key has exactly one
owning block. A key that moves keeps its old name as an alias
(``KnobBlock.aliases``).

Anchors: Mitsuba 3 registers plugins by name, each reading its own
parameter block; build systems (make, Dask graphs) key work on its inputs.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import importlib
import json
import os
import time
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import numpy as np

from .validation import SceneError

__all__ = ["Stage", "Method", "KnobBlock", "Context", "UndeclaredRead", "register_method", "register_block",
           "get_method", "method_names", "BLOCKS", "Builtin",
           "load_builtin_blocks", "load_builtin_methods", "method_blocks", "run_graph", "run_stages", "execute_stage", "method_renderer",
           "stage_inputs", "STAGE_PREFIX",
           "describe", "file_stamp"]

#: prefix of kept stage buffers in a result's arrays: ``stage.<stage>.<buffer>``
STAGE_PREFIX = "stage."


class UndeclaredRead(KeyError):
    """A stage read a scene key it does not declare in ``Stage.reads`` (a bug of the stage)."""

    def __str__(self):
        return str(self.args[0])


@dataclass(frozen=True)
class KnobBlock:
    """A method's parameter block: defaults, validation, documentation.

    Attributes
    ----------
    name : str
        Top-level scene key (``"imagespace"``).
    defaults : dict or None
        The seed's own settings; ``None`` for a block that is absent unless
        given (``water``, ``volume``).
    validate : callable
        ``validate(data, base_dir)``: checks the block inside the merged
        scene, raising :class:`~refraction_ref.scene.SceneError` naming the key.
    owner : str
        The method that reads it (documentation; ``docs/oracle.md``).
    aliases : dict
        Old key name -> new key name, for keys that moved.
    merge : callable or None
        ``merge(data)``: fill a block that is given (``water``) with its
        defaults while the scene is resolved; None for plain blocks.
    knobs : tuple of Knob
        The block's declarations (:mod:`refraction_ref.knobs`), from which
        its defaults, checks and table are derived.
    """

    name: str
    defaults: dict | None
    validate: Callable
    owner: str
    aliases: dict = field(default_factory=dict)
    merge: Callable | None = None
    knobs: tuple = ()


@dataclass(frozen=True)
class Stage:
    """One pass of a method.

    Attributes
    ----------
    name : str
        Unique within its method; the key in ``timings_ms`` and ``plan``.
    run : callable
        ``run(ctx) -> dict`` of named buffers (arrays or Python objects).
    reads : tuple of str
        Dotted scene keys it depends on (``"camera"``, ``"imagespace.layers"``,
        ``"objects"``); a change to any re-runs it.
    after : tuple of str
        Upstream stages whose buffers it reads (``ctx.buf[name]``).
    makes : tuple of str
        Buffer names it returns; the arrays among them can be kept.
    doc : str
        One line: what the pass does and the paper's section.
    diagnostic : bool
        A stage that makes buffers for inspection only (e.g. per-layer
        normal maps the trace computes on the fly): it runs only when kept.
    """

    name: str
    run: Callable
    reads: tuple = ()
    after: tuple = ()
    makes: tuple = ()
    doc: str = ""
    diagnostic: bool = False


@dataclass(frozen=True)
class Method:
    """A registered method.

    Attributes
    ----------
    name : str
    blocks : tuple of str
        The knob blocks it owns.
    stages : callable
        ``stages(scene) -> tuple of Stage`` in execution order: the graph
        for this scene (e.g. caustic stages only when the scene has lights
        and receivers); each stage's ``after`` names stages earlier in it.
    assemble : callable
        ``assemble(scene, buffers, stats) -> (arrays, info)``: the output
        keys of ``docs/oracle.md`` from the stages' buffers.
    skipped : callable
        ``skipped(scene) -> list of {stage, ran: False, why}`` for stages the
        scene does not need (said in ``meta.plan``).
    warm : callable or None
        ``warm(scene=None)``: compile the kernels this scene's plan needs on
        a tiny copy of it (once per process and plan), so that ``timings_ms``
        measure run time, not JIT time. Every built-in method registers
        ``warm=refraction_ref.warm.warmer(name)``, the one warm-up, which
        shrinks the scene by :attr:`tiny`.
    check : callable or None
        ``check(scene)``: the method's preconditions on a loaded scene
        (e.g. the memory its buffers need), raising
        :class:`~refraction_ref.scene.SceneError` before any stage runs.
    results : tuple of str
        What ``assemble`` reads: ``"stage"`` (all its buffers) or
        ``"stage.buffer"``. A render without a session frees every other
        buffer once the last stage that reads it has run, so later stages
        reuse that memory (fresh pages cost several times a write here).
    doc : str
        One line: the paper and what the method does (``refraction-ref
        render --help``).
    label : str
        A few words naming the method's source (``"Chaudhari 2008"``), for
        the command line's method lists.
    params : callable or None
        ``params(scene) -> tuple of str``: the knob blocks whose values
        ``meta["params"]`` holds for this scene (e.g. the exact reference's
        water blocks on a water scene); None for :attr:`blocks`.
    tiny : callable or None
        ``tiny(scene) -> dict`` of dotted overrides that shrink ``scene`` to
        a warm-up size without changing which kernels run or their argument
        types (:func:`refraction_ref.warm.tiny_scene`).
    default_scene : str or None
        The scene :func:`refraction_ref.warm.warm` warms when given none
        (a path; None for the bundled default scene).
    """

    name: str
    blocks: tuple
    stages: Callable
    assemble: Callable
    skipped: Callable = lambda scene: []
    warm: Callable | None = None
    check: Callable | None = None
    results: tuple = ()
    doc: str = ""
    label: str = ""
    params: Callable | None = None
    tiny: Callable | None = None
    default_scene: str | None = None

    def param_blocks(self, scene):
        """The knob blocks whose values ``meta["params"]`` holds for ``scene``.

        Parameters
        ----------
        scene : Scene
            A validated scene.

        Returns
        -------
        tuple of str
            :attr:`params` ``(scene)``, or :attr:`blocks` when the method gives no ``params``.
        """
        return tuple(self.params(scene)) if self.params is not None else tuple(self.blocks)


BLOCKS: dict = {}
_METHODS: dict = {}


class Builtin(NamedTuple):
    """Where a built-in package registers itself: its knob blocks' module and its method's module."""

    knobs: str  #: registers the package's :class:`KnobBlock` s on import (cheap: no kernels)
    method: str | None  #: registers its :class:`Method` on import (the kernels); None for a service without one


#: The built-in packages, one row each, in the order their blocks are registered. The scene loader imports
#: only the ``knobs`` modules (:func:`load_builtin_blocks`), so it imports no method; :func:`get_method`
#: imports a ``method`` module on first use.
_BUILTIN = {
    "imagespace": Builtin("refraction_ref.imagespace.knobs", "refraction_ref.imagespace.pipeline"),
    "exact": Builtin("refraction_ref.exact.knobs", "refraction_ref.exact.pipeline"),
    "levelmap": Builtin("refraction_ref.levelmap.knobs", "refraction_ref.levelmap.pipeline"),
    "volumetric": Builtin("refraction_ref.volumetric.knobs", "refraction_ref.volumetric.pipeline"),
    "caustics": Builtin("refraction_ref.caustics.knobs", None),
}


def load_builtin_blocks():
    """Import the built-in knob blocks' modules (cheap: no kernels); returns :data:`BLOCKS`.

    Returns
    -------
    dict
        Block name -> :class:`KnobBlock`, every built-in block registered.
    """
    for row in _BUILTIN.values():
        importlib.import_module(row.knobs)
    return BLOCKS


def load_builtin_methods():
    """Import every built-in method's module (the kernels: slow on a first run); returns the methods.

    Returns
    -------
    dict
        Method name -> :class:`Method`, every built-in and registered method, in :func:`method_names`'s order.
    """
    return {name: get_method(name) for name in method_names()}


def method_blocks():
    """Names of the knob blocks of the methods and services: what may differ between two runs of one scene.

    Every registered :class:`KnobBlock` with defaults (``imagespace``,
    ``exact``, ``levelmap``, ``volumetric``, a service's such as
    ``caustics``); the blocks with no defaults (``water``, ``volume``) are
    the scene's own inputs, present only when given. Cheap: imports the
    knob modules only.

    Returns
    -------
    tuple of str
        Block names, in registration order.
    """
    return tuple(name for name, blk in load_builtin_blocks().items() if blk.defaults is not None)


def register_block(block):
    """Register a :class:`KnobBlock`.

    Parameters
    ----------
    block : KnobBlock

    Returns
    -------
    KnobBlock
        ``block``, so that a knobs module can write ``X = register_block(KnobBlock(...))``.
    """
    BLOCKS[block.name] = block
    return block


def register_method(method):
    """Register a :class:`Method` by name.

    Parameters
    ----------
    method : Method

    Returns
    -------
    Method
        ``method``, so that a pipeline can write ``METHOD = register_method(Method(...))``.
    """
    _METHODS[method.name] = method
    return method


def method_names():
    """Names of the built-in and registered methods (importing none).

    Returns
    -------
    tuple of str
        The built-in methods in :data:`_BUILTIN`'s order, then any other registered one.
    """
    return tuple(dict.fromkeys([*(n for n, row in _BUILTIN.items() if row.method), *_METHODS]))


def get_method(name):
    """The registered :class:`Method` called ``name`` (importing a built-in one on first use).

    Parameters
    ----------
    name : str

    Returns
    -------
    Method

    Raises
    ------
    SceneError
        For a name no method has, listing the names there are.
    """
    if name not in _METHODS and name in _BUILTIN and _BUILTIN[name].method:
        importlib.import_module(_BUILTIN[name].method)
    if name not in _METHODS:
        raise SceneError(f"unknown method {name!r}; choose one of {', '.join(method_names())}")
    return _METHODS[name]


# --------------------------------------------------------------------- projection
class _Projected(dict):
    """A dict holding only a stage's declared keys; any other key is an :class:`UndeclaredRead`."""

    __slots__ = ("_where", "_stage")

    def __missing__(self, key):
        raise UndeclaredRead(f"stage '{self._stage}' read '{self._where}{key}', which it does not declare "
                             "in Stage.reads: add it there (or it would reuse a stale result)")

    def get(self, key, default=None):
        if key in self:
            return dict.__getitem__(self, key)
        return self.__missing__(key)


def _proj(stage, where, d):
    p = _Projected(d)
    p._where = where
    p._stage = stage
    return p


def _project(data, reads, stage):
    out = _proj(stage, "", {})
    for key in reads:
        parts = key.split(".")
        src, dst, where = data, out, ""
        for depth, part in enumerate(parts):
            if not isinstance(src, dict) or part not in src:
                raise KeyError(f"stage '{stage}' declares '{key}', which the scene does not have")
            if depth == len(parts) - 1 or src[part] is None or not isinstance(src[part], dict):
                dict.__setitem__(dst, part, src[part])
                break
            where += part + "."
            if not isinstance(dst.get(part) if part in dst else None, _Projected):
                dict.__setitem__(dst, part, _proj(stage, where, {}))
            src, dst = src[part], dict.__getitem__(dst, part)
    return out


# --------------------------------------------------------------------- cache keys
def _lookup(data, key):
    node = data
    for part in key.split("."):
        node = node[part]
    return node


def describe(x, base_dir="."):
    """JSON-able stand-in of a scene value: arrays by hash, files by stat, callables by identity.

    Parameters
    ----------
    x : object
        A scene value (nested dicts and lists are described item by item).
    base_dir : str
        Where relative file names resolve.

    Returns
    -------
    object
        JSON-able: equal for equal inputs, different when an array's bytes
        or a file's stat differ.
    """
    if isinstance(x, str) and os.path.splitext(x)[1] and os.path.isfile(os.path.join(base_dir, x)):
        return file_stamp(os.path.normpath(os.path.join(base_dir, x)))
    if isinstance(x, np.ndarray):
        a = np.ascontiguousarray(x)
        return {"array": list(a.shape), "dtype": str(a.dtype), "sha1": hashlib.sha1(a.view(np.uint8)).hexdigest()}
    if isinstance(x, dict):
        return {str(k): describe(v, base_dir) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [describe(v, base_dir) for v in x]
    if callable(x):
        return f"<callable {id(x)}>"
    if isinstance(x, np.generic):
        return x.item()
    return x


def stage_inputs(scene, stage):
    """The values a stage's cache key is made of: ``{key: value}`` over its ``reads``.

    Parameters
    ----------
    scene : Scene
    stage : Stage

    Returns
    -------
    dict
        Dotted key -> :func:`describe` d value (JSON round-tripped).
    """
    out = {}
    for key in stage.reads:
        v = describe(_lookup(scene.data, key), scene.base_dir)
        if key == "objects" or key.startswith("objects."):
            v = copy.deepcopy(v)
            for (kind, k), fn in scene.callables.items():
                if kind == "deform" and isinstance(v, list) and k < len(v):
                    v[k]["deform"] = f"<callable {id(fn)}>"
        out[key] = v
    return json.loads(json.dumps(out, sort_keys=True, default=str))


def _diff(old, new, prefix=""):
    """Dotted names of the entries that differ between two JSON-like values."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for k in sorted(set(old) | set(new)):
            name = f"{prefix}.{k}" if prefix else str(k)
            out += [name] if (k not in old or k not in new) else _diff(old[k], new[k], name)
        return out
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        out = []
        for k, (a, b) in enumerate(zip(old, new)):
            out += _diff(a, b, f"{prefix}.{k}" if prefix else str(k))
        return out
    return [] if old == new else [prefix or "(all)"]


# --------------------------------------------------------------------- running
class Context:
    """What a stage's ``run`` receives.

    Attributes
    ----------
    scene : Scene
        The scene projected onto the stage's ``reads`` (``base_dir`` and the
        Python callables of the objects are kept).
    buf : dict
        ``{upstream stage: its buffers}`` for the stages in ``after``.
    notes : list of str
        Appended to the stage's ``plan`` entry.
    stats : dict
        Statistics for ``meta`` (kept with the cached buffers, so a reused
        stage reports them too).
    timings : dict
        Sub-stage times in ms (``timings_ms["<stage>.<part>"]``), optional.
    progress : bool
    """

    def __init__(self, scene, buf, progress=False):
        self.scene = scene
        self.buf = buf
        self.notes = []
        self.stats = {}
        self.timings = {}
        self.progress = progress
        #: False when the stage found nothing to do (its ``plan`` row then says ``ran: false`` and why)
        self.ran = True

    def note(self, text):
        """Add a remark to the stage's ``plan`` entry.

        Parameters
        ----------
        text : str
        """
        self.notes.append(text)


def _scene_view(scene, stage):
    return dataclasses.replace(scene, data=_project(scene.data, stage.reads, stage.name))


def _keep_names(method_name, stages, keep):
    """The stage names whose buffers to keep; a bad name raises naming it."""
    if not keep:
        return set()
    names = [s.name for s in stages]
    if keep in ("stages", "all", True):
        return set(names)
    asked = [k.strip() for k in (keep.split(",") if isinstance(keep, str) else keep) if k.strip()]
    bad = [k for k in asked if k not in names]
    if bad:
        raise SceneError(f"keep: unknown stage {', '.join(repr(b) for b in bad)} for the {method_name} method "
                         f"on this scene; its stages are {', '.join(names)} (or 'stages' for all)")
    return set(asked)


def execute_stage(stage, ctx, timings):
    """Run one stage: time it, record its parts' times and check that it made its buffers.

    What :func:`run_graph` and :func:`run_stages` share, so that a pass
    sequence inside a stage is timed and checked as the method's own stages are.

    Parameters
    ----------
    stage : Stage
    ctx : Context
    timings : dict
        Gets ``timings[stage.name]`` (ms) and ``timings["<stage>.<part>"]``
        for the parts the stage timed (``ctx.timings``).

    Returns
    -------
    dict
        The stage's buffers.
    """
    t0 = time.perf_counter()
    out = stage.run(ctx)
    timings[stage.name] = (time.perf_counter() - t0) * 1e3
    for k, v in ctx.timings.items():
        timings[f"{stage.name}.{k}"] = v
    missing = [m for m in stage.makes if m not in out]
    if missing:
        raise RuntimeError(f"stage '{stage.name}' did not make {missing}")
    return out


def run_stages(stages, inputs, scene=None, timings=None, plan=None, progress=False):
    """Run a sequence of passes in order, each on the buffers of the ones it names in ``after``.

    The graph runner for a pass sequence that runs inside one stage on
    buffers rather than on the scene: the image-space passes in a light's
    view (the photon pass of Chaudhari 2008 §4.1), the level map's
    preparation. Each pass is a :class:`Stage`, timed and checked by
    :func:`execute_stage` as :func:`run_graph` does, and adds one ``plan``
    row: ``ran`` is the pass's ``ctx.ran``, ``why`` its notes (its ``doc``
    when it made none).

    Parameters
    ----------
    stages : sequence of Stage
        In the order they run; ``after`` may name ``"input"`` (``inputs``)
        or an earlier stage.
    inputs : dict
        The sequence's input buffers, ``ctx.buf["input"]``.
    scene : Scene, optional
        Projected onto each pass's ``reads`` (a pass reading an undeclared
        key raises :class:`UndeclaredRead`); None for passes that read
        buffers only.
    timings, plan : dict, list, optional
        Filled with each pass's time (ms) and plan row.
    progress : bool

    Returns
    -------
    dict
        ``{stage name: its buffers}``, ``"input"`` included.
    """
    timings = {} if timings is None else timings
    plan = [] if plan is None else plan
    bufs = {"input": inputs}
    for st in stages:
        view = None if scene is None else _scene_view(scene, st)
        ctx = Context(view, {u: bufs[u] for u in st.after}, progress)
        bufs[st.name] = execute_stage(st, ctx, timings)
        plan.append({"stage": st.name, "ran": ctx.ran, "why": "; ".join(ctx.notes) if ctx.notes else st.doc})
    return bufs


def method_renderer(method, name, summary):
    """A method's ``render_<method>(scene, *, cache, keep, warm, progress)``: a thin alias of :func:`run_graph`.

    Every method's render function is this one function bound to its
    method, with one shared docstring (its first line ``summary``).

    Parameters
    ----------
    method : Method or str
        The method it runs (a name is looked up on each call).
    name : str
        The function's name (``"render_imagespace"``).
    summary : str
        Its docstring's first line.

    Returns
    -------
    callable
    """

    def render_method(scene, *, cache=None, keep=None, warm=True, progress=False):
        return run_graph(method, scene, cache=cache, keep=keep, progress=progress, warm=warm)

    render_method.__name__ = render_method.__qualname__ = name
    render_method.__doc__ = summary + _RENDER_DOC
    return render_method


_RENDER_DOC = """

    Parameters
    ----------
    scene : Scene
        Validated (:func:`~refraction_ref.scene.load_scene`).
    cache : dict, optional
        Stage cache shared between renders (:func:`~refraction_ref.graph.run_graph`).
    keep : str or sequence of str, optional
        Stage buffers to return as ``stage.<stage>.<buffer>`` (``"stages"``: all).
    warm : bool, default True
        Compile (or load) the kernels on a tiny copy of the scene first, so
        that ``timings_ms`` exclude JIT time.
    progress : bool, default False
        Show progress bars.

    Returns
    -------
    arrays, info : dict, dict
        The output keys of ``docs/oracle.md`` (Outputs) and ``meta``'s
        ``timings_ms``, ``plan``, ``stats``.
    """


def run_graph(method, scene, cache=None, keep=None, progress=False, warm=True):
    """Run a method's stage graph on a scene, reusing cached stages whose inputs did not change.

    Parameters
    ----------
    method : Method or str
    scene : Scene
        Validated.
    cache : dict, optional
        ``{(method, stage): {"inputs", "out", "notes", "stats"}}``, updated in place.
    keep : None, 'stages', str or list of str
        Stage names whose array buffers are added as ``stage.<stage>.<buffer>``.
    progress : bool
    warm : bool
        Compile the method's kernels first (``Method.warm``).

    Returns
    -------
    arrays : dict
    info : dict
        ``timings_ms`` (one entry per stage that ran, ms), ``plan``
        (ran or reused, and why, per stage), ``stats`` and the method's own
        statistics.
    """
    if isinstance(method, str):
        method = get_method(method)
    ephemeral = cache is None  # nothing outlives this call: free buffers after their last reader
    if ephemeral:
        cache = {}
    if method.check is not None:
        method.check(scene)
    stages = tuple(method.stages(scene))
    kept = _keep_names(method.name, stages, keep)
    active = [st for st in stages if not st.diagnostic or st.name in kept]
    last_reader = {u: st.name for st in active for u in st.after}
    if warm and method.warm is not None:
        method.warm(scene)  # the kernels this scene's plan needs, on a tiny copy of it
    timings, plan, stats = {}, [], {}
    bufs, ran = {}, {}
    for st in stages:
        if st.diagnostic and st.name not in kept:
            plan.append({"stage": st.name, "ran": False,
                         "why": f"inspection buffers only: runs when kept (keep='{st.name}')"})
            continue
        inputs = None if ephemeral else stage_inputs(scene, st)  # nothing to compare against
        ck = (method.name, st.name)
        prev = cache.get(ck)
        up_ran = [u for u in st.after if ran.get(u)]
        if prev is not None and prev["inputs"] == inputs and not up_ran:
            bufs[st.name] = prev["out"]
            ran[st.name] = False
            stats.update(prev["stats"])
            plan.append({"stage": st.name, "ran": False,
                         "why": "reused: its inputs and upstream stages are unchanged"})
            continue
        if prev is None:
            why = "no earlier result"
        else:
            changed = _diff(prev["inputs"], inputs)
            why = ("changed: " + ", ".join(changed[:6]) + (" ..." if len(changed) > 6 else "")) if changed else ""
            if up_ran:
                why = (why + "; " if why else "") + "upstream re-ran: " + ", ".join(up_ran)
        ctx = Context(_scene_view(scene, st), {u: bufs[u] for u in st.after}, progress)
        out = execute_stage(st, ctx, timings)
        if not ephemeral:
            cache[ck] = {"inputs": inputs, "out": out, "stats": dict(ctx.stats)}
        bufs[st.name] = out
        ran[st.name] = True
        stats.update(ctx.stats)
        parts = [] if (why == "no earlier result" and ctx.notes) else [why]
        text = " | ".join(parts + (["; ".join(ctx.notes)] if ctx.notes else []))
        plan.append({"stage": st.name, "ran": ctx.ran, "why": text})
        if ephemeral:
            for u in st.after:
                if last_reader.get(u) == st.name and u not in kept:
                    bufs[u] = _results_only(bufs[u], u, method.results)
    for s in method.skipped(scene):
        plan.append(s)
    arrays, info = method.assemble(scene, bufs, stats)
    for name in kept:
        for b in next(s for s in stages if s.name == name).makes:
            v = bufs[name].get(b)
            if isinstance(v, np.ndarray) and (v.size <= 1 or 0 not in v.strides):  # not a broadcast placeholder
                arrays[f"{STAGE_PREFIX}{name}.{b}"] = v
    info = dict(info)
    info["timings_ms"] = timings
    info["plan"] = plan
    info["stages"] = [s.name for s in stages]
    read = {r.split(".")[0] for st in stages for r in st.reads} & set(BLOCKS)
    info["params_read"] = {b: scene.data[b] for b in sorted(read)}  # every knob block a stage read
    return arrays, info


def _results_only(buffers, stage, results):
    """The buffers of ``stage`` that ``assemble`` reads (``Method.results``); the rest is dropped."""
    if stage in results:
        return buffers
    keep = {r.split(".", 1)[1] for r in results if r.startswith(stage + ".")}
    return {k: v for k, v in buffers.items() if k in keep}


def file_stamp(path):
    """``{path, mtime, size}`` of a file, for cache keys of stages that read it.

    Parameters
    ----------
    path : str

    Returns
    -------
    dict
        ``mtime`` and ``size`` None for a file that does not exist.
    """
    st = os.stat(path) if os.path.exists(path) else None
    return {"path": path, "mtime": st.st_mtime if st else None, "size": st.st_size if st else None}
