"""`display_server`: the image streamed to a tev viewer, here a loopback listener that
decodes tev's packets (u32 length that counts itself, u8 type, fields) as tev does."""

import socket
import struct
import threading

import numpy as np
import pytest

import pcbpt
from conftest import CORNELL


class _Fields:
    """Reads a packet's fields in order."""

    def __init__(self, body: bytes):
        self.body = body

    def take(self, n: int) -> bytes:
        out, self.body = self.body[:n], self.body[n:]
        return out

    def u8(self) -> int:
        return self.take(1)[0]

    def u32(self) -> int:
        return struct.unpack("<I", self.take(4))[0]

    def u64(self) -> int:
        return struct.unpack("<Q", self.take(8))[0]

    def string(self) -> str:
        end = self.body.index(0)
        s = self.take(end).decode()
        self.take(1)
        return s


def _decode(stream: bytes) -> tuple[str, np.ndarray, int]:
    """The image's name, its last pixels (height × width × 3) and the count of updates."""
    name, image, updates = None, None, 0
    while stream:
        length = struct.unpack("<I", stream[:4])[0]
        f, stream = _Fields(stream[4:length]), stream[length:]
        kind = f.u8()
        if kind == 4:  # CreateImage: grab focus, name, width, height, channels, their names.
            f.u8()
            name = f.string()
            width, height = f.u32(), f.u32()
            assert [f.string() for _ in range(f.u32())] == ["R", "G", "B"]
            image = np.zeros((height, width, 3), np.float32)
        elif kind == 6:  # UpdateImage: grab focus, name, channels, x, y, w, h, offsets, strides.
            f.u8()
            assert f.string() == name and image is not None
            channels = [f.string() for _ in range(f.u32())]
            x, y, w, h = f.u32(), f.u32(), f.u32(), f.u32()
            offsets = [f.u64() for _ in channels]
            strides = [f.u64() for _ in channels]
            data = np.frombuffer(f.body, "<f4")
            for c, channel in enumerate(channels):
                values = data[offsets[c] + strides[c] * np.arange(w * h)]
                image[y : y + h, x : x + w, "RGB".index(channel)] = values.reshape(h, w)
            updates += 1
        else:
            raise AssertionError(f"packet type {kind}")
    return name, image, updates


def test_the_viewer_receives_the_rendered_image():
    scene = pcbpt.load(CORNELL, resx=70, resy=40, spp=4)
    listener = socket.create_server(("127.0.0.1", 0))
    received = bytearray()

    def viewer():
        connection, _ = listener.accept()
        with connection:
            while chunk := connection.recv(1 << 16):
                received.extend(chunk)

    thread = threading.Thread(target=viewer, daemon=True)
    thread.start()
    try:
        port = listener.getsockname()[1]
        image = pcbpt.render(scene, seed=3, threads=2, display_server=f"127.0.0.1:{port}")
        thread.join(timeout=60)
    finally:
        listener.close()
    assert not thread.is_alive() and received
    name, shown, updates = _decode(bytes(received))
    # The final image, sent whole in 64-pixel tiles (2 × 1 here), is the render's bit for bit.
    assert name == "scene.xml" and updates >= 2
    assert np.array_equal(shown, image)


def test_a_missing_viewer_leaves_the_render_and_a_bad_address_is_refused():
    scene = pcbpt.load(CORNELL, resx=8, resy=6, spp=2)
    closed = socket.create_server(("127.0.0.1", 0))
    port = closed.getsockname()[1]
    closed.close()
    image = pcbpt.render(scene, seed=1, threads=2, display_server=f"127.0.0.1:{port}")
    assert np.array_equal(image, pcbpt.render(scene, seed=1, threads=2))
    for bad in ["localhost", "localhost:0", ":14158"]:
        with pytest.raises(ValueError, match="display_server"):
            pcbpt.render(scene, display_server=bad)

