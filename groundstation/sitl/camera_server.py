"""The SITL camera: a TCP server on loopback that streams rendered frames, each with its
capture time and its age at sending (the protocol is in :mod:`onboard.link.sitl_camera`).

Each client gets its own sender thread and a two-frame queue, so a slow or stalled client
loses old frames and never slows the simulation. Nothing a client sends is read as data.
"""

from __future__ import annotations

import contextlib
import queue
import socket
import threading

import numpy as np

from onboard.link.sitl_camera import pack_header


class CameraServer:
    def __init__(self, host: str = "127.0.0.1", port: int = 5600) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._sock.bind((host, port))
        self._sock.listen(4)
        self._sock.settimeout(0.2)
        self.address = self._sock.getsockname()
        self._clients: list[tuple[socket.socket, queue.Queue]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.sent = 0
        self.dropped = 0
        self._seq = 0
        threading.Thread(target=self._accept, name="camera-accept", daemon=True).start()

    @property
    def url(self) -> str:
        return f"sitl://{self.address[0]}:{self.address[1]}"

    @property
    def clients(self) -> int:
        with self._lock:
            return len(self._clients)

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            q: queue.Queue = queue.Queue(maxsize=2)
            with self._lock:
                self._clients.append((conn, q))
            threading.Thread(target=self._send_loop, args=(conn, q), daemon=True).start()
            threading.Thread(target=self._drain, args=(conn,), daemon=True).start()

    def _drain(self, conn: socket.socket) -> None:
        """Read and discard whatever a client sends, so it cannot fill our buffers."""
        with contextlib.suppress(OSError):
            while conn.recv(4096):
                pass

    def _send_loop(self, conn: socket.socket, q: queue.Queue) -> None:
        try:
            while not self._stop.is_set():
                try:
                    data = q.get(timeout=0.2)
                except queue.Empty:
                    continue
                conn.sendall(data)
                self.sent += 1
        except OSError:
            pass
        finally:
            with self._lock:
                self._clients = [(c, qq) for c, qq in self._clients if c is not conn]
            with contextlib.suppress(OSError):
                conn.close()

    def publish(self, image_bgr: np.ndarray, capture_time_s: float, age_s: float) -> None:
        h, w = image_bgr.shape[:2]
        self._seq += 1
        payload = np.ascontiguousarray(image_bgr, dtype=np.uint8).tobytes()
        data = pack_header(self._seq, w, h, capture_time_s, age_s) + payload
        with self._lock:
            clients = list(self._clients)
        for _, q in clients:
            if q.full():
                with contextlib.suppress(queue.Empty):
                    q.get_nowait()
                    self.dropped += 1
            with contextlib.suppress(queue.Full):
                q.put_nowait(data)

    def close(self) -> None:
        self._stop.set()
        with contextlib.suppress(OSError):
            self._sock.close()
        with self._lock:
            for c, _ in self._clients:
                with contextlib.suppress(OSError):
                    c.shutdown(socket.SHUT_RDWR)
                    c.close()
            self._clients = []
