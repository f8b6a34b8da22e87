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
    if not scenes:
        return {}, None
    with tempfile.TemporaryDirectory(prefix="partcal-scene-") as tmp:
        arrays = {}
        for i, spec in enumerate(scenes.values()):
            for key, value in spec.items():
                arrays[f"{i}__{key}"] = np.asarray(value)
        np.savez(Path(tmp) / "scenes.npz", n=len(scenes), **arrays)
        env = {**os.environ, "VTK_DEFAULT_OPENGL_WINDOW": "vtkEGLRenderWindow"}
        try:
            proc = subprocess.run([sys.executable, "-m", "partcal.report.scene", tmp], capture_output=True,
                                  text=True, timeout=TIMEOUT_S, env=env)
        except subprocess.TimeoutExpired:
            return {}, f"3-D rendering took longer than {TIMEOUT_S} s and was stopped"
        except OSError as exc:
            return {}, f"3-D rendering could not start ({exc.strerror or exc})"
        pngs = {}
        for i, name in enumerate(scenes):
            png = Path(tmp) / f"{i}.png"
            if png.exists():
                pngs[name] = png.read_bytes()
        if proc.returncode != 0 or len(pngs) < len(scenes):
            last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
            return pngs, f"3-D rendering failed (exit {proc.returncode}: {last[:200]})"
        return pngs, None


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
        line = pv.lines_from_points(path_points)
        line["residual (mm)"] = spec[f"residual{k}"]
        plotter.add_mesh(line, scalars="residual (mm)", cmap="plasma", clim=(0, top), line_width=5,
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
