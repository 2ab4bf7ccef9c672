"""Figures of ``holonomic-analyze --plot DIR`` (matplotlib, headless).

Each function writes one PNG and returns its path. Planes are named by our
twist components (REP 103: vx forward, vy left, wz CCW); the paper's figures
use X = lateral (right), Y = forward, so its XY plane is our vy-vx, its
X-Phi plane our vy-wz and its Y-Phi plane our vx-wz.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the backend)
import numpy as np  # noqa: E402

from holonomic_analysis.mobility import AXIS_LABELS, SpeedSet  # noqa: E402

#: (axes, title) of the three planes, in the paper's order
PLANES = (((1, 0), "translation: vy-vx (paper: X-Y)"),
          ((1, 2), "lateral-rotation: vy-wz (paper: X-Phi)"),
          ((0, 2), "forward-rotation: vx-wz (paper: Y-Phi)"))


def _closed(poly: np.ndarray) -> np.ndarray:
    return np.vstack([poly, poly[:1]])


def _edges(speeds: SpeedSet, vertices: np.ndarray) -> list[tuple[int, int]]:
    """Edges of the speed polytope: vertex pairs sharing two facet planes."""
    values = vertices @ speeds.normalized.T                    # k x n
    active = [frozenset((i, int(np.sign(v[i])))
                        for i in np.nonzero(np.abs(np.abs(v) - 1.0) < 1e-7)[0])
              for v in values]
    edges = []
    for i in range(len(vertices)):
        for j in range(i + 1, len(vertices)):
            if len(active[i] & active[j]) >= 2:
                edges.append((i, j))
    return edges


def mobility_3d(speeds: SpeedSet, title: str, path: Path) -> Path:
    """Isometric view of the mobility ellipsoid inside the speed polytope."""
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    u, v = np.meshgrid(np.linspace(0, 2 * math.pi, 48), np.linspace(0, math.pi, 24))
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)])
    L = np.linalg.cholesky(speeds.ellipsoid_shape)
    ell = np.einsum("ij,jab->iab", L, sphere)
    ax.plot_surface(ell[0], ell[1], ell[2], color="tab:blue", alpha=0.35, linewidth=0)
    verts = speeds.vertices()
    for i, j in _edges(speeds, verts):
        ax.plot(*verts[[i, j]].T, color="0.3", linewidth=0.8)
    ax.set_xlabel(AXIS_LABELS[0])
    ax.set_ylabel(AXIS_LABELS[1])
    ax.set_zlabel(AXIS_LABELS[2])
    ax.set_title(title + "\nmobility ellipsoid (blue) in the joint-speed-limit polytope (lines)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def mobility_projections(speeds: SpeedSet, title: str, path: Path) -> Path:
    """Shadows and intersections of the ellipsoid and the polytope on the
    three coordinate planes (the paper's Figs. 7b, 8, 13b, 14)."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))
    for ax, (plane, name) in zip(axes, PLANES):
        shadow = _closed(speeds.shadow(plane))
        cut = _closed(speeds.intersection(plane))
        ax.fill(shadow[:, 0], shadow[:, 1], color="0.88", label="polytope shadow")
        ax.plot(cut[:, 0], cut[:, 1], color="0.35", linewidth=1.0,
                label="polytope intersection")
        es = speeds.ellipse(plane, "shadow")
        ei = speeds.ellipse(plane, "intersection")
        ax.plot(es[:, 0], es[:, 1], color="tab:blue", linestyle="--", label="ellipsoid shadow")
        ax.plot(ei[:, 0], ei[:, 1], color="tab:red", linewidth=1.5,
                label="ellipsoid intersection")
        ax.axhline(0.0, color="0.6", linewidth=0.5)
        ax.axvline(0.0, color="0.6", linewidth=0.5)
        ax.set_xlabel(AXIS_LABELS[plane[0]])
        ax.set_ylabel(AXIS_LABELS[plane[1]])
        ax.set_title(name, fontsize=10)
        if plane == (1, 0):
            ax.set_aspect("equal", adjustable="datalim")
    axes[0].legend(fontsize=8, loc="lower left")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def sweep_plot(rows: list[dict], key: str, title: str, path: Path) -> Path:
    """H_hat and the maximum speeds against the swept parameter."""
    x = [r["value"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
    ax1.plot(x, [r["H_hat"] for r in rows], marker="o", label="H_hat")
    ax1.plot(x, [r["sigma_ratio"] for r in rows], marker=".", linestyle=":",
             label="sigma_ratio")
    ax1.set_xlabel(key)
    ax1.set_ylim(0.0, 1.05)
    ax1.set_title("holonomicity")
    ax1.legend()
    for name in ("forward", "lateral", "lateral_constant_heading"):
        ax2.plot(x, [r["max_speed"][name] for r in rows], marker=".", label=f"{name} [m/s]")
    ax2.plot(x, [r["max_speed"]["rotation"] for r in rows], linestyle="--",
             label="rotation [rad/s]")
    ax2.set_xlabel(key)
    ax2.set_title("maximum speeds (joint speed limits)")
    ax2.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def isotropy_trajectory_plot(times, index, segments, title: str, path: Path) -> Path:
    """Isotropy index along a scripted trajectory, with the segment names."""
    fig, ax = plt.subplots(figsize=(10, 4.4))
    ax.plot(times, index)
    # Segment n is numbered above the plot at its start (names under the
    # axes): text inside the axes would cross the curve.
    for n, (start, _) in enumerate(segments, 1):
        ax.axvline(start, color="0.7", linewidth=0.6)
        ax.annotate(str(n), (start, 1.0), xycoords=("data", "axes fraction"),
                    xytext=(3, 2), textcoords="offset points", fontsize=8, color="tab:blue")
    ax.set_ylim(0.0, 1.05)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("isotropy index (best L)")
    ax.set_title(title, pad=14)
    fig.text(0.5, 0.01, "segment starts: " + "   ".join(
        f"{n} {name}" for n, (_, name) in enumerate(segments, 1)),
        ha="center", va="bottom", fontsize=8)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def measured_plot(measurement, title: str, path: Path) -> Path:
    """Move time against direction, one curve per heading change (polar)."""
    fig = plt.figure(figsize=(6, 6))
    ax = fig.add_subplot(projection="polar")
    # ±90 deg give the same times on a symmetric base: a style per curve
    # keeps a curve drawn over another visible
    styles = [("-", "o", 6), ("--", "s", 5), (":", "^", 5), ("-.", "D", 4)]
    for k, theta in enumerate(measurement.thetas):
        moves = [m for m in measurement.moves if m.theta == theta]
        a = [m.alpha for m in moves] + [moves[0].alpha]
        t = [m.seconds for m in moves] + [moves[0].seconds]
        line, marker, size = styles[k % len(styles)]
        ax.plot(a, t, linestyle=line, marker=marker, markersize=size,
                label=f"heading change {math.degrees(theta):g} deg: "
                      f"H = {measurement.h_of(theta):.2f}")
    ax.set_title(f"{title}\ntime [s] to move d_T = {measurement.distance:g} m, by direction",
                 fontsize=9)
    # below the polar axes, clear of the angle labels
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
