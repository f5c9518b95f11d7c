"""The documentation's pictures, taken from the running dashboard (run by hand, not in CI).

``python -m groundstation.bench.docs_pictures [--out docs/img]`` starts a simulator-mode
ground station on a free port with a scratch data folder, drives it with Playwright (Debian's
chromium) and writes:

- ``dashboard.png``: the dashboard 4 s into a CV intercept;
- ``intercept.gif``: that intercept as it flies, from Start to the outcome;
- ``gains.png``: the gains panel with an edited value and the edits listed;
- ``sorties.png``: the Sorties page listing the recorded sorties;
- ``compare.png``: a recorded sortie replayed with a re-flown one overlaid (sortie B);
- ``studies.png``: the gain-studies panel with a small study stored by ``groundstation tune``.

Set ``PEREGRINE_JIT=0`` for a start in about a second.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHROMIUM_ARGS = ["--no-sandbox", "--enable-unsafe-swiftshader"]
VIEWPORT = {"width": 1440, "height": 960}
GIF_WIDTH_PX = 880  # the animation is scaled to this width: under 2 MB for a 6 s intercept
FRAME_S = 0.25  # sortie time between the animation's frames; it plays at 1x
DASHBOARD_AT_S = 4.0  # the dashboard's picture: mid-intercept, the target large in the image
CONTROL_PERIOD_S = 0.01  # one single-step of the dashboard (the scenarios' 100 Hz tick)
SCENE_SETTLE_S = 0.6  # the 3D view redraws at 2.5-5 Hz


def _gif(frames: list[bytes], path: Path) -> None:
    """Assemble PNG screenshots taken every FRAME_S of sortie time into a looping GIF that
    plays at 1x, holding the last (the outcome) for 2.5 s."""
    from PIL import Image

    images = []
    for png in frames:
        im = Image.open(io.BytesIO(png)).convert("RGB")
        h = round(im.height * GIF_WIDTH_PX / im.width)
        images.append(im.resize((GIF_WIDTH_PX, h), Image.LANCZOS))
    # one palette for every frame (no flicker), from a montage of frames across the sortie so
    # that colours only some frames show (the detection's orange, the plots' lines) keep theirs
    picks = [*images[:: max(1, len(images) // 6)], images[-1]]
    montage = Image.new("RGB", (GIF_WIDTH_PX, sum(im.height for im in picks)))
    y = 0
    for im in picks:
        montage.paste(im, (0, y))
        y += im.height
    palette = montage.quantize(colors=160, method=Image.Quantize.FASTOCTREE)
    quantized = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    durations = [round(1000 * FRAME_S)] * (len(quantized) - 1) + [2500]
    quantized[0].save(
        path,
        save_all=True,
        append_images=quantized[1:],
        duration=durations,
        loop=0,
        optimize=True,
    )


def _dismiss_notices(scene) -> None:
    """Close viser's notices (e.g. software WebGL) so they do not cover the 3D view."""
    from playwright.sync_api import Error as PlaywrightError

    buttons = scene.locator(".mantine-Notification-closeButton")
    for i in range(buttons.count()):
        # a notice already closing (hidden or sliding out) needs no click
        with contextlib.suppress(PlaywrightError):
            buttons.nth(i).click(timeout=2000)


def _small_study(data_dir: Path) -> None:
    """A two-trial study on one static target, stored where the ground station looks."""
    subprocess.run(
        [
            sys.executable,
            "-m",
            "groundstation",
            "tune",
            "static-ahead-20m",
            "--gains",
            "K_y,K_z",
            "--trials",
            "3",
            "--n",
            "1",
            "--workers",
            "1",
            "--study",
            "static-ahead-20m-png",
            "--data-dir",
            str(data_dir),
            "--out",
            str(data_dir / "tune"),
        ],
        check=True,
        stdout=subprocess.DEVNULL,
    )


