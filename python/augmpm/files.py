"""Atomic output files: a file appears under its name complete, or not at all.

Every output of a run goes through :func:`atomic_write`: the bytes go to a temporary file
in the same directory, and the file is renamed over its final name (``os.replace`` is
atomic on POSIX and Windows). A run killed at any moment (even SIGKILL) leaves each file
either as it was before or complete, plus at most a stray temporary ``.<name>.tmp-<pid>``
file that the next run removes. Only ``durable`` writes (checkpoints) are also forced to
the disk before the rename (the directory entry is not), so a checkpoint's own bytes
survive a power cut; the other files cost no disk flush each and are safe only against
the process dying.
"""

from __future__ import annotations

import contextlib
import io
import os
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

import numpy as np

TMP_MARK = ".tmp-"


def output_dir(path: str | Path, key: str = "out") -> Path:
    """Creates the directory ``path`` (and its parents) for a run's outputs; a path that is a file, or
    that cannot be created, is bad input: :class:`augmpm.SceneError` naming ``key``."""
    from augmpm._core import SceneError

    path = Path(path)
    if path.exists() and not path.is_dir():
        reason = f"{path} exists and is not a directory"
    else:
        try:
            path.mkdir(parents=True, exist_ok=True)
            return path
        except OSError as e:
            reason = f"cannot create {path} ({e.strerror})"
    err = SceneError(f"{key}: {reason}")
    err.key, err.reason = key, reason
    raise err


@contextlib.contextmanager
def atomic_write(
    path: str | Path, mode: str = "wb", encoding: str | None = None, durable: bool = False
) -> Iterator[IO]:
    """Opens a temporary file beside ``path`` and renames it to ``path`` once written.

    Nothing is renamed if the block raises; the temporary file is then removed.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}{TMP_MARK}{os.getpid()}")
    newline = "" if "b" not in mode else None
    try:
        with open(tmp, mode, encoding=encoding, newline=newline) as fh:
            yield fh
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_bytes(path: str | Path, data: bytes, durable: bool = False) -> None:
    with atomic_write(path, durable=durable) as fh:
        fh.write(data)


def write_text(path: str | Path, text: str, encoding: str = "utf-8") -> None:
    with atomic_write(path, "w", encoding=encoding) as fh:
        fh.write(text)


def save_png(fig, path: str | Path, dpi: int = 80) -> None:
    """Saves a matplotlib figure as PNG, atomically, and closes it."""
    import matplotlib.pyplot as plt

    with atomic_write(path) as fh:
        fig.savefig(fh, format="png", dpi=dpi)
    plt.close(fig)


def npz_bytes(arrays: dict[str, np.ndarray], compress: bool = False, allow_pickle: bool = False) -> bytes:
    """The ``.npz`` archive of ``arrays`` (readable by ``np.load``), byte for byte the same for
    the same arrays: unlike ``np.savez`` it stamps no modification time into the archive. ``compress``:
    deflated, as ``np.savez_compressed``; ``allow_pickle``: object arrays too (read back with
    ``np.load(..., allow_pickle=True)``)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED) as z:
        for name, a in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = z.compression
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asanyarray(a), allow_pickle=allow_pickle)
            z.writestr(info, member.getvalue())
    return buf.getvalue()


def write_npz(path: str | Path, arrays: dict[str, np.ndarray], durable: bool = False) -> None:
    """Writes ``arrays`` as a deterministic ``.npz`` (see :func:`npz_bytes`), atomically."""
    write_bytes(path, npz_bytes(arrays), durable=durable)


def remove_stale_temporaries(directory: Path) -> None:
    """Removes the temporary files a killed run left in ``directory`` and its subdirectories."""
    for tmp in directory.rglob(f".*{TMP_MARK}*"):
        tmp.unlink(missing_ok=True)
