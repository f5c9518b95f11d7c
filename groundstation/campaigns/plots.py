"""Campaign plots (PNG, matplotlib): trajectories, miss and image-error distributions, wind
and outdoor figures; one function per campaign, each returning the file names it wrote."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from onboard.enums import GuidanceLaw

from .definitions import WIND_SPEEDS_M_S
from .runner import SortieOutcome

LAW_COLOURS = {
    GuidanceLaw.PNG.value: "tab:red",
    GuidanceLaw.PG.value: "tab:blue",
    GuidanceLaw.IBVS.value: "tab:green",
    GuidanceLaw.APN.value: "tab:purple",
}
LAW_NAMES = {law.value: law.name for law in GuidanceLaw} | {GuidanceLaw.PNG.value: "PNG (proposed)"}
assert set(LAW_COLOURS) == set(LAW_NAMES)


def _laws_of(outcomes: list[SortieOutcome]) -> list[str]:
    seen: list[str] = []
    for o in outcomes:
        if o.labels["law"] not in seen:
            seen.append(o.labels["law"])
    return seen


def _first(outcomes, **labels) -> SortieOutcome | None:
    for o in outcomes:
        if all(o.labels.get(k) == v for k, v in labels.items()):
            return o
    return None


def _savefig(fig, out: Path, name: str, plots: list[str]) -> None:
    fig.tight_layout()
    fig.savefig(out / name, dpi=110)
    plt.close(fig)
    plots.append(name)


# ------------------------------------------------------------------------------- plots
def _plot_trajectories_3d(ax, outs: list[SortieOutcome], label_key: str = "law") -> None:
    for o in outs:
        tr = o.trace
        if not tr:
            continue
        v = np.array(tr["vehicle_pos_m"])
        tg = np.array(tr["target_pos_m"])
        law = o.labels["law"]
        ax.plot(
            v[:, 0],
            v[:, 1],
            v[:, 2],
            color=LAW_COLOURS.get(law, "k"),
            lw=1.0,
            label=LAW_NAMES.get(law, law) if label_key else None,
        )
        ax.plot(tg[:, 0], tg[:, 1], tg[:, 2], color="k", lw=0.8, ls="--")
        ax.scatter(*tg[-1], color="k", s=8)
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    ax.set_zlabel("z up (m)")
    _equal_axes(ax)


def _equal_axes(ax) -> None:
    """One metre is as long on every axis: trajectories in their true proportions."""
    lims = np.array([ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()])
    centre = lims.mean(axis=1)
    half = max(float((lims[:, 1] - lims[:, 0]).max()) / 2.0, 0.5)
    ax.set_xlim3d(centre[0] - half, centre[0] + half)
    ax.set_ylim3d(centre[1] - half, centre[1] + half)
    ax.set_zlim3d(max(centre[2] - half, 0.0), max(centre[2] - half, 0.0) + 2 * half)
    ax.set_box_aspect((1, 1, 1))


def _trajectory_panels(outcomes, laws, scenarios, grid, figsize, out: Path, plots) -> None:
    """trajectories_3d.png: one 3D panel per scenario with the first try of every law."""
    fig = plt.figure(figsize=figsize)
    for i, sc in enumerate(scenarios):
        ax = fig.add_subplot(*grid, i + 1, projection="3d")
        firsts = [_first(outcomes, scenario=sc, law=law, **{"try": 0}) for law in laws]
        _plot_trajectories_3d(ax, [o for o in firsts if o is not None])
        ax.set_title(sc)
        if i == 0:
            ax.legend(fontsize=7)
    _savefig(fig, out, "trajectories_3d.png", plots)


def _boxplot(ax, data: list[list[float]], labels: list[str], colours: list[str]) -> None:
    bp = ax.boxplot(data, patch_artist=True, showfliers=True)
    ax.set_xticks(range(1, len(labels) + 1), labels)
    for patch, c in zip(bp["boxes"], colours, strict=True):
        patch.set_facecolor(c)
        patch.set_alpha(0.5)


def _static_plots(outcomes, out: Path) -> list[str]:
    plots: list[str] = []
    laws = _laws_of(outcomes)
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    _plot_trajectories_3d(ax, [o for o in outcomes if o.labels["law"] == laws[0]], label_key="")
    ax.set_title(f"Static targets: {LAW_NAMES.get(laws[0], laws[0])} trajectories")
    _savefig(fig, out, "trajectories_3d.png", plots)

    fig, ax = plt.subplots(figsize=(6, 4))
    data = [[o.result["miss_m"] for o in outcomes if o.labels["law"] == law] for law in laws]
    _boxplot(
        ax,
        data,
        [LAW_NAMES.get(law, law) for law in laws],
        [LAW_COLOURS.get(law, "grey") for law in laws],
    )
    ax.set_ylabel("miss distance (m)")
    ax.set_yscale("log")
    ax.set_title("Static targets: miss distance (paper Fig. 5b)")
    _savefig(fig, out, "miss_boxplot.png", plots)

    fig, ax = plt.subplots(figsize=(6, 4.5))
    pts = np.array(
        [
            o.trace["initial_px"]
            for o in outcomes
            if o.labels["law"] == laws[0] and o.trace and o.trace["initial_px"]
        ]
    )
    if len(pts):
        ax.scatter(pts[:, 0], pts[:, 1], s=14, color="tab:red")
    ax.set_xlim(0, 640)
    ax.set_ylim(480, 0)
    ax.set_aspect("equal")
    ax.axhline(240, color="grey", lw=0.5)
    ax.axvline(320, color="grey", lw=0.5)
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.set_title("Initial target positions in the image (paper Fig. 5c)")
    _savefig(fig, out, "targets_image_plane.png", plots)

    fig, ax = plt.subplots(figsize=(5.5, 5))
    for law in laws:
        xs, ys = [], []
        for o in outcomes:
            if o.labels["law"] != law or not o.trace:
                continue
            rel = np.array(o.trace["closest_rel_m"])
            vel = np.array(o.trace["closest_vel_m_s"])
            n = vel / (np.linalg.norm(vel) or 1.0)
            right = np.cross(n, [0.0, 0.0, 1.0])
            right = right / (np.linalg.norm(right) or 1.0)
            up = np.cross(right, n)
            xs.append(float(rel @ right))
            ys.append(float(rel @ up))
        ax.scatter(xs, ys, s=14, label=LAW_NAMES.get(law, law), color=LAW_COLOURS.get(law))
    ax.add_patch(plt.Circle((0, 0), 0.15, fill=False, color="k", lw=0.8))
    ax.set_aspect("equal")
    ax.set_xlabel("right of flight path (m)")
    ax.set_ylabel("above flight path (m)")
    ax.legend()
    ax.set_title("Miss at closest approach (paper Fig. 5d); circle: target")
    _savefig(fig, out, "miss_scatter.png", plots)
    return plots


def _moving_plots(outcomes, out: Path) -> list[str]:
    plots: list[str] = []
    laws = _laws_of(outcomes)
    scenarios = list(dict.fromkeys(o.labels["scenario"] for o in outcomes))
    _trajectory_panels(
        outcomes, laws, scenarios, (1, len(scenarios)), (5 * len(scenarios), 4.5), out, plots
    )

    fig, axes = plt.subplots(2, len(scenarios), figsize=(5 * len(scenarios), 6), squeeze=False)
    for i, sc in enumerate(scenarios):
        for law in laws:
            o = _first(outcomes, scenario=sc, law=law, **{"try": 0})
            if not o or not o.trace:
                continue
            c = LAW_COLOURS.get(law)
            axes[0][i].plot(
                o.trace["t_s"],
                o.trace["normal_accel_m_s2"],
                color=c,
                label=LAW_NAMES.get(law, law),
                lw=1,
            )
            axes[1][i].plot(o.trace["t_s"], o.trace["normal_vel_m_s"], color=c, lw=1)
        axes[0][i].set_title(sc)
        axes[0][i].set_ylabel("normal acceleration (m/s²)")
        axes[1][i].set_ylabel("velocity normal to LOS (m/s)")
        axes[1][i].set_xlabel("time (s)")
    axes[0][0].legend(fontsize=8)
    _savefig(fig, out, "normal_accel_velocity.png", plots)

    fig, axes = plt.subplots(2, len(scenarios), figsize=(5 * len(scenarios), 6), squeeze=False)
    for i, sc in enumerate(scenarios):
        for j, comp in enumerate(("e_x / f", "e_y / f")):
            data = []
            for law in laws:
                vals = []
                for o in outcomes:
                    if o.labels["scenario"] == sc and o.labels["law"] == law and o.trace:
                        vals += [e[j] for e in o.trace["e_norm_upright"] if e is not None]
                data.append(vals or [math.nan])
            _boxplot(
                axes[j][i],
                data,
                [LAW_NAMES.get(law, law) for law in laws],
                [LAW_COLOURS.get(law, "grey") for law in laws],
            )
            axes[j][i].set_ylabel(f"normalised {comp}")
        axes[0][i].set_title(sc)
    _savefig(fig, out, "image_error_boxplot.png", plots)

    fig, axes = plt.subplots(1, len(scenarios), figsize=(5 * len(scenarios), 4), squeeze=False)
    for i, sc in enumerate(scenarios):
        data = [
            [
                o.result["miss_m"]
                for o in outcomes
                if o.labels["scenario"] == sc and o.labels["law"] == law
            ]
            for law in laws
        ]
        _boxplot(
            axes[0][i],
            data,
            [LAW_NAMES.get(law, law) for law in laws],
            [LAW_COLOURS.get(law, "grey") for law in laws],
        )
        axes[0][i].set_yscale("log")
        axes[0][i].set_ylabel("miss (m)")
        axes[0][i].set_title(sc)
    _savefig(fig, out, "miss_boxplot.png", plots)
    return plots


def _wind_plots(outcomes, summary, out: Path) -> list[str]:
    plots: list[str] = []
    laws = _laws_of(outcomes)
    fig, ax = plt.subplots(figsize=(6, 4))
    width = 0.8 / len(laws)
    for k, law in enumerate(laws):
        rates = [summary["cells"][str(w)][law]["success_rate"] * 100 for w in WIND_SPEEDS_M_S]
        ax.bar(
            np.arange(len(WIND_SPEEDS_M_S)) + k * width,
            rates,
            width,
            color=LAW_COLOURS.get(law),
            label=LAW_NAMES.get(law, law),
        )
    paper = [100 * summary["paper"][str(w)]["success"] for w in WIND_SPEEDS_M_S]
    ax.plot(
        np.arange(len(WIND_SPEEDS_M_S)) + 0.4 - width / 2,
        paper,
        "k*",
        ms=10,
        label="paper (proposed)",
    )
    ax.set_xticks(
        np.arange(len(WIND_SPEEDS_M_S)) + 0.4 - width / 2, [f"{w} m/s" for w in WIND_SPEEDS_M_S]
    )
    ax.set_ylabel("success rate (%)")
    ax.set_ylim(0, 105)
    ax.legend(fontsize=8)
    ax.set_title("Tethered balloon in wind (paper Table 2)")
    _savefig(fig, out, "success_rate.png", plots)

    law = GuidanceLaw.PNG.value if GuidanceLaw.PNG.value in laws else laws[0]  # the paper's law
    fig, axes = plt.subplots(1, 2, figsize=(9, 4))
    for j, comp in enumerate(("u", "v")):
        data = []
        for w in WIND_SPEEDS_M_S:
            vals = []
            for o in outcomes:
                if o.labels["wind_m_s"] == w and o.labels["law"] == law and o.trace:
                    vals += [e[j] for e in o.trace["e_norm_upright"] if e is not None]
            data.append(vals or [math.nan])
        _boxplot(axes[j], data, [f"{w} m/s" for w in WIND_SPEEDS_M_S], ["tab:red"] * 4)
        axes[j].set_ylabel(f"normalised {comp}")
    fig.suptitle(f"Image-plane error by wind speed, {LAW_NAMES.get(law, law)} (paper Fig. 18)")
    _savefig(fig, out, "image_error_boxplot.png", plots)
    _wind_miss_plot(outcomes, out, plots)
    return plots


def _outdoor_plots(outcomes, out: Path) -> list[str]:
    plots: list[str] = []
    laws = _laws_of(outcomes)
    scenarios = list(dict.fromkeys(o.labels["scenario"] for o in outcomes))
    cols = 2 if len(scenarios) <= 4 else 4
    rows = -(-len(scenarios) // cols)
    _trajectory_panels(outcomes, laws, scenarios, (rows, cols), (5 * cols, 4 * rows), out, plots)
    width = (4.5 if len(scenarios) <= 4 else 3.2) * len(scenarios)
    fig, axes = plt.subplots(2, len(scenarios), figsize=(width, 6), squeeze=False)
    for i, sc in enumerate(scenarios):
        for law in laws:
            o = _first(outcomes, scenario=sc, law=law, **{"try": 0})
            if not o or not o.trace:
                continue
            speed = np.linalg.norm(np.array(o.trace["vehicle_vel_m_s"]), axis=1)
            axes[0][i].plot(
                o.trace["t_s"],
                speed,
                color=LAW_COLOURS.get(law),
                lw=1,
                label=LAW_NAMES.get(law, law),
            )
            axes[1][i].plot(
                o.trace["t_s"], o.trace["normal_accel_m_s2"], color=LAW_COLOURS.get(law), lw=1
            )
        axes[0][i].set_title(sc)
        axes[0][i].set_ylabel("speed (m/s)")
        axes[1][i].set_ylabel("normal acceleration (m/s²)")
        axes[1][i].set_xlabel("time (s)")
    axes[0][0].legend(fontsize=8)
    _savefig(fig, out, "speed_normal_accel.png", plots)
    return plots


# ------------------------------------------------------------------------------- tables


# ------------------------------------------------------------------------------- envelope maps
def _heatmap(ax, values: np.ndarray, rows: list[str], cols: list[str], cmap, norm, fmt) -> None:
    im = ax.imshow(values, cmap=cmap, norm=norm, aspect="auto", origin="lower")
    ax.set_xticks(range(len(cols)), cols)
    ax.set_yticks(range(len(rows)), rows)
    for i in range(len(rows)):
        for j in range(len(cols)):
            v = values[i, j]
            if math.isfinite(v):
                ax.text(j, i, fmt(v), ha="center", va="center", fontsize=7)
    return im


def envelope_grid(summary, law: str, key: str) -> tuple[np.ndarray, list[str], list[str]]:
    """``summary["cells"][law]`` as an (elevation x azimuth) array of ``key`` (nan if None),
    with the row (elevation) and column (azimuth) labels in ascending order."""
    by_el = summary["cells"][law]
    rows = sorted(by_el, key=float)
    cols = sorted({az for by_az in by_el.values() for az in by_az}, key=float)
    grid = np.full((len(rows), len(cols)), math.nan)
    for i, el in enumerate(rows):
        for j, az in enumerate(cols):
            v = by_el[el].get(az, {}).get(key)
            if v is not None:
                grid[i, j] = v
    return grid, rows, cols


def _envelope_plots(summary, out: Path) -> list[str]:
    from matplotlib.colors import LogNorm, Normalize

    plots: list[str] = []
    laws = list(summary["cells"])
    fig, axes = plt.subplots(
        2, len(laws), figsize=(4.5 * len(laws) + 1.5, 10), squeeze=False, layout="constrained"
    )
    for k, law in enumerate(laws):
        ok, rows, cols = envelope_grid(summary, law, "success_rate")
        im = _heatmap(
            axes[0, k], 100 * ok, rows, cols, "RdYlGn", Normalize(0, 100), lambda v: f"{v:.0f}"
        )
        axes[0, k].set_title(f"{LAW_NAMES.get(law, law)}: HIT %")
        cep, _, _ = envelope_grid(summary, law, "cep_m")
        im2 = _heatmap(
            axes[1, k],
            np.clip(cep, 1e-4, 30),
            rows,
            cols,
            "viridis_r",
            LogNorm(1e-3, 3),
            lambda v: f"{v:.3f}" if v < 1 else f"{v:.1f}",
        )
        axes[1, k].set_title(f"{LAW_NAMES.get(law, law)}: CEP (m)")
        for r in range(2):
            axes[r, k].set_xlabel("azimuth from the nose (deg)")
            axes[r, k].set_ylabel("elevation from the nose (deg)")
    fig.colorbar(im, ax=axes[0, :].tolist(), shrink=0.8, label="HIT %")
    fig.colorbar(im2, ax=axes[1, :].tolist(), shrink=0.8, label="CEP (m, median miss)")
    fig.suptitle("Static envelope: targets 15-25 m away,\nvehicle flying forward at 2 m/s")
    fig.savefig(out / "envelope_map.png", dpi=110)
    plt.close(fig)
    plots.append("envelope_map.png")
    return plots


def _range_plots(outcomes, summary, out: Path) -> list[str]:
    from .maps import ZEM_LIMIT_M, acquisition, zem_series

    plots: list[str] = []
    cells = summary["cells"]
    ranges = sorted(cells, key=float)
    laws = _laws_of(outcomes)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    width = 0.8 / len(laws)
    x = np.arange(len(ranges))
    for k, law in enumerate(laws):
        hit = [100 * cells[r][law]["success_rate"] for r in ranges]
        acq = [100 * cells[r][law]["acquired_rate"] for r in ranges]
        axes[0].bar(x + k * width, hit, width, color=LAW_COLOURS.get(law), label=f"{law} HIT")
        axes[0].plot(x + k * width, acq, "kv", ms=6, label="acquired" if k == 0 else None)
    axes[0].set_xticks(x + 0.4 - width / 2, [f"{r} m" for r in ranges])
    axes[0].set_ylim(0, 105)
    axes[0].set_ylabel("%")
    axes[0].legend(fontsize=8)
    axes[0].set_title("Success and acquisition by initial range")
    palette = ("tab:blue", "tab:orange", "tab:purple", "tab:brown", "tab:olive", "tab:cyan")
    colours = {r: palette[i % len(palette)] for i, r in enumerate(ranges)}
    law = GuidanceLaw.PNG.value if GuidanceLaw.PNG.value in laws else laws[0]  # the paper's law
    for o in outcomes:
        if o.labels["law"] != law or not o.trace:
            continue
        acq = acquisition(o.trace)
        if acq is None:
            continue
        t, zem = zem_series(o.trace)
        keep = t >= acq[0]
        axes[1].semilogy(
            t[keep] - acq[0],
            np.maximum(zem[keep], 1e-3),
            color=colours[str(o.labels["range_m"])],
            lw=0.7,
            alpha=0.7,
        )
    for r in ranges:
        axes[1].plot([], [], color=colours[r], label=f"{r} m")
    axes[1].axhline(ZEM_LIMIT_M, color="k", ls="--", lw=0.8)
    axes[1].set_xlabel("time since acquisition (s)")
    axes[1].set_ylabel("zero-effort miss (m)")
    axes[1].legend(fontsize=8)
    axes[1].set_title(f"Predicted miss (ZEM) from true states, {LAW_NAMES.get(law, law)}")
    _savefig(fig, out, "range_zem.png", plots)
    return plots


def _wind_miss_plot(outcomes, out: Path, plots: list[str]) -> None:
    """Miss distance over wind speed, one box per law and speed (log scale)."""
    laws = _laws_of(outcomes)
    fig, ax = plt.subplots(figsize=(6, 4))
    width = 0.8 / len(laws)
    for k, law in enumerate(laws):
        data = [
            [
                max(o.result["miss_m"], 1e-4)
                for o in outcomes
                if o.labels["wind_m_s"] == w and o.labels["law"] == law
            ]
            or [math.nan]
            for w in WIND_SPEEDS_M_S
        ]
        bp = ax.boxplot(
            data,
            positions=np.arange(len(WIND_SPEEDS_M_S)) + k * width,
            widths=0.8 * width,
            patch_artist=True,
            showfliers=True,
        )
        for patch in bp["boxes"]:
            patch.set_facecolor(LAW_COLOURS.get(law, "grey"))
        ax.plot([], [], "s", color=LAW_COLOURS.get(law), label=LAW_NAMES.get(law, law))
    radii = {o.result["hit_radius_m"] for o in outcomes}
    if len(radii) == 1:
        ax.axhline(radii.pop(), color="k", ls="--", lw=0.8, label="hit radius")
    ax.set_yscale("log")
    ax.set_xticks(
        np.arange(len(WIND_SPEEDS_M_S)) + 0.4 - width / 2, [f"{w} m/s" for w in WIND_SPEEDS_M_S]
    )
    ax.set_ylabel("miss distance (m)")
    ax.legend(fontsize=8)
    ax.set_title("Miss over wind speed")
    _savefig(fig, out, "miss_by_wind.png", plots)
