"""Poses and geometry between the API's messages and numpy.

A pose is a 4x4 float64 matrix T_a_b (p_a = T_a_b @ p_b), as in the proto: T_world_camera is
the camera pose, T_world_object an object's base frame in a session's world.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from objdb.v1 import objdb_pb2 as pb


def pose_to_matrix(pose: pb.Pose) -> np.ndarray:
    """The 4x4 matrix of a proto Pose (its quaternion normalised)."""
    q = np.array([pose.qw, pose.qx, pose.qy, pose.qz], dtype=np.float64)
    n = np.linalg.norm(q)
    if n == 0.0:
        raise ValueError("pose has a zero quaternion")
    w, x, y, z = q / n
    T = np.eye(4)
    T[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    T[:3, 3] = [pose.x, pose.y, pose.z]
    return T


def matrix_to_pose(T, what: str = "pose") -> pb.Pose:
    """A proto Pose from a 4x4 rigid transform; ValueError (naming `what`) when it is not one."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"{what} must be a 4x4 matrix (got shape {T.shape})")
    if not np.all(np.isfinite(T)):
        raise ValueError(f"{what} holds a non-finite value")
    R = T[:3, :3]
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-6):
        raise ValueError(f"{what}: the last row must be [0 0 0 1] (got {T[3].tolist()})")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-3) or np.linalg.det(R) < 0:
        raise ValueError(f"{what}: the upper-left 3x3 block is not a rotation")
    # Shepperd's method: the largest of the four squared components first, for accuracy.
    tr = np.trace(R)
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        w, x, y, z = 0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        w, x, y, z = (R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] > R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        w, x, y, z = (R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s
    else:
        s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        w, x, y, z = (R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return pb.Pose(x=T[0, 3], y=T[1, 3], z=T[2, 3], qx=x / n, qy=y / n, qz=z / n, qw=w / n)


def _open3d():
    try:
        import open3d
    except ImportError:
        raise ImportError("to_open3d() needs the open3d package (pip install open3d)") from None
    return open3d


def _floats(values, columns: int) -> np.ndarray:
    return np.array(values, dtype=np.float32).reshape(-1, columns)


def _bytes(data: bytes, columns: int) -> Optional[np.ndarray]:
    if not data:
        return None
    return np.frombuffer(data, dtype=np.uint8).reshape(-1, columns).copy()


def _normals_and_colors(message) -> tuple:
    """The optional per-point normals (N x 3 float32) and colours (N x 3 uint8) of a message."""
    normals = _floats(message.normals, 3) if len(message.normals) else None
    return normals, _bytes(message.colors, 3)


@dataclass
class PointCloud:
    """Points (N x 3, metres), unit normals (N x 3) and RGB colours (N x 3 uint8), or None."""

    points: np.ndarray
    normals: Optional[np.ndarray] = None
    colors: Optional[np.ndarray] = None

    @staticmethod
    def from_proto(cloud: pb.PointCloud) -> "PointCloud":
        return PointCloud(_floats(cloud.points, 3), *_normals_and_colors(cloud))

    def save_ply(self, path) -> None:
        """Writes a binary little-endian PLY file."""
        _write_ply(Path(path), self.points, self.normals, self.colors, None)

    def to_open3d(self):
        """An open3d.geometry.PointCloud with the points, normals and colours (0..1)."""
        o3d = _open3d()
        out = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.points.astype(np.float64)))
        if self.normals is not None:
            out.normals = o3d.utility.Vector3dVector(self.normals.astype(np.float64))
        if self.colors is not None:
            out.colors = o3d.utility.Vector3dVector(self.colors.astype(np.float64) / 255.0)
        return out


