"""The one place where GL contexts are made: EGL by default, OSMesa as the fallback.

Both give a moderngl.Context on Mesa (llvmpipe without a GPU). EGL comes from glcontext's
standalone EGL backend. OSMesa has no glcontext backend, so it is made here through ctypes and
handed to moderngl as a function loader (OSMesaGetProcAddress), which needs no PyOpenGL.
"""

import ctypes
import ctypes.util
import os

import moderngl

from glsynth.core.errors import UserError

REQUIRED_GL = 330
PLATFORMS = ("egl", "osmesa")
_PACKAGES = {"egl": "libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri libgbm1",
             "osmesa": "libosmesa6"}


class GLUnavailableError(UserError):
    """No GL context could be made; the message lists each platform tried, why it failed and
    which packages provide it. A machine without GL is for the user to fix, so it is a
    UserError: the command line prints it as one line."""


class _OSMesaLoader:
    """An OSMesa core-profile context with a 1x1 default framebuffer; moderngl loads GL
    functions through it. Offscreen rendering then goes to moderngl framebuffers."""

    _FORMAT, _DEPTH_BITS, _PROFILE, _CORE, _MAJOR, _MINOR = 0x22, 0x30, 0x33, 0x34, 0x36, 0x37
    _RGBA, _UNSIGNED_BYTE = 0x1908, 0x1401

    def __init__(self) -> None:
        name = ctypes.util.find_library("OSMesa") or "libOSMesa.so.8"
        self.lib = ctypes.CDLL(name)
        self.lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
        self.lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int),
                                                        ctypes.c_void_p]
        self.lib.OSMesaMakeCurrent.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int,
                                               ctypes.c_int, ctypes.c_int]
        self.lib.OSMesaGetProcAddress.restype = ctypes.c_void_p
        self.lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
        self.lib.OSMesaDestroyContext.argtypes = [ctypes.c_void_p]
        attribs = (ctypes.c_int * 11)(self._FORMAT, self._RGBA, self._DEPTH_BITS, 24,
                                      self._PROFILE, self._CORE, self._MAJOR, 3, self._MINOR, 3, 0)
        self.ctx = self.lib.OSMesaCreateContextAttribs(attribs, None)
        if not self.ctx:
            raise RuntimeError("OSMesaCreateContextAttribs returned NULL (no GL 3.3 core)")
        self.buffer = ctypes.create_string_buffer(4)
        if not self.lib.OSMesaMakeCurrent(self.ctx, self.buffer, self._UNSIGNED_BYTE, 1, 1):
            raise RuntimeError("OSMesaMakeCurrent failed")

    def load_opengl_function(self, name: str) -> int:
        return self.lib.OSMesaGetProcAddress(name.encode()) or 0

    def __enter__(self) -> None:
        """Make this context current (moderngl's Context.__enter__ calls it)."""
        if not self.lib.OSMesaMakeCurrent(self.ctx, self.buffer, self._UNSIGNED_BYTE, 1, 1):
            raise RuntimeError("OSMesaMakeCurrent failed")

    def __exit__(self, *args: object) -> None:
        """Leave the context current: glsynth makes its context current before each use."""

    def release(self) -> None:
        if self.ctx:
            self.lib.OSMesaDestroyContext(self.ctx)
            self.ctx = None


def _create(platform: str) -> moderngl.Context:
    if platform == "egl":
        return moderngl.create_standalone_context(backend="egl", require=REQUIRED_GL)
    loader = _OSMesaLoader()
    moderngl.init_context(loader)
    ctx = moderngl.get_context()
    ctx.extra = {"osmesa": loader}  # keep the context alive as long as moderngl's
    if ctx.version_code < REQUIRED_GL:
        raise RuntimeError(f"OSMesa gives GL {ctx.version_code}, need {REQUIRED_GL}")
    return ctx


def create_context(platform: str | None = None) -> tuple[moderngl.Context, str]:
    """A GL context and the platform that made it.

    platform: "egl", "osmesa", or None for the environment variable GLSYNTH_GL_PLATFORM, else
    EGL then OSMesa.
    """
    platform = platform or os.environ.get("GLSYNTH_GL_PLATFORM") or None
    if platform is not None and platform not in PLATFORMS:
        raise UserError(f"GL platform {platform!r} (GLSYNTH_GL_PLATFORM): choose one of "
                        f"{PLATFORMS}, or leave it unset to try EGL, then OSMesa")
    tried = []
    for name in ([platform] if platform else PLATFORMS):
        try:
            return _create(name), name
        except Exception as err:  # any failure of one platform: record it, try the next
            reason = " ".join(str(err).split())  # one line, whatever the library wrote
            reason = reason if len(reason) <= 40 else reason[:37] + "..."  # a 300-char line
            tried.append(f"{name.upper()}: {type(err).__name__}: {reason}")
    packages = " ".join(_PACKAGES[name] for name in ([platform] if platform else PLATFORMS))
    raise GLUnavailableError(f"no OpenGL context ({'; '.join(tried)}); install the Debian "
                             f"packages {packages} (scripts/install.sh does), or set "
                             "GLSYNTH_GL_PLATFORM to a platform that works")


def device_name(ctx: moderngl.Context) -> str:
    """The device a context draws on, as its driver names it: "llvmpipe (LLVM ...)" for Mesa's
    CPU rasterizer, the GPU's name for a hardware driver. EGL picks the device with
    glcontext's GLCONTEXT_DEVICE_INDEX (its position in eglQueryDevicesEXT's list)."""
    info = ctx.info
    return f"{info['GL_RENDERER']} ({info['GL_VENDOR']}, GL {ctx.version_code})"


def check_render_size(ctx: moderngl.Context, platform: str, width: int, height: int,
                      msaa: int, shadow_map_px: int, trial: bool = True) -> None:
    """Refuse, with the limit, a render size this GL cannot hold: the context's
    MAX_TEXTURE_SIZE, MAX_RENDERBUFFER_SIZE and MAX_VIEWPORT_DIMS, asked once, and with
    ``trial`` a trial allocation of the multisampled colour target (llvmpipe refuses
    16000x9000 at 4 samples though each side is within its limits)."""
    info = ctx.info
    side = min(info["GL_MAX_TEXTURE_SIZE"], info["GL_MAX_RENDERBUFFER_SIZE"],
               *info["GL_MAX_VIEWPORT_DIMS"])
    for name, value in (("width", width), ("height", height), ("shadow_map_px", shadow_map_px)):
        if value > side:
            raise UserError(f"[render] {name} = {value}: this GL ({platform}) renders at most "
                            f"{side} px a side; set {name} to {side} or less")
    if not trial:
        return
    try:
        target = ctx.renderbuffer((width, height), 4, samples=msaa)
        frame = ctx.framebuffer([target])
    except moderngl.Error:
        raise UserError(f"[render] {width}x{height} at msaa = {msaa}: this GL ({platform}) "
                        "cannot allocate a target that large; lower width and height, or "
                        "msaa") from None
    frame.release()
    target.release()
