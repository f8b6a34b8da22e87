"""3-D workspace pictures (pyvista, off-screen PNG), rendered in a child process.

VTK picks EGL with Mesa's software renderer on a headless machine. A missing
or broken OpenGL stack can crash a process rather than raise, so the pictures
are drawn by ``python -m partcal.report.scene`` in a child process with a
time limit: if it fails, the report shows a note instead and the run goes on.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)
TIMEOUT_S = 180


def render_scenes(scenes: dict[str, dict]) -> tuple[dict[str, bytes], str | None]:
    """Render each scene to PNG bytes; return ``(pngs, problem)`` (problem: why some are missing)."""
    return SceneRendering(scenes).result()


class SceneRendering:
    """The scenes' child process, started at once; :meth:`result` waits for it (the report draws its
    other figures meanwhile, on the other core)."""

    def __init__(self, scenes: dict[str, dict]):
        self.names, self.proc, self.problem = list(scenes), None, None
        self._tmp = tempfile.TemporaryDirectory(prefix="partcal-scene-")
        if not scenes:
            return
        arrays = {}
        for i, spec in enumerate(scenes.values()):
            for key, value in spec.items():
                arrays[f"{i}__{key}"] = np.asarray(value)
        np.savez(Path(self._tmp.name) / "scenes.npz", n=len(scenes), **arrays)
        env = {**os.environ, "VTK_DEFAULT_OPENGL_WINDOW": "vtkEGLRenderWindow"}
        try:
            self.proc = subprocess.Popen([sys.executable, "-m", "partcal.report.scene", self._tmp.name],
                                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
        except OSError as exc:
            self.problem = f"3-D rendering could not start ({exc.strerror or exc})"

    def result(self) -> tuple[dict[str, bytes], str | None]:
        """``(pngs, problem)``: PNG bytes per scene name, and why some are missing (None if none is)."""
        try:
            if self.proc is None:
                return {}, self.problem
            try:
                _, stderr = self.proc.communicate(timeout=TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.communicate()
                return {}, f"3-D rendering took longer than {TIMEOUT_S} s and was stopped"
            pngs = {}
            for i, name in enumerate(self.names):
                png = Path(self._tmp.name) / f"{i}.png"
                if png.exists():
                    pngs[name] = png.read_bytes()
            if self.proc.returncode != 0 or len(pngs) < len(self.names):
                last = (stderr.strip().splitlines() or ["no message"])[-1]
                return pngs, f"3-D rendering failed (exit {self.proc.returncode}: {last[:200]})"
            return pngs, None
        finally:
            self._tmp.cleanup()


REGION_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
                  "#bcbd22", "#17becf", "#aec7e8", "#ffbb78", "#98df8a", "#ff9896", "#c5b0d5", "#c49c94",
                  "#f7b6d2", "#c7c7c7", "#dbdb8d", "#9edae5")       # matplotlib's tab20, darker shades first
LEGEND_REGIONS = 12          # regions named in the legend; more share a last entry
WINDOW = (1100, 720)         # pixels; the scene takes the left SCENE_SHARE, the legend and colour bar the rest
SCENE_SHARE = 0.78
FONT_PX = 14                 # axis titles and tick labels, upright screen text


def region_colour(label: int) -> str:
    """The colour of region ``label`` (0-based) in the picture and its legend."""
    return REGION_COLOURS[int(label) % len(REGION_COLOURS)]


def legend_entries(labels) -> list[tuple[str, str]]:
    """``(text, colour)`` of each region in the legend: ``region 1`` .. (1-based), at most
    :data:`LEGEND_REGIONS`, the rest as one entry saying how many more.

    >>> legend_entries([0, 2, 2, 1])
    [('region 1', '#1f77b4'), ('region 2', '#ff7f0e'), ('region 3', '#2ca02c')]
    """
    regions = sorted({int(v) for v in np.asarray(labels).ravel()})
    out = [(f"region {k + 1}", region_colour(k)) for k in regions[:LEGEND_REGIONS]]
    if len(regions) > LEGEND_REGIONS:
        out.append((f"{len(regions) - LEGEND_REGIONS} more regions (colours repeat)", "#ffffff"))
    return out


def _draw(spec: dict, path: Path) -> None:
    import pyvista as pv

    pv.OFF_SCREEN = True
    plotter = pv.Plotter(off_screen=True, window_size=WINDOW, shape=(1, 2),
                         col_weights=[SCENE_SHARE, 1 - SCENE_SHARE], border=False)
    plotter.set_background("white")
    plotter.subplot(0, 0)
    points, labels = spec["points"], spec["labels"].astype(int)
    for k in np.unique(labels):                   # one colour per region, as the legend names it
        plotter.add_mesh(pv.PolyData(points[labels == k]), color=region_colour(k), point_size=9,
                         render_points_as_spheres=True)
    if spec["boxes"].size:
        for low, high in spec["boxes"]:
            plotter.add_mesh(pv.Box(bounds=(low[0], high[0], low[1], high[1], low[2], high[2])),
                             style="wireframe", color="#555555", line_width=1, opacity=0.5)
    top = float(spec["residual_max"])
    mapper = None
    for k in range(int(spec["n_paths"])):
        path_points = spec[f"path{k}"]
        joined = bool(spec.get(f"joined{k}", True))         # a path is a line; scattered poses stay points
        shape = pv.lines_from_points(path_points) if joined else pv.PolyData(path_points)
        shape["residual (mm)"] = spec[f"residual{k}"]
        style = {"line_width": 5} if joined else {"point_size": 6, "render_points_as_spheres": True}
        actor = plotter.add_mesh(shape, scalars="residual (mm)", cmap="plasma", clim=(0, top), **style,
                                 show_scalar_bar=False)
        mapper = mapper or actor.mapper
    plotter.show_bounds(color="black", xtitle="x (mm)", ytitle="y (mm)", ztitle="z (mm)", font_size=FONT_PX,
                        use_3d_text=False, location="outer", fmt="%.0f", n_xlabels=3, n_ylabels=3, n_zlabels=3,
                        bold=False)
    plotter.camera_position = "iso"
    plotter.camera.zoom(0.85)
    plotter.subplot(0, 1)                          # beside the scene: nothing drawn over an axis
    entries = legend_entries(labels)
    plotter.add_legend(entries, bcolor="white", size=(0.6, min(0.035 * len(entries), 0.45)), loc="upper left",
                       face="circle")
    if mapper is not None:
        plotter.add_scalar_bar("test sets: residual (mm)", mapper=mapper, vertical=True, color="black",
                               position_x=0.3, position_y=0.06, width=0.25, height=0.42,
                               title_font_size=FONT_PX, label_font_size=FONT_PX, fmt="%.2f")
    plotter.screenshot(str(path))
    plotter.close()


def _main(folder: str) -> int:
    data = np.load(Path(folder) / "scenes.npz")
    for i in range(int(data["n"])):
        prefix = f"{i}__"
        spec = {k[len(prefix):]: data[k] for k in data.files if k.startswith(prefix)}
        _draw(spec, Path(folder) / f"{i}.png")
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1]))
