"""``groundstation bench``: a measuring tool beside the product, not part of it. Each kind of
figure has its module (core, campaigns, dashboard, overlay, recording, serve_start, sitl);
each imports only the parts of the product it measures, when it runs. ``docs_table`` and
``docs_pictures`` write the manual's benchmark page and pictures from them (run by hand:
``python -m groundstation.bench.docs_table``)."""

from .campaigns import run_campaign_bench
from .core import run_bench
from .dashboard import run_dashboard_bench
from .overlay import run_overlay_bench
from .recording import run_recording_bench
from .serve_start import run_serve_start_bench
from .sitl import run_sitl_bench

__all__ = [
    "run_bench",
    "run_campaign_bench",
    "run_dashboard_bench",
    "run_overlay_bench",
    "run_recording_bench",
    "run_serve_start_bench",
    "run_sitl_bench",
]
