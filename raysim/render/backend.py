"""Headless drawing back ends: pyvista/VTK off-screen through EGL, matplotlib through Agg.

Nothing here needs a display. :func:`pyvista` points VTK at its EGL render window before the
first window exists (the ``VTK_DEFAULT_OPENGL_WINDOW`` environment variable, read when VTK
creates a window), so a user sets nothing; a user who set the variable keeps their choice.
Sizes are (width, height) in pixels everywhere.
"""

from __future__ import annotations

import ctypes
import functools
import os
import re
from pathlib import Path
from typing import Any

from raysim.errors import RaysimError

EGL_WINDOW = "vtkEGLRenderWindow"
EGL_PLATFORM_DEVICE_EXT = 0x313F
MIN_SIZE = (800, 600)  # smaller pictures cannot hold their labels legibly
MAX_SIZE = (8000, 8000)
DPI = 100  # matplotlib dots per inch: a figure of W x H pixels is W/100 x H/100 inches


class RenderError(RaysimError, ValueError):
    """A picture cannot be made from what the user gave (file kind, size, option)."""


def parse_size(size: str | tuple[int, int] | None, default: tuple[int, int]) -> tuple[int, int]:
    """Picture size (width, height) in pixels from ``"WxH"``, a pair, or None (``default``)."""
    if size is None:
        return default
    if isinstance(size, str):
        match = re.fullmatch(r"\s*(\d+)\s*[xX×,]\s*(\d+)\s*", size)
        if not match:
            raise RenderError(f"--size must look like 1600x1200 (width x height in pixels), got {size!r}")
        width, height = int(match.group(1)), int(match.group(2))
    else:
        try:
            width, height = (int(v) for v in size)
        except (TypeError, ValueError) as exc:
            raise RenderError(f"size must be (width, height) in pixels, got {size!r}") from exc
    if not (MIN_SIZE[0] <= width <= MAX_SIZE[0] and MIN_SIZE[1] <= height <= MAX_SIZE[1]):
        raise RenderError(f"size {width}x{height} is outside {MIN_SIZE[0]}x{MIN_SIZE[1]} .. "
                          f"{MAX_SIZE[0]}x{MAX_SIZE[1]} pixels")
    return width, height


EGL_HINT = ("install EGL with Mesa: scripts/install-system-deps.sh, or apt-get install libegl1 "
            "libegl-mesa0 libgl1-mesa-dri")


@functools.cache
def egl_available() -> bool:
    """Whether EGL can open an off-screen display here, probed the way VTK's EGL window opens
    one (an EGL device, then eglInitialize), without VTK: VTK crashes where this fails."""
    try:
        egl = ctypes.CDLL("libEGL.so.1")
    except OSError:
        return False
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    query = egl.eglGetProcAddress(b"eglQueryDevicesEXT")
    platform = egl.eglGetProcAddress(b"eglGetPlatformDisplayEXT")
    if not query or not platform:
        return False
    query_devices = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.POINTER(ctypes.c_void_p),
                                     ctypes.POINTER(ctypes.c_int))(query)
    platform_display = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_uint, ctypes.c_void_p,
                                        ctypes.c_void_p)(platform)
    egl.eglInitialize.restype = ctypes.c_uint
    egl.eglInitialize.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int)]
    egl.eglTerminate.argtypes = [ctypes.c_void_p]
    devices = (ctypes.c_void_p * 32)()
    count = ctypes.c_int(0)
    if not query_devices(32, devices, ctypes.byref(count)):
        return False
    major, minor = ctypes.c_int(0), ctypes.c_int(0)
    for k in range(count.value):
        display = platform_display(EGL_PLATFORM_DEVICE_EXT, devices[k], None)
        if display and egl.eglInitialize(display, ctypes.byref(major), ctypes.byref(minor)):
            egl.eglTerminate(display)
            return True
    return False


