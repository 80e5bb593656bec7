"""ParaView output: one ``.vtp`` (VTK XML PolyData) per frame and a ``.pvd`` index; the walls of each frame
(where moving walls are then) likewise, as polylines.

meshio writes unstructured grids (``.vtu``) but not PolyData, which is the
natural type of a point cloud, so the few lines of XML are written here.
"""

from __future__ import annotations

import base64
import re
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
    """Writes particles (N, 2) as vertices at z = 0 (or (N, 3) as they are) with per-point arrays."""
    n = len(x)
    points = np.zeros((n, 3))
    points[:, : x.shape[1]] = x
    arrays = []
    for name, a in point_data.items():
        a = np.asarray(a)
        if a.ndim == 3:  # a D×D tensor per point: VTK's 3×3, row-major
            a3 = np.zeros((n, 3, 3), dtype=a.dtype)
            a3[:, : a.shape[1], : a.shape[2]] = a
            a = a3.reshape(n, 9)
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


def write_outlines_vtp(path: Path, outlines: list[np.ndarray]) -> None:
    """Writes closed outlines ((M, 2) vertices each, m) as polylines at z = 0, with a cell array `wall`
    (the outline's index): the walls of one frame."""
    points = np.zeros((sum(len(o) for o in outlines), 3))
    conn, offsets, start = [], [], 0
    for o in outlines:
        points[start : start + len(o), :2] = o
        conn.extend([*range(start, start + len(o)), start])  # closed: back to the first vertex
        offsets.append(len(conn))
        start += len(o)
    wall = np.arange(len(outlines), dtype=np.int32)
    xml = (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt32">\n'
        f'<PolyData><Piece NumberOfPoints="{len(points)}" NumberOfVerts="0" NumberOfLines="{len(outlines)}" '
        'NumberOfStrips="0" NumberOfPolys="0">\n'
        f"<Points>{_data_array('Points', points, 3)}</Points>\n"
        f"<Lines>{_data_array('connectivity', np.asarray(conn, dtype=np.int64), 1)}"
        f"{_data_array('offsets', np.asarray(offsets, dtype=np.int64), 1)}</Lines>\n"
        f"<CellData>{_data_array('wall', wall, 1)}</CellData>\n"
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


_DATA_ARRAY = re.compile(r'<DataArray type="(\w+)" Name="(\w+)" NumberOfComponents="(\d+)" format="binary">([^<]*)<')
_NUMPY_TYPES = {name: dtype for dtype, name in _VTK_TYPES.items()}


def read_vtp(path: Path) -> dict[str, np.ndarray]:
    """The arrays of a ``.vtp`` written here (:func:`write_vtp`, :func:`write_outlines_vtp`) by name:
    ``Points`` (M, 3), ``connectivity`` and ``offsets`` of its vertices or lines, and its point or cell
    data. Not a general VTK reader."""
    arrays = {}
    for kind, name, components, payload in _DATA_ARRAY.findall(Path(path).read_text(encoding="ascii")):
        raw = base64.b64decode(payload)
        size = int(np.frombuffer(raw[:4], dtype=np.uint32)[0])
        a = np.frombuffer(raw[4 : 4 + size], dtype=_NUMPY_TYPES[kind])
        arrays[name] = a.reshape(-1, int(components)) if int(components) > 1 else a
    return arrays


def read_outlines(path: Path, dim: int = 2) -> list[np.ndarray]:
    """The closed outlines (M, 2) of a file of :func:`write_outlines_vtp` (2D), or its points (M, 3) as one
    array (a 3D frame's wall surface points, :func:`write_vtp`)."""
    a = read_vtp(path)
    points = a["Points"]
    if dim == 3:
        return [points]
    outlines, start = [], 0
    for end in a["offsets"]:
        ids = a["connectivity"][start : end - 1]  # the last repeats the first
        outlines.append(points[ids, :2])
        start = end
    return outlines


def write_ply(path: Path, x: np.ndarray, point_data: dict[str, np.ndarray]) -> None:
    """Writes particles (N, 2) at z = 0 (or (N, 3)) as a binary PLY point cloud (``plyfile``), with each
    per-point array as vertex properties: scalars by name, vectors by component (``velocity_x``, ...),
    tensors by entry (``stress_xy``, ...). The same arrays give the same bytes (no time stamp)."""
    import io

    from plyfile import PlyData, PlyElement

    n = len(x)
    columns: list[tuple[str, np.ndarray]] = [(axis, np.zeros(n)) for axis in "xyz"]
    for k in range(x.shape[1]):
        columns[k] = ("xyz"[k], np.asarray(x[:, k], dtype=np.float64))
    for name, a in point_data.items():
        a = np.asarray(a)
        if a.ndim == 1:
            columns.append((name, a))
        elif a.ndim == 2:
            columns += [(f"{name}_{'xyz'[k]}", a[:, k]) for k in range(a.shape[1])]
        else:
            columns += [
                (f"{name}_{'xyz'[i]}{'xyz'[j]}", a[:, i, j]) for i in range(a.shape[1]) for j in range(a.shape[2])
            ]
    dtype = [(name, "i4" if np.issubdtype(c.dtype, np.integer) else "f8") for name, c in columns]
    vertices = np.empty(n, dtype=dtype)
    for name, c in columns:
        vertices[name] = c
    buffer = io.BytesIO()
    PlyData([PlyElement.describe(vertices, "vertex")], text=False, byte_order="<").write(buffer)
    from augmpm.files import write_bytes

    write_bytes(path, buffer.getvalue())