def take(out: Path) -> list[Path]:
    """Take every picture into ``out``; return the files written."""
    from playwright.sync_api import sync_playwright

    from groundstation.app.server import GroundStation

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        raise SystemExit("docs_pictures: Debian's chromium is needed (apt-get install chromium)")
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    scratch = Path(tempfile.mkdtemp(prefix="peregrine-pictures-"))
    _small_study(scratch)
    gs = GroundStation(port=0, data_dir=scratch, log_dir=scratch / "logs")
    gs.start_in_thread()
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport=VIEWPORT)
            page.goto(gs.url())
            page.wait_for_selector("text=telemetry: live", timeout=60000)
            page.wait_for_function("document.querySelectorAll('#gains input').length > 5")
            scene = page.frame_locator("#viser")
            scene.locator("text=View").first.wait_for(timeout=60000)
            _dismiss_notices(scene)
            base = gs.url().split("?")[0]

            def start_paused(scenario: str) -> None:
                page.select_option("#scenario", scenario)
                page.select_option("#speed", "1")
                page.click("#btn-start")
                page.wait_for_function("window.peregrine.snap && window.peregrine.snap.t > 0")
                page.request.post(base + "api/sortie/pause")
                page.wait_for_selector("#st-state:has-text('paused')", timeout=30000)

            def advance(seconds: float) -> bool:
                """Step the paused sortie on by ``seconds``; True once it has ended."""
                for _ in range(round(seconds / CONTROL_PERIOD_S)):
                    status = page.request.post(base + "api/sortie/step").json()
                    if status["state"] != "paused":
                        break
                t = page.request.get(base + "api/status").json()["time_s"]
                page.wait_for_function(f"window.peregrine.shownT >= {t} - 1e-6", timeout=30000)
                time.sleep(SCENE_SETTLE_S)  # the 3D view redraws a few times a second
                return page.request.get(base + "api/status").json()["state"] != "paused"

            # the intercept, a frame every FRAME_S of sortie time; the dashboard's picture is
            # the frame at about 4 s, the target large in the image plane
            start_paused("cv-top-to-bottom")
            frames: list[bytes] = [page.screenshot()]
            while not advance(FRAME_S):
                frames.append(page.screenshot())
                if abs(len(frames) * FRAME_S - DASHBOARD_AT_S) < FRAME_S / 2:
                    (out / "dashboard.png").write_bytes(frames[-1])
                if len(frames) > 200:
                    raise SystemExit("docs_pictures: the sortie did not end")
            page.wait_for_function(
                "document.querySelector('#st-outcome').textContent.includes('miss')"
            )
            time.sleep(SCENE_SETTLE_S)
            frames.append(page.screenshot())
            _gif(frames, out / "intercept.gif")
            written += [out / "intercept.gif", out / "dashboard.png"]

            # an edited gain: bold amber in its row, listed with its time once applied
            start_paused("cv-top-to-bottom")
            advance(1.0)
            page.fill('#gains input[data-gain="K_y"]', "4")
            page.click("#btn-apply-gains")
            advance(0.5)
            page.wait_for_function(
                "document.querySelector('#gains-applied').textContent.includes('applied at t =')"
            )
            page.request.post(base + "api/sortie/resume")
            page.select_option("#speed", "max")
            page.wait_for_function(
                "document.querySelector('#st-outcome').textContent.includes('miss')",
                timeout=120000,
            )
            page.locator("#gains-panel").screenshot(path=str(out / "gains.png"))
            written.append(out / "gains.png")

            # the gain studies `groundstation tune` stored
            page.wait_for_selector("#trials tbody tr", timeout=30000)  # the first study shown
            time.sleep(1.0)
            page.locator("#studies-panel").screenshot(path=str(out / "studies.png"))
            written.append(out / "studies.png")

            # the Sorties page, then a re-fly with another law overlaid on the original
            page.goto(base + "sorties")
            page.wait_for_selector("#logs tr button", timeout=30000)
            page.select_option("#refly-law", "pg")
            page.select_option("#refly-speed", "max")
            row = page.locator("#logs tr", has_text="cv-top-to-bottom").last
            row.locator('button[data-act="refly"]').click()
            page.click("#refly-go")  # the form offers the recorded gains: fly them
            page.wait_for_selector("#cmp-legend:not(:empty)", timeout=60000)
            page.wait_for_function(
                "document.querySelector('#st-outcome').textContent.includes('miss')",
                timeout=120000,
            )
            _dismiss_notices(page.frame_locator("#viser"))
            time.sleep(2.0)
            page.screenshot(path=str(out / "compare.png"))
            written.append(out / "compare.png")
            page.goto(base + "sorties")  # the re-flown sortie listed with its lineage
            page.wait_for_function("document.querySelectorAll('#logs tbody tr').length >= 3")
            page.locator("main .panel").first.screenshot(path=str(out / "sorties.png"))
            written.append(out / "sorties.png")
            browser.close()
    finally:
        gs.stop()
        shutil.rmtree(scratch, ignore_errors=True)
    return written


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m groundstation.bench.docs_pictures")
    ap.add_argument("--out", type=Path, default=Path("docs/img"), help="folder (docs/img)")
    args = ap.parse_args(argv)
    for path in take(args.out):
        print(f"{path} ({path.stat().st_size / 1e3:.0f} kB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
