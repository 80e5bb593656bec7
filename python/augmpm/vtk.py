"""ParaView output: one ``.vtp`` (VTK XML PolyData) per frame and a ``.pvd`` index.

meshio writes unstructured grids (``.vtu``) but not PolyData, which is the
natural type of a point cloud, so the few lines of XML are written here.
"""

from __future__ import annotations

import base64
from pathlib import Path

import numpy as np

from augmpm.files import write_text

_VTK_TYPES = {np.dtype(np.float64): "Float64", np.dtype(np.int32): "Int32", np.dtype(np.int64): "Int64"}


def _data_array(name: str, a: np.ndarray, components: int) -> str:
    a = np.ascontiguousarray(a)
    raw = a.tobytes()
    # Inline binary: base64 of a UInt32 byte count followed by the data.
    payload = base64.b64encode(np.uint32(len(raw)).tobytes() + raw).decode("ascii")
    return (
        f'<DataArray type="{_VTK_TYPES[a.dtype]}" Name="{name}" NumberOfComponents="{components}" '
        f'format="binary">{payload}</DataArray>'
    )


def write_vtp(path: Path, x: np.ndarray, point_data: dict[str, np.ndarray]) -> None:
    """Writes particles (N, 2) as vertices at z = 0 with per-point arrays."""
    n = len(x)
    points = np.zeros((n, 3))
    points[:, :2] = x
    arrays = []
    for name, a in point_data.items():
        a = np.asarray(a)
        if a.ndim == 2 and a.shape[1] == 2:
            a3 = np.zeros((n, 3), dtype=a.dtype)
            a3[:, :2] = a
            a = a3
        arrays.append(_data_array(name, a, 1 if a.ndim == 1 else a.shape[1]))
    conn = np.arange(n, dtype=np.int64)
    offsets = np.arange(1, n + 1, dtype=np.int64)
    xml = (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt32">\n'
        f'<PolyData><Piece NumberOfPoints="{n}" NumberOfVerts="{n}" NumberOfLines="0" '
        'NumberOfStrips="0" NumberOfPolys="0">\n'
        f"<Points>{_data_array('Points', points, 3)}</Points>\n"
        f"<Verts>{_data_array('connectivity', conn, 1)}{_data_array('offsets', offsets, 1)}</Verts>\n"
        f"<PointData>{''.join(arrays)}</PointData>\n"
        "</Piece></PolyData>\n</VTKFile>\n"
    )
    write_text(path, xml, encoding="ascii")


def write_pvd(path: Path, frames: list[tuple[float, str]]) -> None:
    """Writes the ``.pvd`` collection that lists each frame file with its time (s)."""
    rows = "\n".join(f'<DataSet timestep="{t!r}" part="0" file="{f}"/>' for t, f in frames)
    write_text(
        path,
        '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n<Collection>\n'
        f"{rows}\n</Collection>\n</VTKFile>\n",
        encoding="ascii",
    )
