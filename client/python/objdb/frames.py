"""Frames to stream: numpy arrays, or a dataset folder read lazily.

A dataset folder is in objdb's layout (intrinsics.json, poses.txt, depth/NNNNNN.png,
color/NNNNNN.png; what `objdb sim` writes) or TUM RGB-D's (intrinsics.json, depth.txt, rgb.txt,
groundtruth.txt; each depth image takes the pose and the colour image nearest in time within
20 ms, as the C++ reader does). Its PNG and JPEG files go to the server as they are, undecoded:
the server checks and decodes them.
"""

from __future__ import annotations

import bisect
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, List, Optional, Tuple

import numpy as np

from objdb.geometry import Intrinsics, matrix_to_pose, png_size
from objdb.v1 import objdb_pb2 as pb

TUM_DEPTH_FACTOR = 5000.0  # units per metre
MAX_TIME_DIFFERENCE_S = 0.02


@dataclass
class Frame:
    """One posed RGB-D frame as arrays.

    depth: H x W, uint16 (scaled by the stream's depth_scale, metres per unit; 0 = no
    measurement) or float32 metres (0 or NaN = none). color: H x W x 3 uint8 RGB, or None.
    pose: 4 x 4 T_world_camera (camera to world, OpenCV camera axes). timestamp: seconds,
    increasing (default: the frame's position / 30). index: increasing (default: position).
    """

    depth: np.ndarray
    pose: np.ndarray
    color: Optional[np.ndarray] = None
    timestamp: Optional[float] = None
    index: Optional[int] = None


def frame_to_proto(frame: Frame, position: int, intrinsics: Intrinsics,
                   depth_scale: float) -> pb.Frame:
    """The proto of a numpy frame; ValueError naming the frame and what is wrong."""
    what = f"frame {position}"
    depth = np.asarray(frame.depth)
    if depth.shape != (intrinsics.height, intrinsics.width):
        raise ValueError(f"{what}: depth has shape {depth.shape}, the intrinsics say "
                         f"{(intrinsics.height, intrinsics.width)} (height, width)")
    out = pb.Frame()
    out.index = position if frame.index is None else int(frame.index)
    out.timestamp_s = position / 30.0 if frame.timestamp is None else float(frame.timestamp)
    out.T_world_camera.CopyFrom(matrix_to_pose(frame.pose, f"{what}: pose"))
    d = out.depth
    d.width, d.height = intrinsics.width, intrinsics.height
    if depth.dtype == np.uint16:
        d.encoding = pb.DepthImage.UINT16
        d.metres_per_unit = depth_scale
        d.data = depth.astype("<u2", copy=False).tobytes()
    elif depth.dtype == np.float32:
        d.encoding = pb.DepthImage.FLOAT32
        d.data = depth.astype("<f4", copy=False).tobytes()
    else:
        raise ValueError(f"{what}: depth must be uint16 or float32 (got {depth.dtype})")
    if frame.color is not None:
        color = np.asarray(frame.color)
        if color.shape != (intrinsics.height, intrinsics.width, 3) or color.dtype != np.uint8:
            raise ValueError(f"{what}: color must be uint8 of shape "
                             f"{(intrinsics.height, intrinsics.width, 3)} (got {color.dtype} "
                             f"{color.shape})")
        c = out.color
        c.width, c.height = intrinsics.width, intrinsics.height
        c.encoding = pb.ColorImage.RGB8
        c.data = np.ascontiguousarray(color).tobytes()
    return out


def _read_intrinsics(path: Path, scale_key: str) -> Tuple[Intrinsics, Optional[float]]:
    try:
        k = json.loads(path.read_text())
        intrinsics = Intrinsics(int(k["width"]), int(k["height"]), float(k["fx"]),
                                float(k["fy"]), float(k["cx"]), float(k["cy"]))
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{path}: not valid intrinsics ({e})") from None
    return intrinsics, (float(k[scale_key]) if scale_key in k else None)


def _records(path: Path, parse, expected: str) -> list:
    """parse(fields) of every line that is not blank or a '#' comment; ValueError naming the
    file, the line and the `expected` form when a line does not parse."""
    out = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        try:
            out.append(parse(fields))
        except (ValueError, IndexError) as e:
            raise ValueError(f"{path}:{number}: expected '{expected}' ({e})") from None
    return out


def _pose(fields) -> Tuple[float, pb.Pose]:
    t, tx, ty, tz, qx, qy, qz, qw = (float(f) for f in fields)
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if not (n > 0 and math.isfinite(n)):
        raise ValueError("the quaternion is zero or not finite")
    return t, pb.Pose(x=tx, y=ty, z=tz, qx=qx / n, qy=qy / n, qz=qz / n, qw=qw / n)


