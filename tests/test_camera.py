"""Frame sources without a camera: video files, the emulated camera, frames over localhost TCP, lost cameras."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from pectoral_gym.hardware.vision.camera import (
    CameraLostError,
    EmulatedCamera,
    Frame,
    FrameServer,
    FrameSource,
    NetworkCamera,
    OpenCVCamera,
    VideoFileSource,
    open_source,
)
from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.scene import SceneConditions

FPS = 20.0
N_FRAMES = 6


@pytest.fixture
def video(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (64, 48))
    assert writer.isOpened()
    for index in range(N_FRAMES):
        writer.write(np.full((48, 64, 3), 30 * index + 20, np.uint8))  # brightness encodes the frame index
    writer.release()
    return path


def _index(frame):
    return round((frame.image.mean() - 20) / 30)


def test_video_file_frames_in_order_with_file_timing(video):
    source = open_source(str(video))
    assert isinstance(source, VideoFileSource) and isinstance(source, FrameSource)
    frames = [source.read() for _ in range(N_FRAMES)]
    assert [_index(frame) for frame in frames] == list(range(N_FRAMES))
    np.testing.assert_allclose(np.diff([frame.timestamp for frame in frames]), 1 / FPS)
    assert abs(frames[0].timestamp - time.monotonic()) < 5.0  # on the monotonic clock
    assert source.read() is None  # end of file
    source.close()
    source.close()
    assert source.read() is None


def test_video_file_loop_and_missing(video, tmp_path):
    source = VideoFileSource(video, loop=True)
    indices = [_index(source.read()) for _ in range(N_FRAMES + 2)]
    assert indices == [*range(N_FRAMES), 0, 1]
    source.close()
    with pytest.raises(FileNotFoundError):
        VideoFileSource(tmp_path / "nope.avi")


def test_opencv_camera_grabber_reports_the_end_as_lost(video):
    # VideoCapture opens files like devices: the grabber thread runs through the clip, then the source is lost
    camera = OpenCVCamera(str(video), read_timeout=0.5, stale_after=0.5)
    first = camera.read()
    assert first is not None and first.image.shape == (48, 64, 3)
    deadline = time.monotonic() + 3.0
    while camera.read() is not None and time.monotonic() < deadline:
        pass
    start = time.monotonic()
    assert camera.read() is None
    assert time.monotonic() - start < 0.7  # never hangs
    assert camera.lost and "no frame" in camera.lost_reason
    camera.close()
    camera.close()


def test_opencv_camera_that_does_not_exist_raises():
    with pytest.raises(CameraLostError, match="cannot open camera"):
        OpenCVCamera(97)


def test_emulated_camera_renders_the_pose_and_reports_loss():
    samples = iter([((1.0, 0.5, 0.0), 10.0), ((1.0, 0.5, 0.0), 10.0), None, ((1.2, 0.5, 0.0), 10.1)])
    camera = EmulatedCamera(lambda: next(samples), conditions=SceneConditions.clean(), seed=0)
    frame = camera.read()
    assert frame.timestamp == 10.0 and frame.image.shape == (360, 640, 3)
    assert camera.read() is None  # same time stamp: no new frame
    assert camera.read() is None  # pose_fn lost
    moved = camera.read()
    assert moved.timestamp == 10.1 and np.any(moved.image != frame.image)
    camera.close()
    assert camera.read() is None


def _wait_for(source, timeout=3.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        frame = source.read()
        if frame is not None:
            return frame
    return None


@pytest.mark.parametrize("encoding", ["bmp", "png"])
def test_network_camera_over_localhost_is_lossless_and_keeps_timestamps(encoding):
    server = FrameServer(port=0, encoding=encoding)
    client = open_source(server.spec)
    assert isinstance(client, NetworkCamera)
    try:
        image = np.random.default_rng(0).integers(0, 256, (36, 64, 3), dtype=np.uint8)
        deadline = time.monotonic() + 3.0
        while client.frames_received == 0 and time.monotonic() < deadline:
            server.publish(Frame(image, 123.25))  # until the client has connected
            time.sleep(0.05)
        frame = _wait_for(client)
        assert frame is not None and frame.timestamp == 123.25
        np.testing.assert_array_equal(frame.image, image)
        # newest only: after a burst the client hands out the last frame, then nothing new
        for k in range(5):
            server.publish(Frame(np.full((36, 64, 3), k, np.uint8), 200.0 + k))
        seen = []
        deadline = time.monotonic() + 3.0
        while (not seen or seen[-1].timestamp < 204.0) and time.monotonic() < deadline:
            frame = client.read()
            if frame is not None:
                seen.append(frame)
        assert seen[-1].timestamp == 204.0 and seen[-1].image.max() == 4
        stamps = [frame.timestamp for frame in seen]
        assert stamps == sorted(set(stamps))  # never an old or repeated frame
        assert client.read() is None
    finally:
        client.close()
        server.close()
        server.close()


def test_network_camera_reports_a_lost_server_without_hanging():
    server = FrameServer(EmulatedCamera(lambda: ((1.0, 0.5, 0.0), time.monotonic()), seed=0), fps=20)
    client = NetworkCamera(server.host, server.port, read_timeout=0.1, stale_after=0.4)
    try:
        assert _wait_for(client) is not None
        server.close()
        time.sleep(0.6)
        start = time.monotonic()
        assert client.read() is None
        assert time.monotonic() - start < 0.3
        assert client.lost and client.lost_reason
    finally:
        client.close()
        server.close()


def test_open_source_rejects_unknown_specs():
    with pytest.raises(ValueError, match="emu://HOST:PORT"):
        open_source("emu://localhost")
    with pytest.raises(ValueError, match="not a camera index"):
        open_source("no/such/file.avi")


def test_frame_server_arguments():
    with pytest.raises(ValueError, match="encoding"):
        FrameServer(encoding="gif")
    assert CameraModel.default().width == 640


def test_the_default_camera_model_is_one_shared_immutable_model():
    from pectoral_gym.hardware.vision.cameramodel import CameraModel

    model = CameraModel.default()
    assert CameraModel.default() is model  # what is cached per model (the renderer's tables) is made once
    corners = [[22.0, 338.0], [618.0, 338.0], [604.0, 26.0], [36.0, 26.0]]
    fresh = CameraModel.from_corners(640, 360, corners)
    assert (model.width, model.height) == (640, 360) and np.array_equal(model.homography, fresh.homography)
    assert not model.homography.flags.writeable and not model.inverse.flags.writeable  # nobody can change it
