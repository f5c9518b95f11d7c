"""A Foxglove WebSocket client for ``groundstation bench --sitl --foxglove``."""

from __future__ import annotations

import json


class FoxgloveClient:
    """A Foxglove WebSocket client in a thread: connects (retrying while ``onboard run``
    starts), subscribes to every advertised channel and counts the messages."""

    def __init__(self, port: int) -> None:
        import threading

        self.port = port
        self.messages = 0
        self._halt = threading.Event()
        self._thread = threading.Thread(target=self._run, name="foxglove-client", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from websockets.sync.client import connect

        while not self._halt.is_set():
            try:
                ws = connect(f"ws://127.0.0.1:{self.port}", subprotocols=["foxglove.sdk.v1"])
                break
            except OSError:
                self._halt.wait(0.2)
        else:
            return
        with ws:
            subscribed = 0
            while not self._halt.is_set():
                try:
                    data = ws.recv(timeout=0.2)
                except TimeoutError:
                    continue
                except Exception:  # the server stopped
                    return
                if isinstance(data, bytes):
                    self.messages += 1
                    continue
                msg = json.loads(data)
                if msg.get("op") == "advertise":
                    subs = [
                        {"id": subscribed + k, "channelId": c["id"]}
                        for k, c in enumerate(msg["channels"])
                    ]
                    subscribed += len(subs)
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def stop(self) -> None:
        self._halt.set()
        self._thread.join(timeout=2)
