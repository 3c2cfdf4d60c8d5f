"""Bird's-eye previews: what the static and the dynamic ground plane do to an inverse perspective image.

:func:`synthetic_preview`: a simulated drive seen by a KITTI camera (lane markings and a
grid on the true road, :func:`~imu_ground.evaluation.simulate.camera.render_road`), the
default method's planes beside the static and the true ones, and the lane-width error
against distance. :func:`images_preview`: a user's images with an estimate of their log.
:func:`render_preview`: one picture a frame (matplotlib), a PNG (the lane-width errors as
JSON in its :data:`PNG_KEY` text chunk) or an animated GIF (Pillow).
"""
from __future__ import annotations

import io
import json
import math
import textwrap
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.errors import ImuGroundError, OptionError
from imu_ground.evaluation.ground_effect import LANE_WIDTH, ground_errors
from imu_ground.evaluation.lidar import read_times
from imu_ground.evaluation.simulate import SpeedParams, simulate
from imu_ground.evaluation.simulate.camera import render_road
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.methods import METHODS, default_method
from imu_ground.imu import imu_to_egomotion
from imu_ground.perception.camera import Camera, load_camera
from imu_ground.perception.plane import BevGrid, GroundPlane
from imu_ground.perception.warp import warp_to_bev

__all__ = ["DRAWN_BEV_PIXELS", "PREVIEW_GRID", "PNG_KEY", "Preview", "drawn_grid", "images_preview",
           "read_preview_errors", "render_preview", "synthetic_preview"]

#: Default bird's-eye grid: 5-45 m ahead, 7 m either side, 5 cm a pixel.
PREVIEW_GRID = BevGrid(5.0, 45.0, -7.0, 7.0, 0.05)
#: PNG text key under which the plotted lane-width errors are stored (JSON).
PNG_KEY = "lane_width_error"
#: Distances of the lane-width plot, m.
PLOT_DISTANCES = np.arange(5.0, 60.01, 2.5)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm")
#: Most pixels a side of a drawn bird's-eye view (:func:`drawn_grid`): bounds memory and time whatever the grid.
DRAWN_BEV_PIXELS = 1200


@dataclass
class Preview:
    """Frames to draw: their camera images (or a way to render them) and planes.

    Attributes
    ----------
    camera : Camera
    planes : dict of str to GroundPlane
        ``"static"``, ``"dynamic"`` and, for a simulation, ``"truth"``: one plane per frame.
    times : ndarray (F,)
        s.
    image : callable
        ``image(i)`` -> uint8 (height, width, 3) camera image of frame ``i``.
    lane_error : dict, optional
        ``distance_m`` and per plane name the mean absolute lane-width error, m (simulation only).
    title : str
    labels : list of str
        One caption per frame.
    lanes : bool
        Draw the true lane lines (``+- LANE_WIDTH / 2``) (simulation only).
    readings : dict of str to list of str
        Per plane name, one caption a frame.
    marks : ndarray (F, 2), optional
        Per frame, a road point ``(x, y)`` (m, ahead and left) crossed on every bird's-eye view.
    """
    camera: Camera
    planes: dict
    times: np.ndarray
    image: Any
    lane_error: dict | None = None
    title: str = ""
    labels: list = field(default_factory=list)
    lanes: bool = False
    readings: dict = field(default_factory=dict)
    marks: Any = None


