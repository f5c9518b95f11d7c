"""``groundstation bench``: a measuring tool beside the product, not part of it. Each kind of
figure has its module (core, campaigns, dashboard, overlay, recording, sitl); each imports only the
parts of the product it measures, when it runs."""

from .campaigns import run_campaign_bench
from .core import run_bench
from .dashboard import run_dashboard_bench
from .overlay import run_overlay_bench
from .recording import run_recording_bench
from .sitl import run_sitl_bench

__all__ = [
    "run_bench",
    "run_campaign_bench",
    "run_dashboard_bench",
    "run_overlay_bench",
    "run_recording_bench",
    "run_sitl_bench",
]
