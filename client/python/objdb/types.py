"""What the server answers, as dataclasses with numpy arrays. Each keeps its protobuf message in
`proto` for the fields not copied out."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Optional, Tuple, Union

import numpy as np
from google.protobuf import json_format

from objdb.geometry import Intrinsics, Mesh, PointCloud, pose_to_matrix
from objdb.v1 import objdb_pb2 as pb


def to_dict(message) -> dict:
    """A protobuf message as a dict (proto field names, every field present). Integers stay
    integers (protobuf's JSON form writes 64-bit ones as text)."""
    out = json_format.MessageToDict(message, preserving_proto_field_name=True,
                                    including_default_value_fields=True)
    return _ints(message, out)


def _ints(message, out: dict) -> dict:
    from google.protobuf.descriptor import FieldDescriptor as F
    wide = {F.TYPE_INT64, F.TYPE_UINT64, F.TYPE_SINT64, F.TYPE_FIXED64, F.TYPE_SFIXED64}
    for f in message.DESCRIPTOR.fields:
        if f.name not in out:
            continue
        value = getattr(message, f.name)
        repeated = f.label == F.LABEL_REPEATED
        if f.type == F.TYPE_MESSAGE and not repeated:
            _ints(value, out[f.name])
        elif f.type == F.TYPE_MESSAGE:
            for sub, d in zip(value, out[f.name]):
                _ints(sub, d)
        elif f.type in wide:
            out[f.name] = [int(v) for v in value] if repeated else int(value)
    return out


def _enum_name(enum, value: int, prefix: str) -> str:
    name = enum.Name(value) if value in enum.values() else f"{prefix}{value}"
    return name[len(prefix):].lower() if name.startswith(prefix) else name.lower()


def _box(box: pb.BoundingBox) -> Tuple[np.ndarray, np.ndarray]:
    return (np.array([box.min.x, box.min.y, box.min.z]),
            np.array([box.max.x, box.max.y, box.max.z]))


@dataclass
class FrameAck:
    """A frame was integrated (accepted) or refused (reason names the field and value)."""

    index: int
    accepted: bool
    reason: str
    counters: dict  # this frame's FrameCounters, then the session's totals under "session"
    proto: pb.FrameAck = field(repr=False)


@dataclass
class SegmentExtracted:
    """A segment of the session's map went to the database."""

    segment_id: int
    gsm_label: int
    reason: str  # "idle" or "session_end"
    num_voxels: int
    T_world_segment: np.ndarray
    bounds_world: Tuple[np.ndarray, np.ndarray]
    parts: List[int]
    proto: pb.SegmentExtracted = field(repr=False)


@dataclass
class MergeEvidence:
    """Why a merge was accepted: e_ICP, e_TSDF and o_TSDF (metres, voxels), the scene checks."""

    icp_rmse_m: float
    tsdf_rmse_m: float
    overlap_voxels: int
    scene_checks: int
    source: str
    proto: pb.MergeEvidence = field(repr=False)

    @staticmethod
    def from_proto(e: pb.MergeEvidence) -> "MergeEvidence":
        return MergeEvidence(e.icp_rmse_m, e.tsdf_rmse_m, e.overlap_voxels, e.scene_checks,
                             e.source, e)


@dataclass
class ObjectEvent:
    """kind "created": segment_id became object object_id. kind "merged": the segment
    (object_id 0) or the existing object object_id merged into into_object_id. kind "removed":
    object object_id is gone (its only segment, segment_id, was re-extracted or withdrawn); the
    segment is in into_object_id now (0: none)."""

    kind: str
    object_id: int
    into_object_id: int
    segment_id: int
    evidence: Optional[MergeEvidence]
    proto: pb.ObjectEvent = field(repr=False)


@dataclass
class SessionSummary:
    session: str
    state: str  # "open", "ended" or "interrupted"
    counters: dict
    object_ids: List[int]
    proto: pb.SessionSummary = field(repr=False)

    @staticmethod
    def from_proto(s: pb.SessionSummary) -> "SessionSummary":
        return SessionSummary(s.session_name, _enum_name(pb.SessionState, s.state, "SESSION_STATE_"),
                              to_dict(s.counters), list(s.object_ids), s)


@dataclass
class SessionOpened:
    """The stream's first event: the session the frames go to. resumed: an existing session
    continues, holding frames up to last_frame_index (None when it holds none); replaced: an
    existing session was withdrawn (segments_withdrawn of its segments) and this one replaces it.
    Both: a resumed session whose map a server crash lost continues from its first frame, and stream() sends every frame again.
    """
    session: str
    resumed: bool
    replaced: bool
    last_frame_index: Optional[int]
    counters: dict
    segments_withdrawn: int
    proto: pb.SessionOpened = field(repr=False)

    @staticmethod
    def from_proto(o: pb.SessionOpened) -> "SessionOpened":
        return SessionOpened(o.session_name, o.resumed, o.replaced,
                             int(o.last_frame_index) if o.has_frames else None,
                             to_dict(o.counters), int(o.segments_withdrawn), o)


@dataclass
class SessionEnded:
    """The last event of Client.stream(end=True): EndSession's summary."""

    summary: SessionSummary


Event = Union[FrameAck, SegmentExtracted, ObjectEvent, SessionSummary, SessionEnded]


def event(response: pb.IngestResponse) -> Event:
    kind = response.WhichOneof("event")
    if kind == "ack":
        a = response.ack
        counters = to_dict(a.frame) | {"session": to_dict(a.session)}
        return FrameAck(a.index, a.accepted, a.reason, counters, a)
    if kind == "segment":
        s = response.segment
        return SegmentExtracted(s.segment_id, s.gsm_label,
                                _enum_name(pb.SegmentExtracted.Reason, s.reason, ""),
                                s.num_voxels, pose_to_matrix(s.T_world_segment),
                                _box(s.bounds_world), list(s.parts), s)
    if kind == "object":
        o = response.object
        merged = o.kind == pb.ObjectEvent.MERGED
        return ObjectEvent(_enum_name(pb.ObjectEvent.Kind, o.kind, ""), o.object_id,
                           o.into_object_id, o.segment_id,
                           MergeEvidence.from_proto(o.evidence) if merged else None, o)
    if kind == "summary":
        return SessionSummary.from_proto(response.summary)
    if kind == "opened":
        return SessionOpened.from_proto(response.opened)
    raise ValueError(f"the server sent an event this client does not know ({kind})")


@dataclass
class SessionInfo:
    name: str
    state: str
    started_unix_s: float
    ended_unix_s: float
    client_info: str
    intrinsics: Intrinsics
    counters: dict  # ints; None where a crash lost a counter (unknown, not zero)
    proto: pb.SessionInfo = field(repr=False)

    @staticmethod
    def from_proto(s: pb.SessionInfo) -> "SessionInfo":
        counters = to_dict(s.counters)
        if s.counters_unknown:
            counters = {k: (v if k == "frames_integrated" and v else None)
                        for k, v in counters.items()}
        return SessionInfo(s.session_name, _enum_name(pb.SessionState, s.state, "SESSION_STATE_"),
                           s.started_unix_s, s.ended_unix_s, s.client_info,
                           Intrinsics.from_proto(s.intrinsics), counters, s)


@dataclass
class ObjectSummary:
    id: int
    state: str  # "active" or "merged"
    sessions: List[str]
    num_poses: int
    num_places: int
    bounds: Tuple[np.ndarray, np.ndarray]  # in the object's base frame
    planar: bool
    structure: bool
    parts: list  # with whole_only=False: the parts (protobuf ObjectPart) at each pose
    proto: pb.ObjectSummary = field(repr=False)

    @staticmethod
    def from_proto(o: pb.ObjectSummary) -> "ObjectSummary":
        return ObjectSummary(o.id, _enum_name(pb.ObjectState, o.state, "OBJECT_STATE_"),
                             list(o.session_names), o.num_poses, o.num_places,
                             _box(o.bounds_object), o.planar, o.structure, list(o.parts), o)


@dataclass
class ObjectDetail:
    """An object: poses[i] is T_world_object in session pose_sessions[i]; cloud and mesh (when
    asked) are in the object's base frame."""

    summary: ObjectSummary
    poses: np.ndarray  # N x 4 x 4
    pose_sessions: List[str]
    segment_ids: List[int]
    cloud: Optional[PointCloud]
    mesh: Optional[Mesh]
    merges: List[MergeEvidence]
    stats: dict
    proto: pb.ObjectDetail = field(repr=False)

    @property
    def id(self) -> int:
        return self.summary.id

    @staticmethod
    def from_proto(d: pb.ObjectDetail) -> "ObjectDetail":
        poses = np.array([pose_to_matrix(p.T_world_object) for p in d.poses]).reshape(-1, 4, 4)
        return ObjectDetail(
            ObjectSummary.from_proto(d.summary), poses, [p.session_name for p in d.poses],
            [p.segment_id for p in d.poses],
            PointCloud.from_proto(d.cloud) if d.HasField("cloud") else None,
            Mesh.from_proto(d.mesh) if d.HasField("mesh") else None,
            [MergeEvidence.from_proto(m) for m in d.merges], to_dict(d.stats), d)


@dataclass
class MatchResult:
    """One stored object a Match query was checked against. accepted: every check of a merge
    passed. stage: where it stopped otherwise ("registration", "model", "colour", "scene").
    T_object_query (4 x 4): the query's frame into the object's base frame."""

    object_id: int
    accepted: bool
    stage: str
    reason: str
    T_object_query: np.ndarray
    inliers: int
    evidence: MergeEvidence
    proto: pb.MatchResult = field(repr=False)

    @staticmethod
    def from_proto(m: pb.MatchResult) -> "MatchResult":
        from objdb.geometry import pose_to_matrix
        return MatchResult(m.object_id, m.accepted, m.stage, m.reason,
                           pose_to_matrix(m.T_object_query), m.inliers,
                           MergeEvidence.from_proto(m.evidence), m)


@dataclass
class MatchAnswer:
    """What Match said: the results, accepted first (the lowest e_TSDF first), then the rest in
    vote order; matchable False (and reason) when the query is no matchable object."""

    matchable: bool
    reason: str
    points: int
    keypoints: int
    shortlist: int
    candidates: int
    results: List[MatchResult]
    elapsed_s: float

    @staticmethod
    def from_proto(r: pb.MatchResponse) -> "MatchAnswer":
        return MatchAnswer(r.matchable, r.reason, r.points, r.keypoints, r.shortlist,
                           r.candidates, [MatchResult.from_proto(m) for m in r.results],
                           r.elapsed_s)


@dataclass
class PlacedObject:
    """An object placed in a session's world (ObjectsInRegion): its summary, T_world_object
    (4 x 4), the model's box centre in the world and the world box holding it (min, max)."""

    object: ObjectSummary
    T_world_object: np.ndarray
    centre: np.ndarray
    bounds: Tuple[np.ndarray, np.ndarray]

    @staticmethod
    def from_proto(p: pb.PlacedObject) -> "PlacedObject":
        from objdb.geometry import pose_to_matrix
        c = p.centre_world
        return PlacedObject(ObjectSummary.from_proto(p.object), pose_to_matrix(p.T_world_object),
                            np.array([c.x, c.y, c.z]), _box(p.bounds_world))


@dataclass
class ObjectChange:
    """One object's placements in two sessions (T_world_object, N x 4 x 4 each) and, when it
    moved, the distance (m)."""

    object: ObjectSummary
    before: np.ndarray
    after: np.ndarray
    moved_m: float

    @staticmethod
    def from_proto(c: pb.ObjectChange) -> "ObjectChange":
        from objdb.geometry import pose_to_matrix
        poses = lambda ps: np.array([pose_to_matrix(p) for p in ps]).reshape(-1, 4, 4)
        return ObjectChange(ObjectSummary.from_proto(c.object), poses(c.before), poses(c.after),
                            c.moved_m)


@dataclass
class SessionChanges:
    """What changed from one session to another of the same world (SessionChanges)."""

    added: List[ObjectChange]
    removed: List[ObjectChange]
    moved: List[ObjectChange]
    unchanged: int

    @staticmethod
    def from_proto(r: pb.SessionChangesResponse) -> "SessionChanges":
        return SessionChanges([ObjectChange.from_proto(c) for c in r.added],
                              [ObjectChange.from_proto(c) for c in r.removed],
                              [ObjectChange.from_proto(c) for c in r.moved], r.unchanged)