def pyvista() -> Any:
    """Import pyvista for off-screen rendering through EGL (no X server); return the module.

    Raises RenderError with what to install when the EGL window is chosen but EGL cannot open
    a display (VTK itself would crash there).
    """
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", EGL_WINDOW)
    if os.environ["VTK_DEFAULT_OPENGL_WINDOW"] == EGL_WINDOW and not egl_available():
        raise RenderError(f"no usable EGL for off-screen 3D rendering: {EGL_HINT}")
    import pyvista as pv
    import pyvista.plotting  # pyvista loads it lazily otherwise, at the first Plotter

    pv.OFF_SCREEN = True
    return pv


def points(size: float) -> int:
    """A VTK font size in points (integer, at least 7)."""
    return max(7, round(size))


def plotter(size: tuple[int, int], shape: tuple[int, int] = (1, 1), **layout: Any) -> Any:
    """An off-screen pyvista Plotter of ``size`` pixels, white background, no window.

    ``layout`` passes pyvista's subplot options (``groups``, ``row_weights``, ``col_weights``).
    """
    pv = pyvista()
    from pyvista.plotting.tools import supports_open_gl

    if not supports_open_gl():
        raise RenderError(f"VTK found no OpenGL for off-screen rendering: {EGL_HINT}")
    try:
        pl = pv.Plotter(off_screen=True, window_size=list(size), shape=shape, border=False,
                        lighting="light_kit", **layout)
    except RuntimeError as exc:  # pragma: no cover - depends on the machine's OpenGL stack
        raise RenderError(f"VTK could not open an off-screen window ({exc}): {EGL_HINT}") from exc
    pl.set_background("white")
    return pl


def screenshot(pl: Any, output: str | os.PathLike[str] | None) -> Any:
    """Render ``pl`` and return its RGB image (height, width, 3); write a PNG when ``output``.

    Renders again on every call (pyvista renders by itself only the first time), so camera,
    actor and size changes since the last picture show.
    """
    pl.render()  # a no-op before the first picture, which screenshot renders itself
    image = pl.screenshot(None, return_img=True)
    if output is not None:
        write_png(image, output)
    return image


def project(pl: Any, points: Any, subplot: tuple[int, int] | None = None) -> Any:
    """Pixel positions (column, row from the top) of world points (n, 3) (m) in ``pl``'s picture,
    through the camera of ``subplot`` (default: the active renderer). Render ``pl`` first."""
    import numpy as np

    if subplot is not None:
        pl.subplot(*subplot)
    renderer = pl.renderer
    height = pl.window_size[1]
    out = []
    for p in np.atleast_2d(np.asarray(points, dtype=np.float64)):
        renderer.SetWorldPoint(float(p[0]), float(p[1]), float(p[2]), 1.0)
        renderer.WorldToDisplay()
        x, y, _ = renderer.GetDisplayPoint()
        out.append((x, height - 1 - y))
    return np.array(out)


def colour_count(image: Any) -> int:
    """Number of distinct RGB colours in an image (uint8 0-255 or float 0-1 values): a blank or
    one-colour picture has 1."""
    import numpy as np

    rgb = np.asarray(image)[..., :3]
    if rgb.dtype.kind == "f":
        rgb = np.round(rgb * 255.0)
    rgb = rgb.astype(np.int64)
    return int(np.unique((rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]).size)


def write_png(image: Any, output: str | os.PathLike[str]) -> Path:
    """Write an RGB(A) uint8 image array as PNG, creating the folder."""
    from matplotlib.image import imsave

    from raysim.files import atomic_path

    path = Path(output)
    with atomic_path(path) as tmp:
        imsave(tmp, image, format="png")
    return path


def figure(size: tuple[int, int], text_scale: float = 1.0) -> Any:
    """A matplotlib Figure of exactly ``size`` pixels (Agg canvas, no pyplot, no display).

    ``text_scale`` > 1 draws text and lines that many times larger at the same pixel size (more
    dots per inch): a wide picture shown shrunk to a page's width keeps legible labels."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not (0.25 <= text_scale <= 8.0):
        raise RenderError(f"text_scale must lie in [0.25, 8], got {text_scale:g}")
    dpi = DPI * text_scale
    fig = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def figure_image(fig: Any) -> Any:
    """Draw ``fig`` and return its RGB image (height, width, 3) as uint8."""
    import numpy as np

    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()

