"""The objdb client: stream posed RGB-D frames to an objdb server and query its database.

    import objdb
    db = objdb.Client("127.0.0.1:50051")
    for event in db.stream("data/lounge/session_1", session="monday"):
        if isinstance(event, objdb.ObjectEvent):
            print(event.kind, event.object_id, event.into_object_id)
    for o in db.objects():
        detail = db.object(o.id)
        print(o.id, detail.poses.shape, len(detail.cloud.points))

Every call's failure is an objdb.Error carrying the gRPC status code and the server's message.
"""

from __future__ import annotations

import ipaddress
import threading
from pathlib import Path
from typing import Callable, Iterable, Iterator, List, Optional, Union

import grpc
import numpy as np

from objdb import types
from objdb.frames import Dataset, Frame, frame_to_proto
from objdb.geometry import Intrinsics, Mesh
from objdb.v1 import objdb_pb2 as pb
from objdb.v1 import objdb_pb2_grpc as rpc

# The server's default message limit is 16 MiB; a model's mesh may come close, so accept more.
MAX_RECEIVE_BYTES = 256 * 1024 * 1024
MAX_SEND_BYTES = 16 * 1024 * 1024


class Error(Exception):
    """A failed call: `code` is the grpc.StatusCode, `message` the server's (or the channel's)
    explanation."""

    def __init__(self, code: grpc.StatusCode, message: str, call: str = ""):
        self.code = code
        self.message = message
        self.call = call
        prefix = f"{call}: " if call else ""
        super().__init__(f"{prefix}{code.name}: {message}")


def _error(e: grpc.RpcError, call: str) -> Error:
    code = e.code() if hasattr(e, "code") else grpc.StatusCode.UNKNOWN
    details = e.details() if hasattr(e, "details") else str(e)
    return Error(code, details or "", call)


def _is_loopback(address: str) -> bool:
    host = address.rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _read(path_or_bytes) -> bytes:
    if isinstance(path_or_bytes, bytes):
        return path_or_bytes
    return Path(path_or_bytes).read_bytes()


class TLS:
    """TLS to the server: `ca` (PEM CA bundle that signed the server's certificate), and for
    mutual TLS a client certificate `cert` with its key `key`. Each a path or PEM bytes."""

    def __init__(self, ca, cert=None, key=None):
        if (cert is None) != (key is None):
            raise ValueError("TLS: give both a client certificate and its key, or neither")
        self.ca, self.cert, self.key = ca, cert, key

    def credentials(self) -> grpc.ChannelCredentials:
        return grpc.ssl_channel_credentials(
            root_certificates=_read(self.ca),
            private_key=_read(self.key) if self.key is not None else None,
            certificate_chain=_read(self.cert) if self.cert is not None else None)


