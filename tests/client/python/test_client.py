"""The Python client against a real objdb-server (conftest.py): streaming a dataset and arrays,
queries with known answers, and every bad input as a clear error."""

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time

import grpc
import numpy as np
import pytest

import objdb
from objdb.frames import Dataset


def stream_all(client, source, session, **kwargs):
    return list(client.stream(source, session=session, **kwargs))


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    pose = objdb.v1.objdb_pb2.Pose(qw=q[0], qx=q[1], qy=q[2], qz=q[3])
    return objdb.pose_to_matrix(pose)[:3, :3]


def test_poses_convert_both_ways():
    rng = np.random.default_rng(7)
    rotations = [random_rotation(rng) for _ in range(200)]
    # Half turns about each axis: the branches of the quaternion extraction without a large trace.
    rotations += [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]
    for R in rotations:
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = rng.normal(size=3)
        back = objdb.pose_to_matrix(objdb.matrix_to_pose(T))
        assert np.allclose(back, T, atol=1e-9)
    with pytest.raises(ValueError, match="not a rotation"):
        objdb.matrix_to_pose(np.diag([1.0, 1.0, 2.0, 1.0]))
    with pytest.raises(ValueError, match="4x4"):
        objdb.matrix_to_pose(np.eye(3))


def test_a_dataset_streams_and_its_objects_come_back_where_the_scene_saw_them(server, two_boxes,
                                                                              tmp_path):
    seen = []
    with objdb.Client(server.address) as db:
        events = stream_all(db, two_boxes, "boxes", progress=lambda a, t: seen.append((a, t)))
        acks = [e for e in events if isinstance(e, objdb.FrameAck)]
        assert len(acks) == 30 and all(a.accepted for a in acks)
        assert [a.index for a in acks] == list(range(30))
        assert acks[-1].counters["session"]["frames_integrated"] == 30  # an int, not "30"
        assert seen[-1] == (30, 30) and len(seen) == 30
        assert isinstance(events[-1], objdb.SessionEnded)
        assert events[-1].summary.state == "ended"
        # The segments still live at the end go in with EndSession: its summary counts them.
        assert isinstance(events[0], objdb.SessionOpened) and events[0].session == "boxes"
        assert not events[0].resumed and not events[0].replaced
        created = events[-1].summary.counters["objects_created"]
        assert isinstance(created, int)
        assert created >= 1, "the two boxes make at least one object"
        assert events[-1].summary.object_ids

        sessions = db.sessions()
        assert [(s.name, s.state) for s in sessions] == [("boxes", "ended")]
        assert sessions[0].intrinsics.width == 640

        objects = db.objects()
        assert objects and all(not o.structure for o in objects)
        everything = db.objects(whole_only=False)
        assert {o.id for o in objects} <= {o.id for o in everything}
        assert [o.id for o in db.objects(session="boxes")] == [o.id for o in objects]
        with pytest.raises(objdb.Error) as e:
            db.objects(session="nobody")
        assert e.value.code == grpc.StatusCode.NOT_FOUND and "nobody" in e.value.message

        scene = db.scene("boxes")
        assert len(scene.vertices) > 1000 and len(scene.faces) > 1000
        assert scene.faces.max() < len(scene.vertices)

        for summary in objects:
            o = db.object(summary.id)
            assert o.id == summary.id
            assert o.poses.shape == (summary.num_poses, 4, 4)
            R = o.poses[:, :3, :3]
            assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-6)
            assert o.pose_sessions == ["boxes"] * summary.num_poses
            assert o.cloud.points.shape[1] == 3 and len(o.cloud.points) > 50
            assert o.cloud.normals.shape == o.cloud.points.shape
            assert np.allclose(np.linalg.norm(o.cloud.normals, axis=1), 1.0, atol=1e-3)
            # The boxes are coloured: so is the cloud (issue 47: colors came as None).
            assert o.cloud.colors is not None and o.cloud.colors.shape == o.cloud.points.shape
            assert o.cloud.colors.dtype == np.uint8 and o.cloud.colors.max() > 0
            assert o.mesh.faces.max() < len(o.mesh.vertices)
            # Known answer: the model's cloud, placed at its pose, lies on the scene's surface.
            T = o.poses[0]
            sample = o.cloud.points[:: max(1, len(o.cloud.points) // 200)]
            world = sample @ T[:3, :3].T + T[:3, 3]
            d2 = ((world[:, None, :] - scene.vertices[None, ::4, :]) ** 2).sum(axis=2)
            assert np.median(np.sqrt(d2.min(axis=1))) < 0.02

            path = tmp_path / f"object-{o.id}.ply"
            o.mesh.save_ply(path)
            data = path.read_bytes()
            header, _, body = data.partition(b"end_header\n")
            assert f"element vertex {len(o.mesh.vertices)}".encode() in header
            assert f"element face {len(o.mesh.faces)}".encode() in header
            stride = 12 + (12 if o.mesh.normals is not None else 0) + \
                (3 if o.mesh.colors is not None else 0)
            assert len(body) == len(o.mesh.vertices) * stride + len(o.mesh.faces) * 13

        # "What is this?": an object's own cloud, moved, finds the object at the inverse pose;
        # nothing is written.
        o = db.object(objects[0].id, mesh=False)
        T = np.eye(4)
        T[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
        T[:3, 3] = [0.3, -0.2, 0.1]
        points = o.cloud.points @ T[:3, :3].T + T[:3, 3]
        normals = o.cloud.normals @ T[:3, :3].T
        answer = db.match(points, normals=normals, max_results=3)
        assert answer.matchable, answer.reason
        assert answer.results and answer.results[0].object_id == o.id
        best = answer.results[0]
        assert best.accepted, best.reason
        assert best.T_object_query.shape == (4, 4)
        assert best.evidence.tsdf_rmse_m <= 0.02
        # A box is symmetric: any of its turns is right; the surface must land on the model's.
        moved = points[::50] @ best.T_object_query[:3, :3].T + best.T_object_query[:3, 3]
        d2 = ((moved[:, None, :] - o.cloud.points[None, ::10, :]) ** 2).sum(axis=2)
        assert np.median(np.sqrt(d2.min(axis=1))) < 0.02
        assert [x.id for x in db.objects()] == [x.id for x in objects]
        assert db.match(object_id=o.id).candidates >= 0
        with pytest.raises(ValueError):
            db.match()
        with pytest.raises(objdb.Error) as e:
            db.match(np.zeros((0, 3)))
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert "cloud.points" in e.value.message
        with pytest.raises(objdb.Error) as e:
            db.match(object_id=987654)
        assert e.value.code == grpc.StatusCode.NOT_FOUND and "object_id" in e.value.message

        # "What is here?": the object's own place, a ball around its centre in the session.
        lo, hi = o.summary.bounds
        centre = o.poses[0][:3, :3] @ ((lo + hi) / 2) + o.poses[0][:3, 3]
        placed = db.objects_in_region("boxes", ball=(centre, 0.05))
        assert o.id in [p.object.id for p in placed]
        here = next(p for p in placed if p.object.id == o.id)
        assert np.allclose(here.centre, centre, atol=1e-6)
        assert here.T_world_object.shape == (4, 4)
        far = db.objects_in_region("boxes", box=(centre + 10, centre + 11))
        assert far == []
        with pytest.raises(objdb.Error) as e:
            db.objects_in_region("boxes", box=(centre + 1, centre))
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and "box.min" in e.value.message
        with pytest.raises(ValueError):
            db.objects_in_region("boxes")
        with pytest.raises(objdb.Error) as e:
            db.changes("boxes", "boxes")
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and "to_session" in e.value.message
        with pytest.raises(objdb.Error) as e:
            db.changes("boxes", "nobody")
        assert e.value.code == grpc.StatusCode.NOT_FOUND and "nobody" in e.value.message

        no_geometry = db.object(objects[0].id, mesh=False, cloud=False)
        assert no_geometry.mesh is None and no_geometry.cloud is None

        stats = db.stats()
        assert stats["insert_timings"]["inserts"] >= created


def plane_frames(n, width=64, height=48, depth_m=1.0, dtype=np.float32):
    frames = []
    for i in range(n):
        pose = np.eye(4)
        pose[0, 3] = 0.01 * i
        if dtype == np.uint16:
            depth = np.full((height, width), int(depth_m * 1000), np.uint16)
        else:
            depth = np.full((height, width), depth_m, np.float32)
        color = np.zeros((height, width, 3), np.uint8)
        color[..., 0] = 200
        frames.append(objdb.Frame(depth=depth, pose=pose, color=color, timestamp=0.1 * i))
    return frames


K = objdb.Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)


@pytest.mark.parametrize("dtype", [np.float32, np.uint16])
def test_numpy_frames_stream_as_float_or_scaled_integer_depth(server, dtype):
    with objdb.Client(server.address) as db:
        events = stream_all(db, plane_frames(5, dtype=dtype), f"plane-{dtype.__name__}",
                            intrinsics=K, depth_scale=0.001)
        acks = [e for e in events if isinstance(e, objdb.FrameAck)]
        assert [a.accepted for a in acks] == [True] * 5, [a.reason for a in acks]
        assert all(a.counters["valid_pixels"] == 64 * 48 for a in acks)
        assert events[-1].summary.state == "ended"


def wait_for_state(db, session, state, seconds=30):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        states = {s.name: s.state for s in db.sessions()}
        if states.get(session) == state:
            return True
        time.sleep(0.1)
    return False


def test_a_bad_frame_is_a_value_error_and_the_stream_is_cancelled_not_left_open(server):
    # The bad frame comes once the server has acknowledged the good ones, so that the session
    # exists when the stream is cancelled (else whether the header got there is a race).
    acked = threading.Event()

    def frames():
        good = plane_frames(3)
        yield good[0]
        yield good[1]
        acked.wait(60)
        good[2].depth = np.zeros((10, 10), np.float32)
        yield good[2]

    with objdb.Client(server.address) as db:
        with pytest.raises(ValueError, match=r"frame 2: depth has shape \(10, 10\)"):
            for event in db.stream(frames(), session="bad", intrinsics=K):
                if isinstance(event, objdb.FrameAck) and event.index == 1:
                    acked.set()
        assert wait_for_state(db, "bad", "interrupted")
        # Interrupted, not lost: EndSession still flushes what was integrated.
        assert db.end_session("bad").state == "ended"

        frames = plane_frames(3)
        frames[1].color = np.zeros((48, 64), np.uint8)
        with pytest.raises(ValueError, match="color must be uint8"):
            stream_all(db, frames, "bad-colour", intrinsics=K)
        with pytest.raises(ValueError, match="intrinsics"):
            stream_all(db, plane_frames(2), "no-intrinsics")


def test_a_broken_stream_is_resumed_and_an_ended_one_replaced(server, two_boxes):
    with objdb.Client(server.address) as db:
        # No session name: the dataset folder's, as `objdb stream` names it.
        events = db.stream(two_boxes)
        for event in events:
            if isinstance(event, objdb.FrameAck) and event.index == 9:
                break
        events.close()  # the client goes away
        assert wait_for_state(db, "two-boxes", "interrupted")
        with pytest.raises(objdb.Error, match="ALREADY_EXISTS") as taken:
            stream_all(db, two_boxes, None)
        assert "--resume" in str(taken.value) and "--replace" in str(taken.value)

        seen = []
        events = list(db.stream(two_boxes, resume=True, progress=lambda a, t: seen.append(t)))
        opened = events[0]
        assert isinstance(opened, objdb.SessionOpened) and opened.resumed
        assert opened.last_frame_index >= 9
        assert opened.counters["frames_integrated"] == opened.last_frame_index + 1
        acks = [e for e in events if isinstance(e, objdb.FrameAck)]
        assert [a.index for a in acks] == list(range(opened.last_frame_index + 1, 30))
        assert all(a.accepted for a in acks), [a.reason for a in acks]
        assert seen[-1] == len(acks)  # the progress total counts the frames sent
        assert events[-1].summary.counters["frames_integrated"] == 30

        with pytest.raises(objdb.Error, match="FAILED_PRECONDITION.*has ended"):
            stream_all(db, two_boxes, None, resume=True)
        events = stream_all(db, two_boxes, None, replace=True)
        assert events[0].replaced and events[0].segments_withdrawn >= 1
        assert events[-1].summary.counters["frames_integrated"] == 30
        names = [s.name for s in db.sessions()]
        assert names[-1] == "two-boxes" and names[0].startswith("two-boxes.replaced-")
        with pytest.raises(ValueError, match="exclude each other"):
            stream_all(db, two_boxes, None, resume=True, replace=True)
        with pytest.raises(ValueError, match="need a session name"):
            stream_all(db, plane_frames(2), None, intrinsics=K)


def test_a_stream_refused_before_its_first_frame_keeps_no_session(server):
    frames = plane_frames(3)
    frames[0].depth = np.zeros((10, 10), np.float32)
    with objdb.Client(server.address) as db:
        with pytest.raises(ValueError, match=r"frame 0: depth has shape"):
            stream_all(db, frames, "never", intrinsics=K)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and db.sessions():
            time.sleep(0.1)
        assert db.sessions() == []
        # The name is free.
        assert stream_all(db, plane_frames(2), "never", intrinsics=K)[-1].summary.state == "ended"


def test_stopping_early_cancels_the_stream(server, two_boxes):
    with objdb.Client(server.address) as db:
        events = db.stream(two_boxes, session="early")
        for event in events:
            if isinstance(event, objdb.FrameAck) and event.index == 3:
                break
        events.close()
        assert wait_for_state(db, "early", "interrupted")


def test_errors_carry_the_status_code_and_the_servers_message(server, two_boxes):
    with objdb.Client(server.address) as db:
        with pytest.raises(objdb.Error) as e:
            db.object(123456)
        assert e.value.code == grpc.StatusCode.NOT_FOUND
        assert "123456" in e.value.message
        with pytest.raises(objdb.Error) as e:
            db.scene("nobody")
        assert e.value.code == grpc.StatusCode.NOT_FOUND
        with pytest.raises(objdb.Error) as e:
            db.end_session("nobody")
        assert e.value.code == grpc.StatusCode.NOT_FOUND

        stream_all(db, two_boxes, "taken", every=10)
        with pytest.raises(objdb.Error) as e:
            stream_all(db, two_boxes, "taken", every=10)
        assert e.value.code == grpc.StatusCode.ALREADY_EXISTS
        with pytest.raises(objdb.Error) as e:
            stream_all(db, plane_frames(2), "bad name!", intrinsics=K)
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        with pytest.raises(objdb.Error) as e:
            stream_all(db, plane_frames(2), "bad-params", intrinsics=K,
                       params='{"tsdf": {"no_such_key": 1}}')
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert "no_such_key" in e.value.message

    port = server.address.rsplit(":", 1)[1]
    server.stop()
    with objdb.Client(f"127.0.0.1:{port}", timeout=5) as down:
        with pytest.raises(objdb.Error) as e:
            down.sessions()
        assert e.value.code in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED)


def test_a_token_server_needs_the_token(token_server):
    with objdb.Client(token_server.address) as anonymous:
        with pytest.raises(objdb.Error) as e:
            anonymous.sessions()
        assert e.value.code == grpc.StatusCode.UNAUTHENTICATED
        assert token_server.token not in str(e.value)
    with objdb.Client(token_server.address, token="wrong-token-0123456789") as wrong:
        with pytest.raises(objdb.Error) as e:
            wrong.sessions()
        assert e.value.code == grpc.StatusCode.UNAUTHENTICATED
    with objdb.Client(token_server.address, token=token_server.token) as db:
        assert db.sessions() == []
    with pytest.raises(ValueError, match="clear text"):
        objdb.Client("192.0.2.1:50051", token=token_server.token)


class _FakeOpen3d:
    """Records what to_open3d() hands to open3d (the test does not need open3d installed)."""

    class utility:
        Vector3dVector = staticmethod(lambda a: ("3d", np.asarray(a)))
        Vector3iVector = staticmethod(lambda a: ("3i", np.asarray(a)))

    class geometry:
        class PointCloud:
            def __init__(self, points):
                self.points, self.normals, self.colors = points, None, None

        class TriangleMesh:
            def __init__(self, vertices, triangles):
                self.vertices, self.triangles = vertices, triangles
                self.vertex_normals = self.vertex_colors = None


def test_clouds_and_meshes_hand_over_to_open3d(monkeypatch):
    cloud = objdb.PointCloud(np.array([[0, 0, 1], [1, 0, 1]], np.float32),
                             np.array([[0, 0, -1], [0, 0, -1]], np.float32),
                             np.array([[255, 0, 0], [0, 0, 255]], np.uint8))
    mesh = objdb.Mesh(cloud.points.copy(), np.array([[0, 1, 1]], np.uint32), None, cloud.colors)
    monkeypatch.setitem(sys.modules, "open3d", _FakeOpen3d)
    o = cloud.to_open3d()
    assert o.points[0] == "3d" and np.array_equal(o.points[1], cloud.points)
    assert np.array_equal(o.normals[1], cloud.normals)
    assert np.allclose(o.colors[1], [[1, 0, 0], [0, 0, 1]])
    m = mesh.to_open3d()
    assert m.triangles[0] == "3i" and m.triangles[1].tolist() == [[0, 1, 1]]
    assert m.vertex_normals is None and np.allclose(m.vertex_colors[1][1], [0, 0, 1])
    monkeypatch.setitem(sys.modules, "open3d", None)  # not installed
    with pytest.raises(ImportError, match="pip install open3d"):
        cloud.to_open3d()


def test_a_tum_folder_reads_as_the_same_frames_and_streams(server, two_boxes, tmp_path):
    """The two-boxes frames rewritten in TUM's layout: same images, poses and intrinsics."""
    tum = tmp_path / "tum"
    (tum / "depth").mkdir(parents=True)
    (tum / "rgb").mkdir()
    k = json.loads((two_boxes / "intrinsics.json").read_text())
    factor = 1.0 / k.pop("depth_scale_m")
    (tum / "intrinsics.json").write_text(json.dumps(k | {"depth_factor": factor}))
    poses = [l for l in (two_boxes / "poses.txt").read_text().splitlines() if not l.startswith("#")]
    depth_lines, rgb_lines, truth = [], [], []
    for i, line in enumerate(poses):
        t = 100.0 + i / 30.0
        name = f"{i:06d}.png"
        shutil.copy(two_boxes / "depth" / name, tum / "depth" / name)
        shutil.copy(two_boxes / "color" / name, tum / "rgb" / name)
        depth_lines.append(f"{t:.6f} depth/{name}")
        rgb_lines.append(f"{t + 0.005:.6f} rgb/{name}")
        if i != 7:  # frame 7 has no pose within 20 ms: skipped, as the C++ reader does
            truth.append(f"{t - 0.004:.6f} " + " ".join(line.split()[1:]))
    (tum / "depth.txt").write_text("# depth\n" + "\n".join(depth_lines) + "\n")
    (tum / "rgb.txt").write_text("# rgb\n" + "\n".join(rgb_lines) + "\n")
    (tum / "groundtruth.txt").write_text("# poses\n" + "\n".join(reversed(truth)) + "\n")

    ours, theirs = Dataset(two_boxes), Dataset(tum)
    assert (ours.layout, theirs.layout) == ("objdb", "tum")
    assert len(theirs) == 29
    a, b = ours.frame(8), theirs.frame(7)
    assert a.depth.data == b.depth.data and a.color.data == b.color.data
    assert a.depth.metres_per_unit == pytest.approx(b.depth.metres_per_unit)
    for field in ("x", "y", "z", "qx", "qy", "qz", "qw"):
        assert getattr(a.T_world_camera, field) == pytest.approx(getattr(b.T_world_camera, field),
                                                                abs=1e-9)
    with objdb.Client(server.address) as db:
        acks = [e for e in db.stream(tum, session="tum") if isinstance(e, objdb.FrameAck)]
        assert len(acks) == 29 and all(a.accepted for a in acks)


def test_bad_dataset_folders_are_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no dataset folder"):
        Dataset(tmp_path / "missing")
    with pytest.raises(ValueError, match="neither an objdb dataset"):
        Dataset(tmp_path)
    (tmp_path / "poses.txt").write_text("0 1 2 3\n")
    with pytest.raises(FileNotFoundError, match="intrinsics.json"):
        Dataset(tmp_path)
    (tmp_path / "intrinsics.json").write_text('{"width": 4}')
    with pytest.raises(ValueError, match="not valid intrinsics"):
        Dataset(tmp_path)
    (tmp_path / "intrinsics.json").write_text(
        '{"width": 4, "height": 3, "fx": 2, "fy": 2, "cx": 1.5, "cy": 1}')
    with pytest.raises(ValueError, match=r"poses.txt:1: expected .timestamp tx ty tz"):
        Dataset(tmp_path)


VANISHING_CLIENT = """
import sys, time
import numpy as np
import objdb
K = objdb.Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
def frames():
    for i in range(2):
        yield objdb.Frame(depth=np.full((48, 64), 1.5, np.float32), pose=np.eye(4),
                          timestamp=0.1 * i)
    time.sleep(3600)  # the stream stays open, and the process is stopped meanwhile
with objdb.Client(sys.argv[1]) as db:
    for event in db.stream(frames(), session="vanished", intrinsics=K):
        if isinstance(event, objdb.FrameAck) and event.index == 1:
            print("acked", flush=True)
"""


def test_a_client_that_vanishes_without_closing_its_connection_is_cut_off_by_keepalive(
        keepalive_server):
    # A client stopped with SIGSTOP sends nothing, not even a TCP reset: only the server's
    # HTTP/2 keepalive pings find it gone. The session is then interrupted (kept for EndSession).
    server = keepalive_server
    client = subprocess.Popen([sys.executable, "-c", VANISHING_CLIENT, server.address],
                              stdout=subprocess.PIPE, text=True, env=dict(os.environ))
    try:
        assert client.stdout.readline().strip() == "acked"
        with objdb.Client(server.address) as db:
            assert {s.name: s.state for s in db.sessions()}["vanished"] == "open"
            client.send_signal(signal.SIGSTOP)
            stopped = time.monotonic()
            assert wait_for_state(db, "vanished", "interrupted", seconds=30)
            print(f"\nkeepalive 0.5 s + timeout 0.5 s: the stopped client's session was "
                  f"interrupted {time.monotonic() - stopped:.2f} s after SIGSTOP")
            assert db.end_session("vanished").state == "ended"
    finally:
        client.kill()
        client.wait()