@dataclass
class Mesh:
    """A triangle mesh: vertices (V x 3, metres), faces (T x 3 vertex indices, counter-clockwise
    seen from outside), per-vertex normals and RGB colours (or None)."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: Optional[np.ndarray] = None
    colors: Optional[np.ndarray] = None

    @staticmethod
    def from_proto(mesh: pb.Mesh) -> "Mesh":
        faces = np.array(mesh.triangles, dtype=np.uint32).reshape(-1, 3)
        return Mesh(_floats(mesh.vertices, 3), faces, *_normals_and_colors(mesh))

    def to_open3d(self):
        """An open3d.geometry.TriangleMesh with the faces, vertex normals and colours (0..1)."""
        o3d = _open3d()
        out = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(self.vertices.astype(np.float64)),
                                        o3d.utility.Vector3iVector(self.faces.astype(np.int32)))
        if self.normals is not None:
            out.vertex_normals = o3d.utility.Vector3dVector(self.normals.astype(np.float64))
        if self.colors is not None:
            out.vertex_colors = o3d.utility.Vector3dVector(self.colors.astype(np.float64) / 255.0)
        return out

    @staticmethod
    def concatenate(meshes) -> "Mesh":
        """One mesh of several (each one's faces offset by the vertices before it)."""
        meshes = list(meshes)
        if not meshes:
            return Mesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32))
        offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
        faces = np.concatenate([m.faces + np.uint32(o) for m, o in zip(meshes, offsets)])
        vertices = np.concatenate([m.vertices for m in meshes])

        def joined(name):
            parts = [getattr(m, name) for m in meshes]
            if any(p is None for p in parts):
                return None
            return np.concatenate(parts)

        return Mesh(vertices, faces, joined("normals"), joined("colors"))

    def save_ply(self, path) -> None:
        """Writes a binary little-endian PLY file."""
        _write_ply(Path(path), self.vertices, self.normals, self.colors, self.faces)


def _write_ply(path: Path, points, normals, colors, faces) -> None:
    n = len(points)
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {n}",
              "property float x", "property float y", "property float z"]
    columns = [np.asarray(points, np.float32)]
    dtype = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        header += ["property float nx", "property float ny", "property float nz"]
        columns.append(np.asarray(normals, np.float32))
        dtype += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if colors is not None:
        header += ["property uchar red", "property uchar green", "property uchar blue"]
        dtype += [("r", "u1"), ("g", "u1"), ("b", "u1")]
    if faces is not None:
        header += [f"element face {len(faces)}", "property list uchar uint vertex_indices"]
    header.append("end_header")
    vertex = np.empty(n, dtype=dtype)
    names = [d[0] for d in dtype]
    for i, name in enumerate(names[:3]):
        vertex[name] = columns[0][:, i]
    if normals is not None:
        for i, name in enumerate(("nx", "ny", "nz")):
            vertex[name] = columns[1][:, i]
    if colors is not None:
        for i, name in enumerate(("r", "g", "b")):
            vertex[name] = np.asarray(colors, np.uint8)[:, i]
    with open(path, "wb") as out:
        out.write(("\n".join(header) + "\n").encode("ascii"))
        out.write(vertex.tobytes())
        if faces is not None:
            face = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<u4", (3,))])
            face["n"] = 3
            face["v"] = np.asarray(faces, np.uint32)
            out.write(face.tobytes())


@dataclass
class Intrinsics:
    """A pinhole camera (no distortion): image size in pixels, focal lengths and principal point."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def to_proto(self) -> pb.Intrinsics:
        return pb.Intrinsics(width=self.width, height=self.height, fx=self.fx, fy=self.fy,
                             cx=self.cx, cy=self.cy)

    @staticmethod
    def from_proto(k: pb.Intrinsics) -> "Intrinsics":
        return Intrinsics(k.width, k.height, k.fx, k.fy, k.cx, k.cy)


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(data: bytes) -> tuple:
    """(width, height) of a PNG file's bytes (its IHDR chunk)."""
    if len(data) < 24 or data[:8] != _PNG_SIGNATURE or data[12:16] != b"IHDR":
        raise ValueError("not a PNG file")
    return struct.unpack(">II", data[16:24])
