"""The installer: capture ConceptGraphs' functions from its imported modules, build the
generation's replacements with those originals passed in, swap them in, and back.

ConceptGraphs' modules are imported when the run script has not imported them yet; when they cannot
be imported, :meth:`Patcher.install` raises :class:`ConceptGraphsNotFoundError` naming what is missing
(the backend is never active with nothing patched). The functions through which a run loads or
passes its class list (``create_or_load_colors``, ``gobs_to_detection_list`` on ``main``;
``ObjectClasses``, ``make_detection_list_from_pcd_and_gobs`` on ``ali-dev``) are wrapped so the
backend learns the class list the run uses (its default vocabulary)."""

from __future__ import annotations

import functools
import importlib
import inspect
import sys
from collections.abc import Callable
from types import ModuleType
from typing import TYPE_CHECKING, Any

from sgbelief.adapters.conceptgraphs.functions import GenerationFunctions, make_functions

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.adapters.conceptgraphs.map_beliefs import MapBeliefs

#: ConceptGraphs names the backend replaces, and the module that defines each one
PATCHED_NAMES: dict[str, str] = {
    "merge_obj2_into_obj1": "conceptgraph.slam.utils",
    "merge_overlap_objects": "conceptgraph.slam.utils",
    "merge_objects": "conceptgraph.slam.utils",
    "filter_objects": "conceptgraph.slam.utils",
    "merge_detections_to_objects": "conceptgraph.slam.mapping",
    "match_detections_to_objects": "conceptgraph.slam.mapping",
    "merge_obj_matches": "conceptgraph.slam.mapping",
}
#: helpers the replacements call through to when present (never patched)
HELPERS: dict[str, str] = {
    "compute_overlap_matrix": "conceptgraph.slam.utils",
    "compute_overlap_matrix_general": "conceptgraph.slam.utils",
    "tracker": "conceptgraph.slam.mapping",
}
CORE_MODULES = ("conceptgraph.slam.utils", "conceptgraph.slam.mapping", "conceptgraph.slam.slam_classes")
#: functions through which a run loads or passes its class list (wrapped, never replaced), by module
CLASS_LIST_FUNCTIONS: dict[str, str] = {
    "create_or_load_colors": "conceptgraph.slam.utils",  # main: returns (classes, colours)
    "gobs_to_detection_list": "conceptgraph.slam.utils",  # main: class_names=, BG_CLASSES=
    "make_detection_list_from_pcd_and_gobs": "conceptgraph.slam.utils",  # ali-dev: obj_classes
}
#: ali-dev's class-list holder (its constructor reads the classes file)
CLASS_LIST_CLASS = ("ObjectClasses", "conceptgraph.utils.general_utils")


class ConceptGraphsNotFoundError(ImportError):
    """ConceptGraphs' mapping modules cannot be found or imported: nothing could be patched."""


def _kwarg_tolerant(cls: type) -> type:
    """A subclass of a ConceptGraphs list class whose constructor ignores keyword arguments."""

    def __init__(self: Any, *args: Any, **_kwargs: Any) -> None:
        cls.__init__(self, *args)

    def __new__(klass: type, *args: Any, **_kwargs: Any) -> Any:
        return list.__new__(klass)

    return type(cls.__name__, (cls,), {"__init__": __init__, "__new__": __new__, "__module__": cls.__module__,
                                       "__qualname__": cls.__qualname__, "_sgbelief_kwarg_tolerant": True})


def is_replacement(value: Any) -> bool:
    """True for a function sgbelief swapped in (a method of a :class:`GenerationFunctions`)."""
    return isinstance(getattr(value, "__self__", None), GenerationFunctions) or bool(
        getattr(value, "_sgbelief_replacement", False))


def _as_list_method(fn: Callable[[Any], Any]) -> Callable[[Any], Any]:
    """``fn(objects)`` as a plain function, so it binds as a method of ConceptGraphs' list classes."""

    def get_most_common_class(self: Any) -> Any:
        return fn(self)

    get_most_common_class.__doc__ = fn.__doc__
    get_most_common_class._sgbelief_replacement = True  # type: ignore[attr-defined]
    return get_most_common_class