class Client:
    """A connection to one objdb server.

    address: "host:port". token: the server's bearer token (objdb-server --token-file), sent
    with every call; in clear text only to a loopback address. tls: a TLS, or the path of a PEM
    CA bundle. timeout: default deadline of the unary calls, seconds (None: none).
    """

    def __init__(self, address: str, token: Optional[str] = None,
                 tls: Union[None, str, Path, TLS] = None, timeout: Optional[float] = 60.0):
        if not address:
            raise ValueError("the server address is empty (host:port)")
        if tls is not None and not isinstance(tls, TLS):
            tls = TLS(ca=tls)
        if token is not None:
            token = token.strip()
            if not token:
                raise ValueError("the token is empty")
            if tls is None and not _is_loopback(address):
                raise ValueError(f"refusing to send the token in clear text to {address}: "
                                 "use TLS (tls=...) or a loopback address")
        self.address = address
        self.timeout = timeout
        self._metadata = (("authorization", f"Bearer {token}"),) if token else ()
        options = [("grpc.max_receive_message_length", MAX_RECEIVE_BYTES),
                   ("grpc.max_send_message_length", MAX_SEND_BYTES)]
        if tls is not None:
            self._channel = grpc.secure_channel(address, tls.credentials(), options)
        else:
            self._channel = grpc.insecure_channel(address, options)
        self._stub = rpc.ObjectDatabaseStub(self._channel)

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _call(self, name: str, request, timeout=None):
        method = getattr(self._stub, name)
        try:
            return method(request, timeout=timeout if timeout is not None else self.timeout,
                          metadata=self._metadata)
        except grpc.RpcError as e:
            raise _error(e, name) from None

    # ---------------------------------------------------------------------------------------
    # Streaming
    # ---------------------------------------------------------------------------------------

    def stream(self, source: Union[str, Path, Dataset, Iterable[Frame]],
               session: Optional[str] = None, *,
               intrinsics: Optional[Intrinsics] = None, depth_scale: float = 0.001,
               params: Optional[str] = None, every: int = 1, end: bool = True,
               end_timeout: Optional[float] = 600.0,
               progress: Optional[Callable[[int, Optional[int]], None]] = None,
               client_info: str = "objdb python", resume: bool = False,
               replace: bool = False) -> Iterator[types.Event]:
        """Streams one session and yields the server's events as they come.

        source: a dataset folder (objdb or TUM layout; see objdb.frames), or Frame objects
        (numpy arrays; then `intrinsics` is required and uint16 depth is scaled by
        `depth_scale` metres per unit). session: the session's name; for a dataset its folder's
        name by default (as `objdb stream` names it), for frames required. params: per-session
        parameter overrides as JSON text. every: send every n-th frame of a dataset.
        progress(acked, total) is called on every frame acknowledgement (total None when the
        frames are an iterator of unknown length).

        A name the database has already is objdb.Error ALREADY_EXISTS unless resume=True
        (continue a session whose stream broke: the frames its map holds, up to the
        SessionOpened's last_frame_index, are skipped by their index) or replace=True (the old
        session's segments are withdrawn and it is streamed again).

        Yields SessionOpened first, then FrameAck, SegmentExtracted, ObjectEvent and
        SessionSummary; then, with end=True, EndSession runs (it flushes the session into the
        database) and a SessionEnded is the last event. A call that fails raises objdb.Error; a
        bad frame raises ValueError. Either way, and when the caller stops iterating early, the
        stream is cancelled, never left half-open: the server keeps the session INTERRUPTED for
        a later end_session() or a resume (a session that received no frame is not kept).
        """
        if every < 1:
            raise ValueError(f"every must be >= 1 (got {every})")
        if resume and replace:
            raise ValueError("resume and replace exclude each other")
        if isinstance(source, (str, Path)):
            source = Dataset(source)
        if session is None:
            if not isinstance(source, Dataset):
                raise ValueError("frames given as arrays need a session name (session=...)")
            session = Path(source.root).name
        if isinstance(source, Dataset):
            intrinsics = source.intrinsics
            frames: Iterable = source.frames(every)
            total: Optional[int] = (len(source) + every - 1) // every
        else:
            if intrinsics is None:
                raise ValueError("frames given as arrays need the camera's intrinsics")
            frames = source
            total = len(source) if hasattr(source, "__len__") else None

        if_exists = (pb.SessionHeader.IF_EXISTS_RESUME if resume else
                     pb.SessionHeader.IF_EXISTS_REPLACE if replace else
                     pb.SessionHeader.IF_EXISTS_REFUSE)
        header = pb.SessionHeader(session_name=session, intrinsics=intrinsics.to_proto(),
                                  params_json=params or "", client_info=client_info,
                                  if_exists=if_exists)
        failure: List[BaseException] = []
        started = threading.Event()
        opened = threading.Event()  # the SessionOpened came (or the stream ended)
        holder = {}

        def requests():
            yield pb.IngestRequest(header=header)
            opened.wait()
            first = holder.get("opened")
            if first is None:
                return  # refused: the call's status says why
            skip_to = first.last_frame_index if first.resumed else None
            try:
                for position, frame in enumerate(frames):
                    if not isinstance(frame, pb.Frame):
                        frame = frame_to_proto(frame, position, intrinsics, depth_scale)
                    if skip_to is not None and frame.index <= skip_to:
                        continue  # the session's map holds it already
                    yield pb.IngestRequest(frame=frame)
            except Exception as e:  # a bad frame or an unreadable file: cancel, never half-close
                failure.append(e)
                started.wait()
                holder["call"].cancel()

        call = self._stub.Ingest(requests(), metadata=self._metadata)
        holder["call"] = call
        started.set()
        acked = 0
        try:
            try:
                for response in call:
                    event = types.event(response)
                    if isinstance(event, types.SessionOpened):
                        holder["opened"] = event
                        opened.set()
                        if event.resumed and event.last_frame_index is not None and total:
                            step = every if isinstance(source, Dataset) else 1
                            total = max(0, total - (event.last_frame_index // step + 1))
                    if isinstance(event, types.FrameAck):
                        acked += 1
                        if progress is not None:
                            progress(acked, total)
                    yield event
            except grpc.RpcError as e:
                if failure:
                    raise failure[0] from None
                raise _error(e, f"Ingest of session {session}") from None
            finally:
                opened.set()  # a refused stream: the request generator stops
            if failure:
                raise failure[0]
            if end:
                yield types.SessionEnded(self.end_session(session, timeout=end_timeout))
        finally:
            call.cancel()  # nothing when the call is over; else the stream does not linger

    def end_session(self, session: str, timeout: Optional[float] = 600.0) -> types.SessionSummary:
        """Flushes a session into the database and ends it (EndSession); its summary."""
        response = self._call("EndSession", pb.EndSessionRequest(session_name=session), timeout)
        return types.SessionSummary.from_proto(response.summary)

    # ---------------------------------------------------------------------------------------
    # Queries
    # ---------------------------------------------------------------------------------------

    def sessions(self) -> List[types.SessionInfo]:
        """Every session, oldest first."""
        out, token = [], ""
        while True:
            page = self._call("ListSessions",
                              pb.ListSessionsRequest(page_size=1000, page_token=token))
            out += [types.SessionInfo.from_proto(s) for s in page.sessions]
            token = page.next_page_token
            if not token:
                return out

    def objects(self, session: Optional[str] = None, whole_only: bool = True,
                include_merged: bool = False) -> List[types.ObjectSummary]:
        """The objects, by id: whole objects by default; whole_only=False adds room structure
        (floors, walls) and each object's parts. session: only those it observed."""
        out, token = [], ""
        while True:
            request = pb.ListObjectsRequest(
                page_size=1000, page_token=token, session_name=session or "",
                include_merged=include_merged, include_structure=not whole_only,
                include_parts=not whole_only)
            page = self._call("ListObjects", request)
            out += [types.ObjectSummary.from_proto(o) for o in page.objects]
            token = page.next_page_token
            if not token:
                return out

    def object(self, id: int, mesh: bool = True, cloud: bool = True,
               parts: bool = False) -> types.ObjectDetail:
        """One object with its poses (N x 4 x 4), its surface cloud and mesh (as asked)."""
        request = pb.GetObjectRequest(id=id, include_mesh=mesh, include_cloud=cloud,
                                      include_parts=parts)
        return types.ObjectDetail.from_proto(self._call("GetObject", request))

    def scene(self, session: str, completed: bool = False,
              timeout: Optional[float] = 600.0) -> Mesh:
        """A session's mesh in its world frame: as observed, or completed with the database's
        models placed where they were seen."""
        request = pb.GetSceneMeshRequest(session_name=session, completed=completed)
        try:
            chunks = self._stub.GetSceneMesh(request, timeout=timeout, metadata=self._metadata)
            return Mesh.concatenate(Mesh.from_proto(c.mesh) for c in chunks)
        except grpc.RpcError as e:
            raise _error(e, "GetSceneMesh") from None

    def match(self, cloud=None, *, normals=None, colors=None, viewpoint=None, depth=None,
              intrinsics: Optional[Intrinsics] = None, mask=None, pose=None,
              depth_scale: float = 0.001, object_id: Optional[int] = None,
              max_results: int = 10, timeout: Optional[float] = 600.0) -> types.MatchAnswer:
        """"What is this?" (Match): the stored objects a segment would merge with, with poses and
        evidence; nothing is written. Give one of
          cloud: N x 3 points (metres; normals N x 3 and colors N x 3 uint8 optional); a cloud
                 without normals is a sensor's, seen from viewpoint (default its origin), one
                 with normals is seen from all sides;
          depth: an H x W uint16 (depth_scale metres per unit) or float32 image with intrinsics,
                 mask (H x W, non-zero = the segment; default all) and pose (4 x 4
                 T_world_camera, default identity);
          object_id: a stored object ("find similar")."""
        given = [cloud is not None, depth is not None, object_id is not None]
        if sum(given) != 1:
            raise ValueError("match: give one of cloud, depth or object_id")
        request = pb.MatchRequest(max_results=max_results)
        if cloud is not None:
            points = np.asarray(cloud, dtype=np.float32)
            if points.ndim != 2 or points.shape[1] != 3:
                raise ValueError(f"match: cloud must be N x 3 (got shape {points.shape})")
            request.cloud.SetInParent()  # an empty cloud is still a cloud (the server says so)
            request.cloud.points.extend(points.ravel().tolist())
            if normals is not None:
                request.cloud.normals.extend(np.asarray(normals, np.float32).ravel().tolist())
            if colors is not None:
                request.cloud.colors = np.asarray(colors, np.uint8).tobytes()
            if viewpoint is not None:
                x, y, z = (float(v) for v in viewpoint)
                request.viewpoint.x, request.viewpoint.y, request.viewpoint.z = x, y, z
        elif depth is not None:
            if intrinsics is None:
                raise ValueError("match: a depth query needs its intrinsics")
            frame = frame_to_proto(Frame(depth=depth, pose=np.eye(4) if pose is None else pose),
                                   0, intrinsics, depth_scale)
            d = request.depth
            d.intrinsics.CopyFrom(intrinsics.to_proto())
            d.depth.CopyFrom(frame.depth)
            if pose is not None:
                d.T_world_camera.CopyFrom(frame.T_world_camera)
            if mask is not None:
                m = np.asarray(mask)
                if m.shape != (intrinsics.height, intrinsics.width):
                    raise ValueError(f"match: mask has shape {m.shape}, the intrinsics say "
                                     f"{(intrinsics.height, intrinsics.width)} (height, width)")
                d.mask = (m != 0).astype(np.uint8).tobytes()
        else:
            request.object_id = int(object_id)
        return types.MatchAnswer.from_proto(self._call("Match", request, timeout))

    def objects_in_region(self, session: str, box=None, ball=None,
                          include_structure: bool = False) -> List[types.PlacedObject]:
        """"What is here?" (ObjectsInRegion): the objects whose placement's centre lies in a box
        ((min xyz, max xyz)) or a ball ((centre xyz, radius)) of the session's world, metres."""
        if (box is None) == (ball is None):
            raise ValueError("objects_in_region: give a box or a ball")
        request = pb.ObjectsInRegionRequest(session_name=session,
                                            include_structure=include_structure)
        if box is not None:
            lo, hi = (np.asarray(c, dtype=float).reshape(3) for c in box)
            request.box.min.x, request.box.min.y, request.box.min.z = lo
            request.box.max.x, request.box.max.y, request.box.max.z = hi
        else:
            centre, radius = ball
            request.ball.centre.x, request.ball.centre.y, request.ball.centre.z = (
                float(v) for v in centre)
            request.ball.radius_m = float(radius)
        response = self._call("ObjectsInRegion", request)
        return [types.PlacedObject.from_proto(p) for p in response.placements]

    def changes(self, from_session: str, to_session: str,
                include_structure: bool = False) -> types.SessionChanges:
        """What changed between two sessions of one world (SessionChanges): objects added,
        removed, moved (no placement of the same object within 5 cm in the other session)."""
        request = pb.SessionChangesRequest(from_session=from_session, to_session=to_session,
                                           include_structure=include_structure)
        return types.SessionChanges.from_proto(self._call("SessionChanges", request))

    def stats(self) -> dict:
        """The server's statistics (GetStats) as a dict."""
        return types.to_dict(self._call("GetStats", pb.GetStatsRequest()))
