"""The onboard video as QGroundControl receives it: QGC's video widget (UDP h.264) is a
GStreamer pipeline, ``udpsrc`` with RTP H.264 caps -> ``rtph264depay`` -> ``h264parse`` -> a
decoder. The same elements, run by ``gst-launch-1.0``, decode our RTP stream here, frame by
frame. Runs where GStreamer is installed (Debian: ``apt-get install gstreamer1.0-tools
gstreamer1.0-plugins-good gstreamer1.0-plugins-bad gstreamer1.0-libav``), skipped elsewhere:
it is not in .ci/run (a clean install is 142 packages, 74 MB)."""

from __future__ import annotations

import re
import shutil
import socket
import subprocess
import threading
import time

import pytest

pytest.importorskip("av")

from onboard.runtime.video import H264RtpSender, VideoConfig

from .sitl_rig import free_port
from .test_video import H, W, _frame, _wait

ELEMENTS = ("udpsrc", "rtph264depay", "h264parse", "avdec_h264", "fakesink")
# QGroundControl's caps for a UDP h.264 source (payload 96, the 90 kHz RTP clock)
CAPS = "application/x-rtp,media=video,clock-rate=90000,encoding-name=H264,payload=96"


def _missing() -> str | None:
    if shutil.which("gst-launch-1.0") is None or shutil.which("gst-inspect-1.0") is None:
        return "GStreamer not installed (gst-launch-1.0)"
    for e in ELEMENTS:
        if subprocess.run(["gst-inspect-1.0", e], capture_output=True).returncode != 0:
            return f"GStreamer element {e} not installed"
    return None


pytestmark = pytest.mark.skipif(_missing() is not None, reason=str(_missing()))


def test_gstreamer_decodes_every_frame_of_our_rtp_stream():
    port = free_port(socket.SOCK_DGRAM)
    proc = subprocess.Popen(
        ["gst-launch-1.0", "-v", "udpsrc", f"port={port}", "address=127.0.0.1", f"caps={CAPS}",
         "!", "rtph264depay", "!", "h264parse", "!", "avdec_h264", "!",
         "fakesink", "silent=false", "sync=false"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True).start()
    frame_bytes = W * H * 3 // 2  # I420, what avdec_h264 hands on

    def decoded() -> int:
        return sum(f"chain   ******* (fakesink0:sink) ({frame_bytes} bytes" in ln for ln in lines)

    n = 60
    sender = H264RtpSender(VideoConfig(port=port, fps=30))
    try:
        # udpsrc has its socket once the pipeline plays
        assert _wait(lambda: any("Setting pipeline to PLAYING" in ln for ln in lines)), lines
        for k in range(n):
            assert sender.send(_frame(k), time.time())
            time.sleep(0.005)
        _wait(lambda: decoded() >= n)
    finally:
        sender.close()
        proc.terminate()
        proc.wait(10)
    text = "".join(lines)
    assert decoded() == n, text[-3000:]
    caps = re.search(r"h264parse0\.GstPad:src: caps = video/x-h264, (.*)", text)
    assert caps is not None and f"width=(int){W}, height=(int){H}" in caps.group(1)
    assert "profile=(string)constrained-baseline" in caps.group(1)  # no B-frames
