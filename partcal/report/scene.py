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


def _draw(spec: dict, path: Path) -> None:
    import pyvista as pv

    pv.OFF_SCREEN = True
    plotter = pv.Plotter(off_screen=True, window_size=(1000, 720))
    plotter.set_background("white")
    points = spec["points"]
    labels = spec["labels"]
    cloud = pv.PolyData(points)
    cloud["region"] = labels.astype(float)
    plotter.add_mesh(cloud, scalars="region", cmap="tab20", point_size=9, render_points_as_spheres=True,
                     show_scalar_bar=False)
    if spec["boxes"].size:
        for low, high in spec["boxes"]:
            plotter.add_mesh(pv.Box(bounds=(low[0], high[0], low[1], high[1], low[2], high[2])),
                             style="wireframe", color="#555555", line_width=1, opacity=0.5)
    top = float(spec["residual_max"])
    for k in range(int(spec["n_paths"])):
        path_points = spec[f"path{k}"]
        joined = bool(spec.get(f"joined{k}", True))         # a path is a line; scattered poses stay points
        shape = pv.lines_from_points(path_points) if joined else pv.PolyData(path_points)
        shape["residual (mm)"] = spec[f"residual{k}"]
        style = {"line_width": 5} if joined else {"point_size": 6, "render_points_as_spheres": True}
        plotter.add_mesh(shape, scalars="residual (mm)", cmap="plasma", clim=(0, top), **style,
                         show_scalar_bar=(k == 0), scalar_bar_args={"title": "residual (mm)", "color": "black",
                                                                    "vertical": True, "position_x": 0.85,
                                                                    "position_y": 0.25, "height": 0.5})
    plotter.show_bounds(color="black", xtitle="x (mm)", ytitle="y (mm)", ztitle="z (mm)", font_size=9)
    plotter.camera_position = "iso"
    plotter.camera.zoom(1.15)
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
