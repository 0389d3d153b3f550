"""A restricted unpickler for ConceptGraphs' saved maps (``pcd_saves/*.pkl.gz``).

Only the globals those files contain are resolved: numpy array / dtype / scalar reconstruction,
builtin containers, ``pathlib`` paths (``color_path``), ``uuid.UUID`` (``ali-dev`` object ids),
``collections.OrderedDict`` and omegaconf's config classes (``main`` pickles the Hydra cfg).
Anything else -- ``os.system``, ``subprocess``, ``builtins.eval``, torch's rebuild hooks -- raises
:class:`UnsafePickleError` before any of it is called.
"""

from __future__ import annotations

import gzip
import importlib
import io
import pickle
import zlib
from pathlib import Path
from typing import Any

from sgbelief.errors import FormatError, SgbeliefError

_NUMPY = {
    ("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "scalar"),
    ("numpy.core.numeric", "_frombuffer"), ("numpy._core.numeric", "_frombuffer"),
    ("numpy", "ndarray"), ("numpy", "dtype"), ("numpy", "bool_"),
}
_BUILTINS = {"set", "frozenset", "complex", "bytearray", "slice", "range", "list", "dict", "tuple",
             "str", "int", "float", "bool", "bytes", "object", "NoneType"}
_OTHER = {
    ("pathlib", "PosixPath"), ("pathlib", "WindowsPath"), ("pathlib", "PurePosixPath"),
    ("pathlib", "PureWindowsPath"), ("pathlib", "Path"), ("pathlib._local", "PosixPath"),
    ("pathlib._local", "WindowsPath"), ("uuid", "UUID"), ("uuid", "SafeUUID"),
    ("collections", "OrderedDict"), ("collections", "defaultdict"), ("typing", "Any"),
}
_OMEGACONF_PREFIXES = ("omegaconf.dictconfig", "omegaconf.listconfig", "omegaconf.base", "omegaconf.nodes")


class UnsafePickleError(SgbeliefError, pickle.UnpicklingError):
    """The pickle references a global outside the allow-list."""


class _OpaqueConfig(dict):
    """Placeholder for an omegaconf object when omegaconf is not installed (state kept as a dict)."""

    def __setstate__(self, state: Any) -> None:
        self["__state__"] = state


class RestrictedUnpickler(pickle.Unpickler):
    """``pickle.Unpickler`` whose ``find_class`` only resolves allow-listed globals."""

    def find_class(self, module: str, name: str) -> Any:
        if (module == "builtins" and name in _BUILTINS) or (module, name) in _OTHER:
            return super().find_class(module, name)
        if (module, name) in _NUMPY or (module.startswith("numpy.dtypes") and name.endswith("DType")):
            return super().find_class(module, name)
        if module.startswith(_OMEGACONF_PREFIXES) and name.isidentifier() and not name.startswith("_"):
            try:
                mod = importlib.import_module(module)
            except ImportError:
                return _OpaqueConfig
            value = getattr(mod, name, None)
            if isinstance(value, type):
                return value
        raise UnsafePickleError(
            f"refusing to load global '{module}.{name}': a ConceptGraphs map only holds numpy arrays, "
            "builtin containers, paths, uuids and omegaconf configs; this pickle may run arbitrary code")


def restricted_loads(data: bytes) -> Any:
    """Unpickle bytes with :class:`RestrictedUnpickler`."""
    return RestrictedUnpickler(io.BytesIO(data)).load()


def load_cg_result(path: str | Path) -> Any:
    """Read a ConceptGraphs ``*.pkl.gz`` (or plain ``.pkl``) with the restricted unpickler."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    raw = path.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except EOFError as exc:  # a truncated download / a save killed half way
            raise FormatError(f"truncated gzip stream ({exc})", path=path) from None
        except (OSError, zlib.error) as exc:
            raise FormatError(f"corrupt gzip stream: {exc}", path=path) from None
    try:
        return restricted_loads(raw)
    except UnsafePickleError as exc:
        raise UnsafePickleError(f"{path}: {exc}") from None
    except EOFError:
        raise FormatError("truncated pickle (the stream ends before its STOP opcode)", path=path) from None
    except (RecursionError, MemoryError):
        raise FormatError("not a readable ConceptGraphs pickle: nested too deeply or too large", path=path) from None
    except Exception as exc:  # noqa: BLE001 - any reconstruction failure of an allow-listed global is bad input
        raise FormatError(f"not a readable ConceptGraphs pickle: {type(exc).__name__}: {exc}", path=path) from None
