"""Debug images of the perception pass (matplotlib, written as PNG files)."""

from __future__ import annotations

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from perception.crop import plate_outline_px, work_volume_corners_W  # noqa: E402
from perception.geometry import project  # noqa: E402
from perception.grasps import CanDetection, FrameAnalysis  # noqa: E402
from scenes.scene import CanPose  # noqa: E402
from scenes.spec import SceneSpec  # noqa: E402

log = logging.getLogger(__name__)


def _label_image(labels: np.ndarray) -> np.ndarray:
    """An RGB picture of a label image: one colour per component, black background."""
    cmap = plt.get_cmap("tab10")
    out = np.zeros(labels.shape + (3,))
    for k in range(1, int(labels.max()) + 1):
        out[labels == k] = cmap((k - 1) % 10)[:3]
    return out


def _centroids(labels: np.ndarray) -> dict[int, tuple[float, float]]:
    out = {}
    for k in range(1, int(labels.max()) + 1):
        rows, cols = np.nonzero(labels == k)
        if rows.size:
            out[k] = (float(cols.mean()), float(rows.mean()))
    return out


def _closed(uv: np.ndarray) -> np.ndarray:
    return np.vstack([uv, uv[:1]])


def frame_figure(fa: FrameAnalysis, spec: SceneSpec, path: Path) -> None:
    """Raw image with the calibration outline, cropped image, colour mask, separated components."""
    im = fa.image
    fig, axes = plt.subplots(1, 4, figsize=(20, 4.6))
    axes[0].imshow(im.rgb)
    plate_uv = plate_outline_px(spec, K=im.K, X_WC=im.X_WC)
    axes[0].plot(*_closed(plate_uv).T, "c-", lw=1.5, label="plate top face")
    wv, _ = project(work_volume_corners_W(spec), K=im.K, X_WC=im.X_WC)
    top = wv[4:][[0, 1, 3, 2]]
    axes[0].plot(*_closed(top).T, "y--", lw=1.2, label="work volume top (can height)")
    axes[0].legend(loc="lower right", fontsize=8)
    axes[0].set_title(f"{im.name}: raw colour, projected plate outline")
    axes[1].imshow(fa.rgb_cropped)
    axes[1].set_title("cropped to the work volume (outside = empty)")
    axes[2].imshow(fa.mask, cmap="gray")
    axes[2].set_title(f"can mask ({int(fa.mask.sum())} px)")
    axes[3].imshow(_label_image(fa.components.eroded))
    for k, (u, v) in _centroids(fa.components.labels).items():
        axes[3].text(u, v, str(k), color="white", ha="center", va="center", fontsize=11, weight="bold")
    axes[3].set_title(f"components after min area + erosion: {fa.components.count}")
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def points_figure(
    fa: FrameAnalysis,
    detections: list[CanDetection] | tuple[CanDetection, ...],
    spec: SceneSpec,
    path: Path,
) -> None:
    """Back-projected points with normals: a 3D view and a top (xy) view of the vertical normals."""
    fig = plt.figure(figsize=(17, 6.5))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    cmap = plt.get_cmap("tab10")
    colors = np.array([cmap((k - 1) % 10)[:3] for k in fa.labels]) if fa.labels.size else np.zeros((0, 3))
    step = max(1, fa.p_W.shape[0] // 6000)
    p, c = fa.p_W[::step], colors[::step]
    ax3.scatter(p[:, 0], p[:, 1], p[:, 2], s=0.5, c=c)
    qstep = max(1, fa.p_W.shape[0] // 300)
    pq, nq, vq = fa.p_W[::qstep], fa.n_W[::qstep], fa.vertical[::qstep]
    L = 0.02
    for sel, col, lab in ((vq, "green", "vertical normal (kept)"), (~vq, "0.5", "other normal")):
        if sel.any():
            ax3.quiver(*pq[sel].T, *(nq[sel] * L).T, color=col, lw=0.6, label=lab)
    cx, cy, _ = spec.plate.center_m
    sx, sy = spec.plate.size_m[:2]
    z0 = spec.plate_top_z_m
    ax3.plot([cx - sx / 2, cx + sx / 2, cx + sx / 2, cx - sx / 2, cx - sx / 2],
             [cy - sy / 2, cy - sy / 2, cy + sy / 2, cy + sy / 2, cy - sy / 2], [z0] * 5, "k-", lw=1)
    ax3.set_xlabel("x [m]")
    ax3.set_ylabel("y [m]")
    ax3.set_zlabel("z [m]")
    ax3.set_zlim(z0, z0 + 0.2)
    ax3.set_box_aspect((sx + 0.04, sy + 0.04, 0.2))
    ax3.set_title(f"{fa.image.name} camera: back-projected can points, normals (every {qstep}th)")
    ax3.legend(loc="upper left", fontsize=8)

    ax = fig.add_subplot(1, 2, 2)
    ax.add_patch(plt.Rectangle((cx - sx / 2, cy - sy / 2), sx, sy, fill=False, ec="k", lw=1))
    ax.scatter(fa.p_W[~fa.vertical, 0], fa.p_W[~fa.vertical, 1], s=0.3, c="0.8")
    v = fa.vertical
    ax.scatter(fa.p_W[v, 0], fa.p_W[v, 1], s=0.5, c=colors[v])
    for d in detections:
        x, y, _ = d.p_WC_m
        ax.plot(x, y, "k+", ms=12, mew=2)
        if d.lying:
            a = np.array([np.cos(d.axis_yaw_rad), np.sin(d.axis_yaw_rad)]) * spec.can.height_m / 2
            ax.plot([x - a[0], x + a[0]], [y - a[1], y + a[1]], "k-", lw=1.5)
        kind = f"lying, yaw {np.degrees(d.axis_yaw_rad):+.1f} deg" if d.lying else "upright"
        ax.text(x + 0.01, y + 0.01, f"{d.id}: {kind}", fontsize=9)
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], ls="", marker="o", ms=5, color="0.8", label="can points, normal not vertical"),
        Line2D([], [], ls="", marker="o", ms=5, color=cmap(0), label="vertical normals (Algorithm 2), by component"),
        Line2D([], [], color="k", lw=1.5, label="fitted axis (TLS line) of a lying can"),
        Line2D([], [], ls="", marker="+", ms=10, mew=2, color="k", label="estimated centre"),
    ]
    ax.set_aspect("equal")
    ax.set_xlim(cx - sx / 2 - 0.02, cx + sx / 2 + 0.02)
    ax.set_ylim(cy - sy / 2 - 0.02, cy + sy / 2 + 0.02)
    ax.set_xlabel("world x [m]")
    ax.set_ylabel("world y [m]")
    ax.set_title("top view of the plate: the points each estimate rests on")
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def grasps_figure(
    fa: FrameAnalysis,
    detections: list[CanDetection] | tuple[CanDetection, ...],
    spec: SceneSpec,
    path: Path,
    truth: tuple[CanPose, ...] | None = None,
) -> None:
    """The grasps drawn over the top camera's image: finger closing line, approach, labels."""
    im = fa.image
    fig, ax = plt.subplots(figsize=(10, 7.8))
    ax.imshow(im.rgb)
    half = spec.grasp.open_width_m / 2
    for d in detections:
        X = d.grasp.X_WG
        # Drawn at the measured top of the can (the grasp itself is top_offset_m higher), so that
        # in the perspective image the line lies over the can's top face.
        p = np.array([X[0, 3], X[1, 3], d.top_z_m])
        # The fingers close along the gripper's x axis; its z axis points along a lying can's axis.
        ends = np.array([p - half * X[:3, 0], p + half * X[:3, 0]])
        zdir = np.array([p, p + 0.04 * X[:3, 2]])
        (e_uv, _), (z_uv, _) = project(ends, K=im.K, X_WC=im.X_WC), project(zdir, K=im.K, X_WC=im.X_WC)
        ax.plot(*e_uv.T, "-", color="lime", lw=3)
        ax.plot(*e_uv.T, "o", color="lime", ms=7)
        ax.annotate("", xy=z_uv[1], xytext=z_uv[0], arrowprops=dict(arrowstyle="->", color="cyan", lw=2))
        kind = f"lying {np.degrees(d.axis_yaw_rad):+.0f}°" if d.lying else "upright"
        ax.text(e_uv[1, 0] + 5, e_uv[1, 1], f"{d.id}: {kind}\ngrasp z {d.grasp.X_WG[2, 3]:.3f} m",
                color="white", fontsize=9, weight="bold",
                bbox=dict(facecolor="black", alpha=0.6, pad=1.5, lw=0))
    if truth:
        tops = [(*c.p_WC_m[:2], c.top_z_m(spec.can.radius_m, spec.can.height_m)) for c in truth]
        t_uv, _ = project(np.array(tops), K=im.K, X_WC=im.X_WC)
        ax.plot(*t_uv.T, "x", color="yellow", ms=9, mew=2)
    ax.plot([], [], "-o", color="lime", label=f"finger line (opening {spec.grasp.open_width_m * 1000:.0f} mm), drawn at the can top")
    ax.plot([], [], "-", color="cyan", label="gripper z axis (along a lying can)")
    if truth:
        ax.plot([], [], "x", color="yellow", label="true centre of the can top")
    ax.legend(loc="lower right", fontsize=9)
    ax.set_title(f"grasps from the {im.name} camera: {len(detections)} cans")
    ax.set_xticks([])
    ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def write_debug_images(
    out_dir: str | Path,
    *,
    frames: dict[str, FrameAnalysis],
    detections,
    spec: SceneSpec,
    grasp_camera: str,
    truth: tuple[CanPose, ...] | None = None,
) -> list[Path]:
    """Write every debug image into `out_dir`; returns the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fa in frames.items():
        p = out / f"{name}_segmentation.png"
        frame_figure(fa, spec, p)
        paths.append(p)
    fa = frames[grasp_camera]
    p = out / f"{grasp_camera}_points_normals.png"
    points_figure(fa, detections, spec, p)
    paths.append(p)
    p = out / f"{grasp_camera}_grasps.png"
    grasps_figure(fa, detections, spec, p, truth)
    paths.append(p)
    for p in paths:
        log.info("wrote %s", p)
    return paths
