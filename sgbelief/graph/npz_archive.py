"""The container of the binary scene-graph layout (``sgbelief.scene_graph.npz``): one uncompressed
``.npz`` archive of typed numpy arrays, written and read with every array checked.

Reading never unpickles (``np.load(..., allow_pickle=False)``) and checks, before any array's bytes
are read, that its dtype and shape are the ones the header implies and that its zip member is
stored uncompressed and fits the file (:class:`NpzArchive`). What the arrays hold is
:mod:`sgbelief.graph.npz_columns` (values and attribute dicts), :mod:`sgbelief.graph.npz_provenance`
(the provenance store) and :mod:`sgbelief.graph.binary` (the graph and its header).
"""

from __future__ import annotations

import gc
import math
import os
import zipfile
import zlib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from sgbelief.errors import FormatError

FORMAT = "sgbelief.scene_graph.npz"
VERSION = 1

#: the dtypes of the layout (little-endian, fixed width)
F8 = np.dtype("<f8")
I8 = np.dtype("<i8")
I4 = np.dtype("<i4")
I1 = np.dtype("|i1")
U1 = np.dtype("|u1")
B1 = np.dtype("|b1")
#: rows per pass when walking millions of Python objects: the later passes over a chunk hit the cache
CHUNK = 8192


def write_npz(fh: BinaryIO, arrays: Mapping[str, np.ndarray]) -> None:
    """Write the arrays as an uncompressed ``.npz`` (what ``np.savez`` writes, without its
    per-chunk copies)."""
    with zipfile.ZipFile(fh, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name, arr in arrays.items():
            arr = np.ascontiguousarray(arr)
            with zf.open(name + ".npy", mode="w", force_zip64=True) as member:
                np.lib.format.write_array_header_1_0(member, np.lib.format.header_data_from_array_1_0(arr))
                if arr.size:
                    member.write(memoryview(arr).cast("B"))


@contextmanager
def open_npz(path: Path) -> Iterator[NpzArchive]:
    """The checked archive of an ``.npz`` file; FormatError when it is not one."""
    if not path.exists():
        raise FileNotFoundError(f"no saved scene graph at {path}")
    try:
        npz = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise FormatError(f"not an .npz archive (truncated or another format): {exc}", path=path) from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise FormatError("a single .npy array, not an .npz scene graph archive", path=path)
    with npz:
        yield NpzArchive(npz, path)


class NpzArchive:
    """Checked access to the arrays of an open ``NpzFile``: dtype, shape and member size are
    validated from the ``.npy`` header before the data is read (so a hostile header cannot make
    the reader allocate more than the file holds)."""

    def __init__(self, npz: Any, source: Path) -> None:
        self.npz = npz
        self.source = source
        self.size = os.path.getsize(source)
        self.names = set(npz.files)
        self.used: set[str] = set()

    def error(self, message: str) -> FormatError:
        return FormatError(message, path=self.source)

    def has(self, name: str) -> bool:
        return name in self.names

    def read(self, name: str, dtype: np.dtype, shape: tuple[int | None, ...]) -> np.ndarray:
        if name not in self.names:
            raise self.error(f"missing array '{name}'")
        self.used.add(name)
        try:
            info = self.npz.zip.getinfo(name + ".npy")
            if info.compress_type != zipfile.ZIP_STORED or info.compress_size != info.file_size \
                    or info.header_offset + info.file_size > self.size:
                raise self.error(f"array '{name}': zip member must be stored uncompressed inside the file")
            with self.npz.zip.open(info) as fp:
                version = np.lib.format.read_magic(fp)
                if version == (1, 0):
                    a_shape, fortran, a_dtype = np.lib.format.read_array_header_1_0(fp)
                elif version == (2, 0):
                    a_shape, fortran, a_dtype = np.lib.format.read_array_header_2_0(fp)
                else:
                    raise self.error(f"array '{name}': unsupported .npy version {version}")
                data_offset = fp.tell()
        except FormatError:
            raise
        except (zipfile.BadZipFile, zlib.error) as exc:  # small members are read whole: CRC checked here
            raise self.error(f"array '{name}': corrupt data ({exc})") from None
        except (KeyError, ValueError, OSError, EOFError) as exc:
            raise self.error(f"array '{name}': unreadable .npy header ({exc})") from None
        if a_dtype.hasobject:
            raise self.error(f"array '{name}': object (pickled) arrays are not allowed")
        if a_dtype != dtype:
            raise self.error(f"array '{name}': dtype {a_dtype.str}, expected {dtype.str}")
        if len(a_shape) != len(shape) or any(e is not None and a != e for a, e in zip(a_shape, shape)):
            want = "(" + ", ".join("*" if e is None else str(e) for e in shape) + ")"
            raise self.error(f"array '{name}': shape {tuple(a_shape)}, expected {want}")
        if fortran and len(a_shape) > 1:
            raise self.error(f"array '{name}': Fortran-ordered arrays are not allowed")
        nbytes = math.prod(a_shape) * dtype.itemsize
        if info.file_size != data_offset + nbytes:
            raise self.error(f"array '{name}': {info.file_size - data_offset} data bytes for {nbytes} expected "
                             "(truncated or padded)")
        try:
            arr = self.npz[name]
        except (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error, MemoryError) as exc:
            raise self.error(f"array '{name}': corrupt data ({exc})") from None
        return arr

    def check_unused(self) -> None:
        extra = sorted(self.names - self.used)
        if extra:
            raise self.error(f"unexpected array '{extra[0]}' (not part of {FORMAT} version {VERSION})")



def check_index(arch: NpzArchive, name: str, arr: np.ndarray, upper: int) -> None:
    """Every value of an index array is in [0, upper)."""
    if len(arr) and (int(arr.min()) < 0 or int(arr.max()) >= upper):
        bad = int(np.flatnonzero((arr < 0) | (arr >= upper))[0])
        raise arch.error(f"array '{name}': index {int(arr[bad])} at row {bad} out of range [0, {upper})")


@contextmanager
def gc_paused() -> Iterator[None]:
    """Saving allocates millions of temporaries: pause the cyclic GC meanwhile."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


@contextmanager
def young_collections_only() -> Iterator[None]:
    """Loading makes millions of long-lived objects. Young collections stay on (they are cheap
    while the new objects are still in cache, and they untrack the float tuples early, so the
    attribute dicts holding them are created untracked); full collections, which would re-traverse
    the whole growing heap again and again, are postponed until the graph is built."""
    t0, t1, t2 = gc.get_threshold()
    gc.set_threshold(t0, t1, 2**30)
    try:
        yield
    finally:
        gc.set_threshold(t0, t1, t2)