class Patcher:
    """Captures ConceptGraphs' originals, builds the replacement functions with them and swaps
    those in; records every (namespace, name, old value) it changes so :meth:`uninstall` restores them.

    ``backend`` is the belief bookkeeping the replacements route into; the Patcher never looks
    anything up on it beyond passing it to :func:`make_functions`.
    """

    def __init__(self, backend: MapBeliefs, *, extra_modules: tuple[Any, ...] = (),
                 generation: str | None = None, fix_list_kwargs: bool = True) -> None:
        self.backend = backend
        self.extra = [sys.modules[m] if isinstance(m, str) else m for m in extra_modules]
        self.fix_list_kwargs = fix_list_kwargs
        self.originals: dict[str, Any] = {}
        self._helpers: dict[str, Any] = {}
        self._records: list[tuple[Any, str, Any, bool]] = []  # (namespace, name, old, existed)
        self.generation = generation
        #: the replacement functions swapped in (built by :meth:`install`)
        self.functions: GenerationFunctions | None = None

    def _module(self, name: str) -> ModuleType | None:
        mod = sys.modules.get(name)
        if mod is not None:
            return mod
        short = name.rsplit(".", 1)[-1]
        for extra in self.extra:
            if getattr(extra, "__name__", "").endswith(short):
                return extra
        return None

    def helper(self, name: str) -> Any:
        return self._helpers.get(name)

    def _require_modules(self) -> None:
        """Import ConceptGraphs' core modules the run script has not imported yet; raise naming the
        ones that can be neither found nor imported."""
        missing: list[str] = []
        for modname in CORE_MODULES:
            if self._module(modname) is not None:
                continue
            try:
                importlib.import_module(modname)
            except ImportError as exc:
                missing.append(f"{modname} ({type(exc).__name__}: {exc})")
        if missing:
            raise ConceptGraphsNotFoundError(
                "ConceptGraphs' mapping modules cannot be imported, so nothing would be patched: "
                + "; ".join(missing) + ". Install concept-graphs (or put its checkout on sys.path) and call "
                "backend.install() after the run script's own imports")

    def install(self) -> None:
        self._require_modules()
        for name, modname in PATCHED_NAMES.items():
            mod = self._module(modname)
            value = getattr(mod, name, None) if mod is not None else None
            if value is None:
                for extra in self.extra:
                    value = extra.__dict__.get(name)
                    if value is not None:
                        break
            if value is not None and not is_replacement(value):
                self.originals[name] = value
        for name, modname in HELPERS.items():
            mod = self._module(modname)
            if mod is not None and name in mod.__dict__:
                self._helpers[name] = mod.__dict__[name]
        if not self.originals:
            raise ConceptGraphsNotFoundError(
                "none of ConceptGraphs' mapping functions (" + ", ".join(PATCHED_NAMES) + ") was found in "
                + ", ".join(CORE_MODULES) + ": nothing would be patched")
        if self.generation is None:
            self.generation = self._detect_generation()
        funcs = self.functions = make_functions(self.backend, self.generation, self.originals, self._helpers)
        replacements = funcs.replacements()
        for name, modname in CLASS_LIST_FUNCTIONS.items():  # class-list sources: wrapped
            mod = self._module(modname)
            value = getattr(mod, name, None) if mod is not None else None
            if callable(value) and not getattr(value, "_sgbelief_replacement", False):
                self.originals[name] = value
                replacements[name] = _class_list_wrapper(name, value, self.backend)
        # every namespace that bound an original (conceptgraph.* modules, run scripts, __main__)
        targets = list(self.extra)
        for modname, mod in list(sys.modules.items()):
            if mod is None or mod in targets:
                continue
            if modname.startswith("conceptgraph") or modname == "__main__":
                targets.append(mod)
            else:
                d = getattr(mod, "__dict__", None)
                if isinstance(d, dict) and any(d.get(n) is o for n, o in self.originals.items()):
                    targets.append(mod)
        for mod in targets:
            d = mod.__dict__
            for name, new in replacements.items():
                old = d.get(name)
                if old is not None and (old is self.originals.get(name)):
                    self._set(mod, name, new)
        holder_name, holder_mod = CLASS_LIST_CLASS
        mod = self._module(holder_mod) or sys.modules.get(holder_mod)
        holder = getattr(mod, holder_name, None) if mod is not None else None
        if isinstance(holder, type) and not getattr(holder.__init__, "_sgbelief_replacement", False):
            self._set(holder, "__init__", _class_holder_init(holder.__init__, self.backend))
        # labels out: DetectionList.get_most_common_class (MapObjectList inherits it)
        classes = self._list_classes(targets)
        for cls in classes.get("DetectionList", []):
            if "get_most_common_class" in cls.__dict__:
                self._set(cls, "get_most_common_class", _as_list_method(funcs.get_most_common_class))
        if self.fix_list_kwargs:
            for cname, found in classes.items():
                for cls in found:
                    if getattr(cls, "_sgbelief_kwarg_tolerant", False) or not _rejects_kwargs(cls):
                        continue
                    tolerant = _kwarg_tolerant(cls)
                    for mod in targets:
                        if mod.__dict__.get(cname) is cls:
                            self._set(mod, cname, tolerant)

    def _list_classes(self, targets: list[Any]) -> dict[str, list[type]]:
        out: dict[str, list[type]] = {"DetectionList": [], "MapObjectList": []}
        for mod in targets:
            for cname in out:
                cls = mod.__dict__.get(cname)
                if isinstance(cls, type) and issubclass(cls, list) and cls not in out[cname]:
                    out[cname].append(cls)
        return out

    def _detect_generation(self) -> str:
        orig = self.originals.get("merge_obj2_into_obj1")
        if orig is None:
            return "main"
        try:
            params = list(inspect.signature(orig).parameters)
        except (TypeError, ValueError):
            return "main"
        return "main" if params and params[0] == "cfg" else "ali-dev"

    def _set(self, namespace: Any, name: str, value: Any) -> None:
        existed = name in namespace.__dict__
        self._records.append((namespace, name, namespace.__dict__.get(name), existed))
        setattr(namespace, name, value)

    def uninstall(self) -> None:
        while self._records:
            namespace, name, old, existed = self._records.pop()
            if existed:
                setattr(namespace, name, old)
            else:
                try:
                    delattr(namespace, name)
                except AttributeError:
                    pass
        self.originals.clear()
        self._helpers.clear()