def synthetic_preview(seed: int = 3, duration: float = 40.0, frames: int = 1, grid: BevGrid = PREVIEW_GRID,
                      camera: str | Camera = "kitti_cam2") -> Preview:
    """A simulated drive seen by a KITTI camera 2, estimated with the default method.

    Parameters
    ----------
    seed, duration : int, float
        The drive (urban style, navigation-grade IMU).
    frames : int
        Frames to show, centred on the moving frame with the largest true pitch.
    grid, camera : BevGrid, str or Camera

    Returns
    -------
    Preview
        With ``lane_error`` over every frame above 3 m/s (None if no frame is).
    """
    cam = load_camera(camera)
    sim = simulate(duration, seed=seed, imu="nav", speed=SpeedParams(style="urban"), name="preview")
    em = imu_to_egomotion(sim.imu, rate=10.0)
    spec = METHODS[default_method(True)]
    track = spec.make(extrinsic=Extrinsic(sim.R_gs, sim.t_gs)).run(em, smooth=bool(spec.smooth))
    tr = sim.truth
    idx = np.clip(np.searchsorted(tr["t"].to_numpy(), em.t - 1e-6), 0, len(tr) - 1)
    truth = tr.iloc[idx].reset_index(drop=True)
    moving = (truth["speed"].to_numpy() > 3.0) & em.valid
    n = len(em)
    planes = {"static": GroundPlane.from_pitch_roll(cam, np.zeros(n), np.zeros(n)),
              "dynamic": GroundPlane.from_pitch_roll(cam, track.pitch, track.roll),
              "truth": GroundPlane.from_pitch_roll(cam, truth["pitch"].to_numpy(), truth["roll"].to_numpy())}
    lane = {"distance_m": PLOT_DISTANCES.tolist()} if moving.any() else None     # (none: a drive too short to move)
    for name in ("static", "dynamic") if lane else ():
        assert lane is not None
        err = ground_errors(planes["truth"][moving], planes[name][moving], PLOT_DISTANCES, LANE_WIDTH)
        lane[name] = np.nanmean(np.abs(err["lane_width"]), axis=0).tolist()
    pitch = np.where(moving, np.abs(truth["pitch"].to_numpy()), -1.0)
    centre = int(np.argmax(pitch))
    first = int(np.clip(centre - frames // 2, 0, max(n - frames, 0)))
    sel = np.arange(first, min(first + max(int(frames), 1), n))
    s = truth["s"].to_numpy()
    planes = {k: p[sel] for k, p in planes.items()}
    labels = [f"t = {em.t[i]:.1f} s, {truth['speed'].iloc[i] * 3.6:.0f} km/h, true pitch "
              f"{math.degrees(truth['pitch'].iloc[i]):+.2f} deg, roll {math.degrees(truth['roll'].iloc[i]):+.2f} deg, "
              f"estimate {math.degrees(track.pitch[i]):+.2f} / {math.degrees(track.roll[i]):+.2f} deg" for i in sel]

    def image(k: int) -> np.ndarray:
        return render_road(planes["truth"][k], cam.image_size, travelled=float(s[sel[k]]))

    return Preview(cam, planes, em.t[sel], image, lane,
                   f"synthetic drive (seed {seed}), camera {cam.name}: bird's-eye views, method "
                   f"{default_method(True)}", labels, lanes=True)


def _read_image(path: Path, camera: Camera) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError
    try:
        with Image.open(path) as im:
            img = np.asarray(im.convert("RGB"))
    except (UnidentifiedImageError, OSError, ValueError) as e:
        raise ImuGroundError(f"{path}: unreadable image ({' '.join(str(e).split())}); give --images a folder of "
                             f"PNG or JPEG files") from None
    if (img.shape[1], img.shape[0]) != tuple(camera.image_size):
        raise ImuGroundError(f"{path}: image is {img.shape[1]}x{img.shape[0]} pixels but camera {camera.name} is "
                             f"{camera.image_size[0]}x{camera.image_size[1]}; give --camera the camera that took it")
    return img


def images_preview(images: str | Path, times: str | Path, camera: str | Camera, t: Any, dynamic: GroundPlane,
                   pitch: Any = None, roll: Any = None, title: str = "") -> Preview:
    """A user's images with the planes of an estimate (the frame nearest each image's time).

    Parameters
    ----------
    images, times : str or Path
        Folder of the camera's images (in name order) and one time a line for each (s, the log's clock).
    camera : str or Camera
        :func:`~imu_ground.perception.load_camera`.
    t, dynamic : array_like (N,), GroundPlane
        The estimate's frame times (s) and planes (``estimate_log(..., camera=...).meta["plane"]``).
    pitch, roll : array_like (N,), optional
        The estimate's angles, rad, for the captions.
    title : str

    Raises
    ------
    ImuGroundError, FileNotFoundError
        One line naming the file: unreadable or wrong-size image, a bad times file, counts that differ.
    """
    folder, times_path = Path(images), Path(times)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no such folder (--images: the folder of the camera's images)")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise ImuGroundError(f"{folder}: no image ({', '.join(IMAGE_SUFFIXES)}) in the folder (--images)")
    t_img, linenos = read_times(times_path)
    if len(t_img) != len(files):
        raise ImuGroundError(f"{times_path}: {len(t_img)} times for {len(files)} images in {folder}; give --times one "
                             "line per image, in the images' name order")
    t = np.asarray(t, dtype=float)
    step = float(np.nanmedian(np.diff(t))) if len(t) > 1 else 0.1
    lo, hi = float(t[0]) - step, float(t[-1])
    bad = np.flatnonzero((t_img < lo) | (t_img > hi))
    if bad.size:
        i = int(bad[0])
        raise ImuGroundError(f"{times_path}:{linenos[i]}: time {t_img[i]:g} s ({files[i].name}) is outside the "
                             f"log's frames ({lo:g} .. {hi:g} s on the log's clock); give --times on the log's clock")
    back = np.flatnonzero(np.diff(t_img) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise OptionError(f"{times_path}:{linenos[i]}: time {t_img[i]:g} s is before the one above it "
                          f"({t_img[i - 1]:g} s); give {{opt}} the images' times in their name order, increasing",
                          "times")
    cam = load_camera(camera)
    for f in files:
        _read_image(f, cam)                         # every image readable and of the camera's size before drawing
    nearest = np.clip(np.searchsorted(t, t_img), 0, len(t) - 1)
    nearest = np.where((nearest > 0) & (np.abs(t[nearest - 1] - t_img) < np.abs(t[nearest] - t_img)),
                       nearest - 1, nearest)
    n = len(t)
    planes = {"static": GroundPlane.from_pitch_roll(cam, np.zeros(n), np.zeros(n))[nearest],
              "dynamic": dynamic[nearest]}
    if pitch is not None and roll is not None:
        p, r = np.degrees(np.asarray(pitch)[nearest]), np.degrees(np.asarray(roll)[nearest])
        labels = [f"{f.name}: t = {ti:.2f} s, estimate pitch {_deg(a)} deg, roll {_deg(b)} deg"
                  for f, ti, a, b in zip(files, t_img, p, r, strict=True)]
    else:
        labels = [f"{f.name}: t = {ti:.2f} s" for f, ti in zip(files, t_img, strict=True)]
    return Preview(cam, planes, t_img, lambda k: _read_image(files[k], cam), title=title, labels=labels)


def drawn_grid(grid: BevGrid) -> BevGrid:
    """``grid``, or above :data:`DRAWN_BEV_PIXELS` pixels a side its extent coarser by the smallest whole factor."""
    factor = math.ceil(max(grid.shape) / DRAWN_BEV_PIXELS)
    if factor <= 1:
        return grid
    return BevGrid(grid.x0, grid.x1, grid.y0, grid.y1, grid.res * factor)


def _deg(value: float) -> str:
    """A caption's angle, deg (``nan`` as the output table writes it)."""
    return "nan" if math.isnan(value) else f"{value:+.2f}"


def _figure(preview: Preview, k: int, grid: BevGrid):
    from matplotlib.figure import Figure
    img = preview.image(k)
    names = [n for n in ("static", "dynamic", "lidar", "truth") if n in preview.planes]
    panels = len(names) + (preview.lane_error is not None)
    fig = Figure(figsize=(3.2 * panels + 0.5, 9.0), dpi=100)
    gs = fig.add_gridspec(2, panels, height_ratios=[1.0, 2.6], hspace=0.25, wspace=0.3)
    ax = fig.add_subplot(gs[0, :])
    ax.imshow(img)
    ax.set_title("camera view" + (f": {preview.labels[k]}" if preview.labels else ""), fontsize=9)
    ax.set_axis_off()
    what = {"static": "static extrinsic", "dynamic": "dynamic (estimate)", "lidar": "LiDAR plane", "truth": "truth"}
    lanes = 0.5 * LANE_WIDTH
    grid = drawn_grid(grid)
    for j, name in enumerate(names):
        plane = preview.planes[name]
        finite = np.all(np.isfinite(plane.rotation[k]))
        bev = warp_to_bev(img, plane.from_bev(grid)[k], grid) if finite else np.zeros(grid.shape + (3,), np.uint8)
        a = fig.add_subplot(gs[1, j])
        a.imshow(bev, extent=(grid.y1, grid.y0, grid.x0, grid.x1), aspect="equal")
        for y in ((-lanes, lanes) if preview.lanes else ()):
            a.axvline(y, color="red", lw=0.7, ls="--")
        if preview.marks is not None and np.all(np.isfinite(preview.marks[k])):
            a.plot(preview.marks[k][1], preview.marks[k][0], "x", color="red", ms=9, mew=2)
        reading = preview.readings.get(name)
        a.set_title(f"bird's-eye, {what[name]}" + (f"\n{reading[k]}" if reading else ""), fontsize=9)
        a.set(xlabel="left (m)", ylabel="ahead (m)" if j == 0 else "")
    if preview.lane_error is not None:
        a = fig.add_subplot(gs[1, -1])
        d = preview.lane_error["distance_m"]
        for name, style in (("static", "C3-"), ("dynamic", "C0-")):
            a.plot(d, preview.lane_error[name], style, label=what[name])
        a.set(xlabel="distance ahead (m)", ylabel="mean |lane-width error| (m)")
        a.set_title("lane-width error (moving frames)", fontsize=9)
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    title = preview.title + ("; red dashes: the true lane lines" if preview.lanes else "")
    fig.suptitle("\n".join(textwrap.wrap(title, width=int(13 * fig.get_figwidth()))), fontsize=10)
    return fig


def render_preview(preview: Preview, fmt: str = "png", grid: BevGrid = PREVIEW_GRID, fps: float = 5.0) -> bytes:
    """The preview drawn: a PNG of its first frame (the lane-width errors in its :data:`PNG_KEY` chunk), or
    (``fmt="gif"``) an animation of all its frames."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image
    if fmt not in ("png", "gif"):
        raise ValueError(f"unknown preview format {fmt!r}; use png or gif")
    count = 1 if fmt == "png" else len(preview.times)
    frames = []
    for k in range(count):
        fig = _figure(preview, k, grid)
        FigureCanvasAgg(fig)
        buf = io.BytesIO()
        if fmt == "png":
            meta = {PNG_KEY: json.dumps(preview.lane_error)} if preview.lane_error else {}
            fig.savefig(buf, format="png", metadata={"Software": "imu-ground preview", **meta})
            return buf.getvalue()
        fig.savefig(buf, format="png", dpi=60)
        frames.append(Image.open(io.BytesIO(buf.getvalue())).convert("RGB").quantize(colors=128))
    out = io.BytesIO()
    frames[0].save(out, format="GIF", save_all=True, append_images=frames[1:], duration=int(round(1000 / fps)),
                   loop=0)
    return out.getvalue()


def read_preview_errors(path: str | Path) -> dict:
    """The lane-width errors a preview PNG plots (its :data:`PNG_KEY` text chunk), as a dict of lists."""
    from PIL import Image
    with Image.open(path) as im:
        text = im.text.get(PNG_KEY) if hasattr(im, "text") else None
    if text is None:
        raise ImuGroundError(f"{path}: no {PNG_KEY!r} text in the PNG (not a synthetic imu-ground preview)")
    return json.loads(text)