def _pose_lines(path: Path) -> List[Tuple[float, pb.Pose]]:
    """A TUM trajectory: (timestamp, T_world_camera) per line."""
    return _records(path, _pose, "timestamp tx ty tz qx qy qz qw")


def _list_lines(path: Path) -> List[Tuple[float, str]]:
    """A TUM file list: (timestamp, path) per line."""
    return _records(path, lambda f: (float(f[0]), f[1]), "timestamp path")


def _nearest(times: List[float], t: float, max_dt: float) -> int:
    i = bisect.bisect_left(times, t)
    best, best_dt = -1, math.inf
    for j in (i - 1, i):
        if 0 <= j < len(times) and abs(times[j] - t) < best_dt:
            best, best_dt = j, abs(times[j] - t)
    return best if best_dt <= max_dt else -1


class Dataset:
    """A dataset folder (objdb or TUM layout), its frames read lazily as proto messages."""

    def __init__(self, root):
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"no dataset folder {self.root}")
        intrinsics_path = self.root / "intrinsics.json"
        # (timestamp, pose, depth path, colour path or None) per frame
        self._frames: List[Tuple[float, pb.Pose, Path, Optional[Path]]] = []
        if (self.root / "poses.txt").exists():
            self.layout = "objdb"
            if not intrinsics_path.exists():
                raise FileNotFoundError(f"objdb dataset {self.root} has no intrinsics.json")
            self.intrinsics, scale = _read_intrinsics(intrinsics_path, "depth_scale_m")
            self.depth_scale = scale if scale is not None else 0.001
            has_color = (self.root / "color").is_dir()
            for i, (t, pose) in enumerate(_pose_lines(self.root / "poses.txt")):
                name = f"{i:06d}.png"
                color = self.root / "color" / name if has_color else None
                self._frames.append((t, pose, self.root / "depth" / name, color))
        elif (self.root / "depth.txt").exists():
            self.layout = "tum"
            if not intrinsics_path.exists():
                raise FileNotFoundError(f"TUM dataset {self.root} has no intrinsics.json")
            self.intrinsics, factor = _read_intrinsics(intrinsics_path, "depth_factor")
            self.depth_scale = 1.0 / (factor if factor is not None else TUM_DEPTH_FACTOR)
            groundtruth = self.root / "groundtruth.txt"
            if not groundtruth.exists():
                raise FileNotFoundError(f"TUM dataset {self.root} has no groundtruth.txt")
            poses = sorted(_pose_lines(groundtruth), key=lambda p: p[0])
            pose_times = [p[0] for p in poses]
            rgb = []
            if (self.root / "rgb.txt").exists():
                rgb = sorted(_list_lines(self.root / "rgb.txt"))
            rgb_times = [r[0] for r in rgb]
            for t, depth in _list_lines(self.root / "depth.txt"):
                p = _nearest(pose_times, t, MAX_TIME_DIFFERENCE_S)
                if p < 0:
                    continue  # no pose: skipped, as the C++ reader does
                c = _nearest(rgb_times, t, MAX_TIME_DIFFERENCE_S)
                color = self.root / rgb[c][1] if c >= 0 else None
                self._frames.append((t, poses[p][1], self.root / depth, color))
        else:
            raise ValueError(f"{self.root} is neither an objdb dataset (poses.txt) nor a TUM one "
                             "(depth.txt)")

    def __len__(self) -> int:
        return len(self._frames)

    def frame(self, i: int) -> pb.Frame:
        """Frame i as sent: the depth PNG and the colour file as they are on disk."""
        t, pose, depth_path, color_path = self._frames[i]
        out = pb.Frame(index=i, timestamp_s=t)
        out.T_world_camera.CopyFrom(pose)
        data = depth_path.read_bytes()
        width, height = png_size(data)
        out.depth.CopyFrom(pb.DepthImage(width=width, height=height,
                                         encoding=pb.DepthImage.PNG16, data=data,
                                         metres_per_unit=self.depth_scale))
        if color_path is not None:
            data = color_path.read_bytes()
            png = color_path.suffix.lower() == ".png"
            # The server checks the size against the depth image's and decodes the file.
            out.color.CopyFrom(pb.ColorImage(
                width=width, height=height, data=data,
                encoding=pb.ColorImage.PNG if png else pb.ColorImage.JPEG))
        return out

    def frames(self, every: int = 1) -> Iterator[pb.Frame]:
        for i in range(0, len(self), every):
            yield self.frame(i)