def _learn(backend: Any, classes: Any, background: Any, source: str) -> None:
    learn = getattr(backend, "learn_class_list", None)
    if learn is None or classes is None or isinstance(classes, (str, bytes)):
        return
    try:
        names = [str(c) for c in classes]
    except TypeError:
        return
    learn(names, background=[str(b) for b in background or ()], source=source)


def _class_list_wrapper(name: str, original: Callable[..., Any], backend: Any) -> Callable[..., Any]:
    """``original`` unchanged, except that the class list it loads or receives is handed to the
    backend (until the backend has one: afterwards one attribute read per call)."""
    try:
        sig: inspect.Signature | None = inspect.signature(original)
    except (TypeError, ValueError):
        sig = None

    @functools.wraps(original)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        out = original(*args, **kwargs)
        if not backend.class_list_known:
            try:
                if name == "create_or_load_colors":
                    _learn(backend, out[0] if isinstance(out, tuple) else None, (), name)
                elif sig is not None:
                    bound = sig.bind_partial(*args, **kwargs).arguments
                    if name == "gobs_to_detection_list":
                        _learn(backend, bound.get("class_names"), bound.get("BG_CLASSES"), name)
                    else:
                        holder = bound.get("obj_classes")
                        if holder is not None and hasattr(holder, "get_classes_arr"):
                            bg = holder.get_bg_classes_arr() if hasattr(holder, "get_bg_classes_arr") else ()
                            _learn(backend, holder.get_classes_arr(), bg, name)
            except TypeError:
                pass
        return out

    wrapper._sgbelief_replacement = True  # type: ignore[attr-defined]
    return wrapper


def _class_holder_init(original: Callable[..., Any], backend: Any) -> Callable[..., Any]:
    """``ObjectClasses.__init__``, then the class list it read handed to the backend."""

    @functools.wraps(original)
    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        original(self, *args, **kwargs)
        if not backend.class_list_known and hasattr(self, "get_classes_arr"):
            bg = self.get_bg_classes_arr() if hasattr(self, "get_bg_classes_arr") else ()
            _learn(backend, self.get_classes_arr(), bg, "ObjectClasses")

    __init__._sgbelief_replacement = True  # type: ignore[attr-defined]
    return __init__


def _rejects_kwargs(cls: type) -> bool:
    try:
        cls(device="cpu")
    except TypeError:
        return True
    except Exception:  # noqa: BLE001
        return False
    return False
