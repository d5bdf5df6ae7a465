"""objdb: a Python client for the objdb object database server (gRPC API objdb.v1).

    import objdb
    with objdb.Client("127.0.0.1:50051") as db:
        for event in db.stream("path/to/tum_folder", session="kitchen-1"):
            print(event)
        for o in db.objects():
            print(o.id, o.num_poses, db.object(o.id).poses.shape)

See docs/python.md.
"""

from objdb.client import TLS, Client, Error
from objdb.frames import Dataset, Frame
from objdb.geometry import Intrinsics, Mesh, PointCloud, matrix_to_pose, pose_to_matrix
from objdb.types import (FrameAck, MergeEvidence, ObjectDetail, ObjectEvent, ObjectSummary,
                         SegmentExtracted, SessionEnded, SessionInfo, SessionOpened, SessionSummary)

__all__ = [
    "Client", "Error", "TLS", "Dataset", "Frame", "Intrinsics", "Mesh", "PointCloud",
    "matrix_to_pose", "pose_to_matrix", "FrameAck", "MergeEvidence", "ObjectDetail",
    "ObjectEvent", "ObjectSummary", "SegmentExtracted", "SessionEnded", "SessionInfo",
    "SessionOpened", "SessionSummary",
]
