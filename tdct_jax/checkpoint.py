"""A sweep's work in progress on disk: every finished chunk kept durably in a visible partial folder
beside the output file, the fingerprint that decides whether a later run may resume from it, and
the output .npz assembled from the chunks with deterministic bytes.

The folder ``<stem>.partial/`` holds ``manifest.json`` (the fingerprint and the number of chunks,
written once) and ``chunk-<i>.npz`` per finished chunk. A chunk file is written under a temporary
name, flushed to the disk and renamed, so a chunk counts as done exactly when its file exists:
a stop at any moment (SIGKILL, time limit, out of memory, Ctrl-C) leaves only whole chunks. The
assembled file carries the fingerprint as its zip comment (``np.load`` ignores it), so that the
same sweep run again finds it complete.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import re
import shutil
import sys
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

MANIFEST = "manifest.json"
EXECUTION = ("chunk_size", "devices")
"""Fingerprint entries that change how a sweep runs, not what its finished file means: a complete
file counts as the same sweep whatever they were."""
CHUNK = re.compile(r"chunk-(\d+)\.npz")
ZIP_TIME = (1980, 1, 1, 0, 0, 0)
"""Timestamp of every member of an assembled .npz, so that equal arrays give equal file bytes."""


def partial_path(path) -> Path:
    """The partial folder of an output file: ``<stem>.partial`` beside it."""
    path = Path(path)
    folder = path.with_name(f"{path.stem}.partial")
    return folder if folder != path else path.with_name(f"{path.name}.partial")


def digest(values) -> dict:
    """What a fingerprint keeps of an array of inputs: its shape and a hash of its float64 bytes."""
    a = np.ascontiguousarray(values, dtype=np.float64)
    return {"shape": list(a.shape), "sha256": hashlib.sha256(a.tobytes()).hexdigest()}


def differences(old: Mapping, new: Mapping) -> list[str]:
    """What differs between two fingerprints, one readable line per entry."""
    lines = []
    for key in [*old, *(k for k in new if k not in old)]:
        a, b = old.get(key), new.get(key)
        if a == b:
            continue
        if isinstance(a, dict) and isinstance(b, dict) and a["shape"] == b["shape"]:
            lines.append(f"{key}: values differ")
        elif isinstance(a, dict) and isinstance(b, dict):
            lines.append(f"{key}: shape {tuple(a['shape'])} then {tuple(b['shape'])}")
        else:
            lines.append(f"{key}: {_show(a)} then {_show(b)}")
    return lines


def _show(value) -> str:
    return "absent" if value is None else json.dumps(value)


def _read_manifest(folder: Path) -> dict | None:
    try:
        return json.loads((folder / MANIFEST).read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as e:
        raise ValueError(f"{folder / MANIFEST} cannot be read ({e}); remove {folder} or pass overwrite=True") from e


def _done(folder: Path) -> set[int]:
    return {int(m.group(1)) for f in folder.iterdir() if (m := CHUNK.fullmatch(f.name))}


def progress(folder) -> tuple[int, int] | None:
    """(chunks done, chunks in all) of a partial folder, or None where there is none."""
    folder = Path(folder)
    manifest = _read_manifest(folder) if folder.is_dir() else None
    return None if manifest is None else (len(_done(folder)), manifest["chunks"])


def _fsync_dir(folder: Path) -> None:
    """Makes a rename in ``folder`` durable (POSIX; elsewhere the rename alone)."""
    if os.name != "posix":
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _durable(tmp: Path, final: Path, write) -> None:
    """Writes a file under a temporary name with ``write(file)``, flushes it to the disk and renames it."""
    with open(tmp, "wb") as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, final)
    _fsync_dir(final.parent)


def written_fingerprint(path) -> dict | None:
    """The fingerprint an assembled file carries (its zip comment), or None (not such a file)."""
    try:
        with zipfile.ZipFile(path) as archive:
            return json.loads(archive.comment.decode()) if archive.comment else None
    except (OSError, zipfile.BadZipFile, ValueError):
        return None


def complete(path, fingerprint: Mapping, *, overwrite: bool = False) -> bool:
    """True when ``path`` is there, assembled by the same sweep (equal fingerprint but for
    ``EXECUTION``) and no partial folder is being filled for it: nothing to compute. False when
    it is not there, with ``overwrite``, or while a partial folder exists (its run goes on).

    Raises:
        ValueError: ``path`` is there but holds another sweep (naming what differs) or a file no
            sweep assembled.
    """
    path = Path(path)
    if overwrite or not path.is_file() or partial_path(path).exists():
        return False
    old = written_fingerprint(path)
    again = "; to replace it pass overwrite=True (tdct sweep --overwrite), or write to another out= path"
    if old is None:
        raise ValueError(f"{path} is there already but was not assembled by tdct.sweep (no sweep fingerprint){again}")
    new = json.loads(json.dumps(dict(fingerprint)))
    changes = differences(*({k: v for k, v in f.items() if k not in EXECUTION} for f in (old, new)))
    if changes:
        raise ValueError(f"{path} holds a different, finished sweep ({'; '.join(changes)}){again}")
    return True


class Partial:
    """The partial folder of one output file (a sweep's, or one process's part of it)."""

    def __init__(self, folder: Path, chunks: int, done: set[int], fingerprint: Mapping):
        self.folder, self.chunks, self.done, self.fingerprint = folder, chunks, frozenset(done), fingerprint

    @classmethod
    def open(cls, path, fingerprint: Mapping, chunks: int, *, overwrite: bool = False) -> Partial:
        """The partial folder of ``path``: created, or resumed where an earlier run of the same
        sweep (equal fingerprint) left it; reported on stderr when it holds finished chunks.

        Args:
            path: the output file.
            fingerprint: {name: JSON value} of everything that determines the file.
            chunks: how many chunks the file is made of.
            overwrite: discard a folder of a different sweep instead of refusing it.

        Raises:
            ValueError: the folder holds chunks of a sweep with another fingerprint (naming what
                differs), or is not a partial folder.
        """
        path = Path(path)
        folder = partial_path(path)
        if not path.parent.is_dir():
            raise ValueError(f"out = {str(path)!r}: the folder {str(path.parent)!r} does not exist")
        fingerprint = json.loads(json.dumps(dict(fingerprint)))  # as it reads back from the manifest
        manifest = _read_manifest(folder) if folder.is_dir() else None
        if folder.exists() and manifest is None and (not folder.is_dir() or any(folder.iterdir())):
            raise ValueError(f"{folder} is in the way of {path.name}'s partial folder (it holds no {MANIFEST}); move it away")
        if manifest is not None and overwrite:
            shutil.rmtree(folder)
            manifest = None
        if manifest is None:
            folder.mkdir(exist_ok=True)
            text = json.dumps(dict(output=path.name, chunks=chunks, fingerprint=fingerprint), indent=1).encode()
            _durable(folder / f"{MANIFEST}.tmp", folder / MANIFEST, lambda f: f.write(text))
            return cls(folder, chunks, set(), fingerprint)
        changes = differences(manifest["fingerprint"], fingerprint)
        if changes:
            raise ValueError(
                f"{folder} holds chunks of a different sweep ({'; '.join(changes)}); to discard them and start afresh "
                f"pass overwrite=True (tdct sweep --overwrite), or write to another out= path"
            )
        done = _done(folder)
        if done:
            print(f"resuming from {folder}: {len(done)} of {chunks} chunks done", file=sys.stderr)
        return cls(folder, chunks, done, fingerprint)

    def _chunk(self, i: int) -> Path:
        return self.folder / f"chunk-{i:06d}.npz"

    def save(self, i: int, arrays: Mapping) -> None:
        """Keeps chunk i's arrays (equal leading lengths); it counts as done once this returns."""
        _durable(self.folder / f"chunk-{i:06d}.tmp", self._chunk(i), lambda f: np.savez(f, **arrays))

    def read(self, i: int, names) -> dict:
        """The named arrays of finished chunk i."""
        with np.load(self._chunk(i)) as data:
            return {name: data[name] for name in names}

    def finish(self, path, head: Mapping, shape: tuple, tail: Mapping) -> Path:
        """Writes ``path``, an uncompressed .npz of ``head``'s arrays, then each array of the
        chunks joined along their leading axis and reshaped to ``shape`` + its trailing axes, then
        ``tail``'s arrays, with the fingerprint as the archive's comment; removes the folder. Host
        memory holds one chunk's array at a time."""
        path = Path(path)
        missing = sorted(set(range(self.chunks)) - _done(self.folder))
        if missing:
            raise RuntimeError(f"{self.folder}: chunk(s) {missing[:10]} of {self.chunks} are not done")
        with np.load(self._chunk(0)) as first:
            templates = {name: first[name][:0] for name in first.files}

        def write(f):
            with zipfile.ZipFile(f, "w", zipfile.ZIP_STORED) as archive:
                archive.comment = json.dumps(self.fingerprint, sort_keys=True).encode()
                for name, v in head.items():
                    _member(archive, name, v.shape, v.dtype, [v])
                for name, v in templates.items():
                    blocks = (self.read(i, [name])[name] for i in range(self.chunks))
                    _member(archive, name, shape + v.shape[1:], v.dtype, blocks)
                for name, v in tail.items():
                    _member(archive, name, v.shape, v.dtype, [v])

        _durable(self.folder / "assembled.tmp", path, write)
        shutil.rmtree(self.folder)
        return path


def _member(archive: zipfile.ZipFile, name: str, shape: tuple, dtype, blocks) -> None:
    """Writes ``<name>.npy`` of the given shape and dtype from C-ordered blocks (as ``np.save`` would)."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": tuple(map(int, shape))}
    )
    info = zipfile.ZipInfo(f"{name}.npy", date_time=ZIP_TIME)
    info.external_attr = 0o644 << 16
    size = math.prod(shape) * dtype.itemsize
    info.file_size = len(header.getvalue()) + size
    written = 0
    with archive.open(info, "w") as f:
        f.write(header.getvalue())
        for block in blocks:
            block = np.ascontiguousarray(block, dtype=dtype)
            f.write(block.data)
            written += block.nbytes
    if written != size:
        raise RuntimeError(f"{name}: the chunks hold {written} bytes, its shape {shape} needs {size}")
