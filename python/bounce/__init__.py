"""bounce from Python: a thin layer over the C library (libbounce.so) through ctypes.

    import bounce
    r = bounce.solve("meshes/cornell-box.obj", unit="mm", bounces=3)
    r.L          # patches x 3 radiance, W m^-2 sr^-1 (numpy, read-only)
    r.terms[k]   # K^k E, patches x 3: r.terms[0] = E, r.terms[1] = KE (direct light), ...
    r.rest       # L minus the kept terms (the longer paths)
    r.area, r.normal, r.centroid, r.reflectance, r.face   # per patch (numpy, read-only)
    r.relight(Le={"light": (34, 24, 8)}, rho={"red": (0.1, 0.6, 0.1)})   # new materials, the same F

The library (libbounce.so) is found, in this order, where the environment variable BOUNCE_LIBRARY
names it; in the build tree beside this package's sources (build/libbounce.so: running from a
checkout); in the Python prefix (`cmake --install build --prefix "$VIRTUAL_ENV"` puts it in the venv's
lib/); in cmake --install's default prefix, /usr/local/lib, or wherever the system's loader finds it.
bounce.library_source() says which. Errors raise bounce.BounceError with bounce's message and status
name. Nothing here computes: every number comes from the C library.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import os
import re
import sys
from typing import Any, Callable, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

# A material's new value: one number (grey) or three (R, G, B).
RGB = Union[float, Sequence[float]]
# Names a parameter takes (method, transport, unit, ...) are the library's: names("method") lists them,
# and _names.py holds them as Literal types, generated from the library's tables (scripts/python_names.py).
from bounce._names import (GatherName, MeshName, MethodName, TransportName, UnitName,  # noqa: E402
                           VisibilityName)
Name = str
PathLike = Union[str, "os.PathLike[str]"]

__version__ = "0.1.0"   # the library's version (CMakeLists.txt's project VERSION; a test keeps them equal)

__all__ = ["Scene", "solve", "Result", "Operator", "BounceError", "as_linear_operator", "library_path", "library_source",
           "library_version", "names", "__version__"]


class BounceError(RuntimeError):
    """A bounce call failed: .status is bounce's status name ("EINPUT", ...), str() its message."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status


def _library_candidates() -> Iterator[Tuple[str, str]]:
    """(path, how it was found) in the order library_path() tries them."""
    env = os.environ.get("BOUNCE_LIBRARY")
    if env:
        yield env, "BOUNCE_LIBRARY"
        return
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    for build in ("build", "build-asan", "build-bench"):
        yield os.path.join(root, build, "libbounce.so"), "the build tree of the checkout at %s" % root
    for prefix in dict.fromkeys((sys.prefix, "/usr/local")):
        for lib in ("lib", "lib64", "lib/x86_64-linux-gnu"):
            yield os.path.join(prefix, lib, "libbounce.so"), "the prefix %s (cmake --install)" % prefix
    found = ctypes.util.find_library("bounce")
    if found:
        yield found, "the system's library path (ldconfig)"


def _find_library() -> Tuple[str, str]:
    for path, how in _library_candidates():
        if how == "BOUNCE_LIBRARY" or os.path.exists(path) or not os.path.isabs(path):
            return path, how
    raise BounceError("EUSAGE", "libbounce.so not found: set BOUNCE_LIBRARY, build bounce in this checkout "
                      "(cmake --preset default && cmake --build --preset default), or install it into this "
                      "Python's prefix (cmake --install build --prefix %s)" % sys.prefix)


def library_path() -> str:
    """The libbounce.so this package uses (see library_source())."""
    return _find_library()[0]


def library_source() -> str:
    """How library_path() was found: "BOUNCE_LIBRARY", "the build tree of the checkout at ...",
    "the prefix ... (cmake --install)" or "the system's library path (ldconfig)"."""
    return _find_library()[1]


class _Opts(ctypes.Structure):
    _fields_ = [("unit", ctypes.c_char_p), ("method", ctypes.c_char_p), ("transport", ctypes.c_char_p),
                ("bounces", ctypes.c_int), ("tol", ctypes.c_double), ("patches", ctypes.c_size_t),
                ("patch_size", ctypes.c_double), ("eps", ctypes.c_double), ("threads", ctypes.c_int),
                ("quiet", ctypes.c_int), ("sigint", ctypes.c_int), ("visibility", ctypes.c_char_p),
                ("max_iter", ctypes.c_size_t), ("atol", ctypes.c_double), ("stop", ctypes.c_char_p),
                ("seed", ctypes.c_uint64), ("precision", ctypes.c_char_p), ("storage", ctypes.c_char_p),
                ("cache", ctypes.c_char_p), ("ff", ctypes.c_char_p), ("more", ctypes.c_char_p)]


_lib = None
_APPLY = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double))
_ROW = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_size_t, ctypes.POINTER(ctypes.c_double),
                        ctypes.POINTER(ctypes.c_double))


def _check_layout(lib, path):
    """The options struct as this package lays it out against the library's own size: a field added
    on one side only would shift every field after it, so a mismatch refuses to go on."""
    lib.bn_version.restype = ctypes.c_char_p
    version = lib.bn_version().decode()
    if not hasattr(lib, "bn_flat_opts_size"):
        raise BounceError("EUSAGE", "%s (bounce %s) is older than this package: rebuild bounce" % (path, version))
    lib.bn_flat_opts_size.restype = ctypes.c_size_t
    theirs, ours = lib.bn_flat_opts_size(), ctypes.sizeof(_Opts)
    if theirs != ours:
        raise BounceError("EUSAGE", "%s (bounce %s) lays bn_flat_opts out in %d bytes, this package in %d: the "
                          "package and the library are from different versions" % (path, version, theirs, ours))


def names(vocabulary: str) -> List[str]:
    """The names a parameter takes, as the library has them (its one table per vocabulary):
    names("method") == ["jacobi", "gauss-seidel", "neumann", "direct"]; "transport", "storage",
    "precision", "ff", "visibility", "unit", "stop", "mesh", "gather", "strategy", "model"."""
    text = _load().bn_flat_names(_name("vocabulary", vocabulary))
    if text is None:
        raise BounceError("EUSAGE", "no vocabulary named %r" % (vocabulary,))
    return text.decode().split("|")


def library_version() -> str:
    """The version of the libbounce.so in use."""
    return _load().bn_version().decode()


def _load() -> Any:
    global _lib
    if _lib is not None:
        return _lib
    path = library_path()
    lib = ctypes.CDLL(path)
    P, D, S, I = ctypes.c_void_p, ctypes.POINTER(ctypes.c_double), ctypes.c_size_t, ctypes.c_int
    _check_layout(lib, path)
    lib.bn_flat_opts_default.argtypes = [ctypes.POINTER(_Opts)]
    lib.bn_flat_solve.argtypes = [ctypes.c_char_p, ctypes.POINTER(_Opts), ctypes.POINTER(P), ctypes.c_char_p, S]
    lib.bn_flat_solve.restype = I
    lib.bn_flat_free.argtypes = [P]
    for name, res in (("bn_flat_patches", S), ("bn_flat_terms", I), ("bn_flat_iterations", S),
                      ("bn_flat_residual", ctypes.c_double)):
        getattr(lib, name).argtypes = [P]
        getattr(lib, name).restype = res
    for name in ("bn_flat_L", "bn_flat_rest", "bn_flat_emission"):
        getattr(lib, name).argtypes = [P]
        getattr(lib, name).restype = D
    lib.bn_flat_term.argtypes = [P, I]
    lib.bn_flat_term.restype = D
    for name in ("bn_flat_stop_reason", "bn_flat_method", "bn_flat_transport"):
        getattr(lib, name).argtypes = [P]
        getattr(lib, name).restype = ctypes.c_char_p
    lib.bn_flat_patch_data.argtypes = [P, D, D, D, D, ctypes.POINTER(ctypes.c_size_t)]
    lib.bn_status_name.argtypes = [I]
    lib.bn_status_name.restype = ctypes.c_char_p
    lib.bn_flat_names.argtypes = [ctypes.c_char_p]
    lib.bn_flat_names.restype = ctypes.c_char_p
    lib.bn_flat_bake.argtypes = [P, ctypes.c_char_p, I, ctypes.c_char_p, I, ctypes.c_double, ctypes.c_double,
                                 ctypes.c_char_p, ctypes.c_longlong, ctypes.c_char_p,
                                 ctypes.c_char_p, S]
    lib.bn_flat_bake.restype = I
    lib.bn_flat_images.argtypes = [P, ctypes.c_char_p, I, I, I, D, D, ctypes.c_double, I, I, I, ctypes.c_char_p,
                                   ctypes.c_char_p,
                                   ctypes.c_char_p, S]
    lib.bn_flat_images.restype = I
    lib.bn_flat_history.argtypes = [P, ctypes.POINTER(D)]
    lib.bn_flat_history.restype = S
    lib.bn_flat_load.argtypes = [ctypes.c_char_p, ctypes.POINTER(_Opts), ctypes.POINTER(P), ctypes.c_char_p, S]
    lib.bn_flat_load.restype = I
    lib.bn_flat_operator.argtypes = [P, ctypes.c_char_p, S]
    lib.bn_flat_operator.restype = I
    lib.bn_flat_ff_diagnostics.argtypes = [P, D]
    lib.bn_flat_form_factors.argtypes = [P, D, ctypes.c_char_p, S]
    lib.bn_flat_form_factors.restype = I
    lib.bn_flat_solve_operator.argtypes = [S, D, _APPLY, _ROW, P, ctypes.POINTER(_Opts), ctypes.POINTER(P),
                                           ctypes.c_char_p, S]
    lib.bn_flat_solve_operator.restype = I
    lib.bn_flat_relight.argtypes = [P, S, ctypes.POINTER(ctypes.c_char_p), D, D, I, ctypes.c_char_p, S]
    lib.bn_flat_relight.restype = I
    Sp = ctypes.POINTER(ctypes.c_size_t)
    lib.bn_flat_form_factors_csr.argtypes = [P, Sp, Sp, D, Sp, ctypes.c_char_p, S]
    lib.bn_flat_form_factors_csr.restype = I
    lib.bn_flat_apply.argtypes = [P, I, D, D, ctypes.c_char_p, S]
    lib.bn_flat_apply.restype = I
    lib.bn_flat_render.argtypes = [P, I, I, I, D, D, ctypes.c_double, I, ctypes.c_char_p,
                                   ctypes.POINTER(ctypes.c_float), ctypes.c_char_p, S]
    lib.bn_flat_render.restype = I
    lib.bn_flat_layers.argtypes = [P]
    lib.bn_flat_layers.restype = I
    lib.bn_flat_layer_name.argtypes = [P, I, ctypes.c_char_p, S]
    lib.bn_flat_layer_name.restype = ctypes.c_char_p
    lib.bn_flat_solve_loaded.argtypes = [P, ctypes.POINTER(_Opts), ctypes.c_char_p, S]
    lib.bn_flat_solve_loaded.restype = I
    lib.bn_flat_relight_gain.argtypes = [P]
    lib.bn_flat_relight_gain.restype = ctypes.c_double
    U64 = ctypes.c_uint64
    lib.bn_flat_trace_patches.argtypes = [P, S, I, U64, I, D, D, ctypes.c_char_p, S]
    lib.bn_flat_trace_patches.restype = I
    Fp = ctypes.POINTER(ctypes.c_float)
    lib.bn_flat_trace_image.argtypes = [P, I, I, S, I, U64, D, D, ctypes.c_double, I, Fp, Fp, ctypes.c_char_p, S]
    lib.bn_flat_trace_image.restype = I
    lib.bn_flat_crosscheck.argtypes = [ctypes.c_char_p, ctypes.POINTER(_Opts), S, I, ctypes.c_double, ctypes.c_char_p,
                                       ctypes.POINTER(P), ctypes.c_char_p, S]
    lib.bn_flat_crosscheck.restype = I
    lib.bn_flat_check_free.argtypes = [P]
    lib.bn_flat_check_free.restype = None
    for fn in ("bn_flat_check_pass", "bn_flat_check_layers"):
        getattr(lib, fn).argtypes = [P]
        getattr(lib, fn).restype = I
    lib.bn_flat_check_entries.argtypes = [P]
    lib.bn_flat_check_entries.restype = S
    lib.bn_flat_check_figures.argtypes = [P, D]
    lib.bn_flat_check_figures.restype = None
    lib.bn_flat_check_arrays.argtypes = [P, D, D, D, D]
    lib.bn_flat_check_arrays.restype = None
    lib.bn_flat_study_run.argtypes = [ctypes.c_char_p, ctypes.POINTER(_Opts), ctypes.c_char_p, D, S,
                                      ctypes.POINTER(P), ctypes.c_char_p, S]
    lib.bn_flat_study_run.restype = I
    lib.bn_flat_study_free.argtypes = [P]
    lib.bn_flat_study_free.restype = None
    lib.bn_flat_study_columns.restype = ctypes.c_char_p
    lib.bn_flat_study_rows.argtypes = [P]
    lib.bn_flat_study_rows.restype = S
    lib.bn_flat_study_row.argtypes = [P, S, D]
    lib.bn_flat_study_row.restype = None
    lib.bn_flat_study_label.argtypes = [P, S, I]
    lib.bn_flat_study_label.restype = ctypes.c_char_p
    lib.bn_flat_study_reference.argtypes = [P, D]
    lib.bn_flat_study_reference.restype = ctypes.c_char_p
    lib.bn_flat_set.argtypes = [P, ctypes.c_char_p, ctypes.c_char_p, S]
    lib.bn_flat_set.restype = I
    lib.bn_layer_name.argtypes = [I, I, ctypes.c_char_p, S]
    lib.bn_layer_name.restype = ctypes.c_char_p
    _lib = lib
    return lib


def _keywords(text):
    """bounce names its options backquoted as in its C structs (`max_iter`); here they are keywords."""
    return re.sub(r"`(\w+)`", r"\1=", text)


def _raise(lib, st, msg):
    name = lib.bn_status_name(st).decode()
    text = _keywords(msg.value.decode(errors="replace"))
    if name == "EINTR":   # Ctrl-C stopped the C loops (opts.sigint): the Python way to say so
        raise KeyboardInterrupt("bounce: " + (text or "interrupted"))
    raise BounceError(name, text)


def _main_thread():
    import threading
    return threading.current_thread() is threading.main_thread()


def _frozen(a):
    """a made read-only: an edit raises (ValueError) instead of being silently ignored by bounce."""
    if a is not None:
        a.flags.writeable = False
    return a


def _patch_data(lib, h, n):
    """area, normal, centroid, reflectance, face of every patch (read-only copies)."""
    Dp = ctypes.POINTER(ctypes.c_double)
    area, normal, centroid, rho = np.full(n, np.nan), np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    face = np.zeros(n, dtype=np.uintp)   # an operator's result has no scene: NaN and 0 stay
    lib.bn_flat_patch_data(h, area.ctypes.data_as(Dp), normal.ctypes.data_as(Dp), centroid.ctypes.data_as(Dp),
                           rho.ctypes.data_as(Dp), face.ctypes.data_as(ctypes.POINTER(ctypes.c_size_t)))
    return [_frozen(a) for a in (area, normal, centroid, rho, face)]


def _rgb(option, name, v):
    """A material's new value: one number (grey) or three."""
    try:
        a = np.asarray(v, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise BounceError("EUSAGE", "%s[%r] must be a number or three, not %r" % (option, name, v))
    if a.shape not in ((1,), (3,)):
        raise BounceError("EUSAGE", "%s[%r] must be a number or three, not %d values" % (option, name, a.size))
    if np.isnan(a).any():
        raise BounceError("EUSAGE", "%s[%r] = %r: nan is not a value" % (option, name, v))
    return np.repeat(a, 3) if a.size == 1 else a


def _scipy_sparse() -> Any:
    try:
        import scipy.sparse   # type: ignore[import]
        import scipy.sparse.linalg   # type: ignore[import]
    except ImportError:
        raise BounceError("EUSAGE", "this needs scipy (Debian: python3-scipy)")
    return scipy.sparse


def _form_factors(lib: Any, h: Any, n: int, sparse: bool) -> Any:
    """F of handle h: dense (n x n), or CSR from the stored entries (two passes: count, then fill)."""
    msg = ctypes.create_string_buffer(2048)
    if not sparse:
        F = np.empty((n, n))
        st = lib.bn_flat_form_factors(h, F.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), msg, len(msg))
        if st != 0:
            _raise(lib, st, msg)
        return F
    sp = _scipy_sparse()
    S, Dp = ctypes.POINTER(ctypes.c_size_t), ctypes.POINTER(ctypes.c_double)
    indptr, nnz = np.zeros(n + 1, dtype=np.uintp), ctypes.c_size_t(0)
    st = lib.bn_flat_form_factors_csr(h, indptr.ctypes.data_as(S), None, None, ctypes.byref(nnz), msg, len(msg))
    indices, data = np.zeros(nnz.value, dtype=np.uintp), np.zeros(nnz.value)
    if st == 0:
        st = lib.bn_flat_form_factors_csr(h, indptr.ctypes.data_as(S), indices.ctypes.data_as(S),
                                          data.ctypes.data_as(Dp), ctypes.byref(nnz), msg, len(msg))
    if st != 0:
        _raise(lib, st, msg)
    return sp.csr_matrix((data, indices.astype(np.int64), indptr.astype(np.int64)), shape=(n, n))


class Traced:
    """The path tracer's answer (Result.trace, Scene.trace, and their trace_image): layers (E, KE, ...,
    rest, L), mean[name] and its statistical error[name] (per patch: the standard error of the mean,
    shape (patches, 3); per pixel: the variance of the mean, shape (height, width, 3)); read-only arrays.
    The tracer shares only the scene with the radiosity side (no F, K or solve): an independent check."""

    def __init__(self, layers: List[str], mean: Dict[str, np.ndarray], error: Dict[str, np.ndarray],
                 spp: int, seed: int) -> None:
        self.layers, self.mean, self.error, self.spp, self.seed = layers, mean, error, spp, seed

    def __repr__(self) -> str:
        return "<bounce.Traced %s, %d samples, seed %d>" % (",".join(self.layers), self.spp, self.seed)


def _trace_args(spp, bounces, seed, threads):
    return (_int("spp", spp, unsigned=True), _int("bounces", bounces, bits=32), _int("seed", seed, unsigned=True),
            _int("threads", threads, bits=32))


def _layer_names(lib, bounces):
    buf = ctypes.create_string_buffer(32)
    return [lib.bn_layer_name(k, bounces, buf, len(buf)).decode() for k in range(bounces + 3)]


def _trace_patches(lib: Any, h: Any, n: int, spp: int, bounces: int, seed: int, threads: int) -> Traced:
    spp, bounces, seed, threads = _trace_args(spp, bounces, seed, threads)
    nl = max(bounces, 0) + 3
    mean, se = np.zeros((nl, n, 3)), np.zeros((nl, n, 3))
    Dp = ctypes.POINTER(ctypes.c_double)
    msg = ctypes.create_string_buffer(2048)
    st = lib.bn_flat_trace_patches(h, spp, bounces, seed, threads, mean.ctypes.data_as(Dp), se.ctypes.data_as(Dp),
                                   msg, len(msg))
    if st != 0:
        _raise(lib, st, msg)
    names_ = _layer_names(lib, bounces)
    return Traced(names_, {k: _frozen(mean[i]) for i, k in enumerate(names_)},
                  {k: _frozen(se[i]) for i, k in enumerate(names_)}, spp, seed)


def _trace_image(lib: Any, h: Any, size: Tuple[int, int], spp: int, bounces: int, seed: int, threads: int,
                 eye: Optional[Sequence[float]], look: Optional[Sequence[float]], fov: Optional[float]) -> Traced:
    spp, bounces, seed, threads = _trace_args(spp, bounces, seed, threads)
    w, hh = (_int("size", v, unsigned=True, bits=32) for v in size)
    nl = max(bounces, 0) + 3
    mean, var = (np.zeros((nl, hh, w, 3), dtype=np.float32) for _ in range(2))
    Dp, Fp = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_float)
    vec = lambda v: None if v is None else ctypes.cast((ctypes.c_double * 3)(*[_float("eye/look", x) for x in v]), Dp)  # noqa: E731
    msg = ctypes.create_string_buffer(2048)
    st = lib.bn_flat_trace_image(h, w, hh, spp, bounces, seed, vec(eye), vec(look), float(fov or 0), threads,
                                 mean.ctypes.data_as(Fp), var.ctypes.data_as(Fp), msg, len(msg))
    if st != 0:
        _raise(lib, st, msg)
    names_ = _layer_names(lib, bounces)
    return Traced(names_, {k: _frozen(mean[i]) for i, k in enumerate(names_)},
                  {k: _frozen(var[i]) for i, k in enumerate(names_)}, spp, seed)


class _Traceable:
    """trace() and trace_image() for a Result and a Scene (the same scene, the tracer's own rays)."""
    _lib: Any
    _h: Any
    patches: int

    def trace(self, spp: int = 64, bounces: int = 3, seed: int = 1, threads: int = 0) -> Traced:
        """The path tracer's estimate of every patch's mean outgoing radiance, bounce by bounce (E ..
        K^bounces E, rest, L), spp independent samples per patch, with each mean's standard error:
        what `bounce trace --patches-out` writes, and what `bounce crosscheck` compares with. Compare
        with the radiosity answer: z = (result.terms[1] - t.mean["KE"]) / t.error["KE"]."""
        return _trace_patches(self._lib, self._h, self.patches, spp, bounces, seed, threads)

    def trace_image(self, size: Tuple[int, int] = (256, 256), spp: int = 16, bounces: int = 3, seed: int = 1,
                    eye: Optional[Sequence[float]] = None, look: Optional[Sequence[float]] = None,
                    fov: Optional[float] = None, threads: int = 0) -> Traced:
        """The path tracer's camera image (bounce trace's EXR, in memory): per layer a float32 array
        (height, width, 3), mean over spp samples per pixel, and the variance of that mean."""
        return _trace_image(self._lib, self._h, size, spp, bounces, seed, threads, eye, look, fov)


class Result(_Traceable):
    """A solved scene. L, terms, rest and the per-patch arrays are read-only numpy arrays (an edit
    raises: bounce never ignores one); relight() solves again for new materials on the same F and
    replaces them (arrays taken before keep the old answer)."""

    L: np.ndarray
    terms: List[np.ndarray]
    rest: Optional[np.ndarray]
    emission: np.ndarray

    def __init__(self, handle: Any, lib: Any, scene: Optional["Scene"] = None) -> None:
        self._h, self._lib = handle, lib
        self._scene = scene   # solved on a Scene's own K: the scene owns the handle (and its F)
        n = lib.bn_flat_patches(handle)
        self.patches = n
        self.area, self.normal, self.centroid, self.reflectance, self.face = _patch_data(lib, handle, n)
        self.relight_gain = 0.0
        self._answer()

    def _answer(self) -> None:
        """The solve's arrays and report, copied from the library (read-only)."""
        lib, handle, n = self._lib, self._h, self.patches

        def copy(ptr):
            return _frozen(np.ctypeslib.as_array(ptr, shape=(n, 3)).copy()) if ptr else None

        self.L = copy(lib.bn_flat_L(handle))
        self.terms = [copy(lib.bn_flat_term(handle, k)) for k in range(lib.bn_flat_terms(handle))]
        self.rest = copy(lib.bn_flat_rest(handle))
        self.emission = copy(lib.bn_flat_emission(handle))
        self.stop_reason = lib.bn_flat_stop_reason(handle).decode()
        self.method = lib.bn_flat_method(handle).decode()
        self.transport = lib.bn_flat_transport(handle).decode()
        self.iterations = lib.bn_flat_iterations(handle)
        self.residual = lib.bn_flat_residual(handle)
        # the monitor's rows (row 0: the initial guess E): arrays per column
        rows = ctypes.POINTER(ctypes.c_double)()
        m = lib.bn_flat_history(handle, ctypes.byref(rows))
        table = np.ctypeslib.as_array(rows, shape=(m, 7)).copy() if m else np.zeros((0, 7))
        self.history = {k: table[:, j] for j, k in enumerate(
            ("iteration", "residual_max", "residual_rms", "change", "bound", "error_bound", "seconds"))}

    def relight(self, Le: Optional[Mapping[str, RGB]] = None, rho: Optional[Mapping[str, RGB]] = None,
                refine: bool = False) -> "Result":
        """Solves again for new materials on this result's own F (no form factor is computed): Le and
        rho map material names to a new emitted radiance (W m^-2 sr^-1, >= 0) or reflectance (in
        [0, 1]), each one number (grey) or three. L, terms, rest, emission and reflectance are
        replaced; the result is returned. Dense and sparse K give exactly a fresh solve of the edited
        scene. Under the hierarchy the links refined for the old light are kept (self.relight_gain:
        how much brighter the new L gets than the old, by which their error bound grows there);
        refine=True builds links for the new light."""
        Le, rho = dict(Le or {}), dict(rho or {})
        for option, d in (("Le", Le), ("rho", rho)):
            for name in d:
                if not isinstance(name, str):
                    raise BounceError("EUSAGE", "%s: material names are strings, not %r" % (option, name))
        mats = sorted(set(Le) | set(rho))
        n = len(mats)
        nan = np.full(3, np.nan)
        R = np.array([_rgb("rho", m, rho[m]) if m in rho else nan for m in mats]).reshape(n, 3)
        L = np.array([_rgb("Le", m, Le[m]) if m in Le else nan for m in mats]).reshape(n, 3)
        names_c = (ctypes.c_char_p * max(n, 1))(*[m.encode() for m in mats])
        Dp = ctypes.POINTER(ctypes.c_double)
        msg = ctypes.create_string_buffer(2048)
        st = self._lib.bn_flat_relight(self._h, n, names_c, np.ascontiguousarray(R).ctypes.data_as(Dp),
                                       np.ascontiguousarray(L).ctypes.data_as(Dp), int(bool(refine)), msg, len(msg))
        if st != 0 and self._lib.bn_flat_L(self._h):
            self._answer()
        if st != 0:
            _raise(self._lib, st, msg)
        self.reflectance = _patch_data(self._lib, self._h, self.patches)[3]
        if self._scene is not None:   # the scene's materials are the ones just edited
            self._scene._refresh()
        self._answer()
        self.relight_gain = self._lib.bn_flat_relight_gain(self._h)
        return self

    def form_factors(self, sparse: bool = False) -> Any:
        """F as a dense patches x patches array (a copy: the library may store it in float, as here
        its values are), or with sparse=True a scipy.sparse CSR matrix made from the stored entries
        (no dense copy). Raises BounceError under the hierarchy, which keeps no pairs."""
        return _form_factors(self._lib, self._h, self.patches, sparse)

    def bake(self, path: PathLike, per_bounce: bool = True, mesh: MeshName = "elements", ldr: bool = False,
             exposure: Optional[float] = None, crease: Optional[float] = None, gather: Union[bool, GatherName] = True,
             vertices: Optional[int] = None, **more: Any) -> None:
        """Bakes this solution to vertex colours as `bounce bake` does, by the extension of `path`
        (.ply, .om, .obj, .glb, .gltf): per_bounce adds every term; mesh="input" bakes the scene's
        own polygons; ldr writes 8-bit sRGB (glTF: a COLOR_1 set beside the float ones) at
        `exposure` EV (None: automatic). gather (as --gather; True: "final", the default) computes
        each vertex by the final gather, the element mesh refined where L changes up to `vertices`
        vertices (as --bake-vertices; None: 100,000; 0: the patches' own); False or "none" bakes the
        patches' values. crease: degrees (None: 30). More options of `bounce bake` by their names:
        names("bake_options") (gather_rays, bake_tol, flat, no_colour_sets). Atomic, as every bounce
        output."""
        gname = _gather_name(gather)
        msg = ctypes.create_string_buffer(2048)
        ev = float("nan") if exposure is None else float(exposure)
        nv = -1 if vertices is None else _int("vertices", vertices, unsigned=True)
        if "bake_vertices" in more:   # the command line's name of vertices=
            if vertices is not None:
                raise BounceError("EUSAGE", "vertices= and bake_vertices= name the same option: give one")
            nv = -1 if more["bake_vertices"] is None else _int("bake_vertices", more["bake_vertices"], unsigned=True)
            more = {k: v for k, v in more.items() if k != "bake_vertices"}
        cr = 0.0 if crease is None else _float("crease", crease)
        self._set(("bake_options",), more)
        st = self._lib.bn_flat_bake(self._h, os.fsencode(path), int(per_bounce), _name("mesh", mesh), int(ldr), ev,
                                    cr, _name("gather", gname), nv, b"python bounce package", msg, len(msg))
        if st != 0:
            _raise(self._lib, st, msg)

    def images(self, path: PathLike, size: Optional[Tuple[int, int]] = None, spp: Optional[int] = None,
               eye: Optional[Sequence[float]] = None, look: Optional[Sequence[float]] = None,
               fov: Optional[float] = None, previews: bool = True, smooth: bool = False, half: bool = False,
               gather: Union[bool, GatherName] = True, **more: Any) -> None:
        """Camera images of every layer as `bounce bounces` writes them: path (FILE.exr, a layer per
        term, rest and L) and with previews FILE.<layer>.png and the contact sheet. The camera is the
        scene's NAME.camera sidecar, else in front of the box; size=(w, h), spp, eye, look (scene
        units) and fov (degrees) override it. gather: a names("gather") name, "final" (or True) the
        final gather per pixel (as `bounce bounces` by default; the solve must keep KE, bounces >= 1),
        "none" (or False) each pixel the value of the patch it sees. More options of `bounce bounces`
        by their names: names("image_options") (light_samples, gather_samples, gather_filter,
        hit_emitters, tree_emitters, tile, exposure, crease, up)."""
        gname = _gather_name(gather)
        self._set(("image_options",), more)
        Dp = ctypes.POINTER(ctypes.c_double)
        vec = lambda v: None if v is None else (ctypes.c_double * 3)(*[float(x) for x in v])
        e, lk = vec(eye), vec(look)
        w, h = size if size else (0, 0)
        msg = ctypes.create_string_buffer(2048)
        st = self._lib.bn_flat_images(self._h, os.fsencode(path), int(w), int(h), int(spp or 0),
                                      ctypes.cast(e, Dp) if e else None, ctypes.cast(lk, Dp) if lk else None,
                                      float(fov or 0), int(previews), int(smooth), int(half), _name("gather", gname),
                                      b"python bounce package", msg, len(msg))
        if st != 0:
            _raise(self._lib, st, msg)

    def render(self, size: Tuple[int, int] = (256, 256), spp: Optional[int] = None,
               eye: Optional[Sequence[float]] = None, look: Optional[Sequence[float]] = None,
               fov: Optional[float] = None, smooth: bool = False,
               gather: Union[bool, GatherName] = True, **more: Any) -> Dict[str, np.ndarray]:
        """The images of images() in memory, no file: {"E": ..., "KE": ..., "K2E": ..., "rest": ...,
        "L": ...}, each a float32 array of shape (height, width, 3), rows from the top, radiance in
        W m^-2 sr^-1 (camera, gather and further options as images() takes them)."""
        gname = _gather_name(gather)
        self._set(("image_options",), more)
        w, h = (_int("size", v, bits=32) for v in size)
        lib, nl = self._lib, self._lib.bn_flat_layers(self._h)
        out = np.zeros((max(nl, 1), h, w, 3), dtype=np.float32) if w > 0 and h > 0 else np.zeros(0, np.float32)
        Dp = ctypes.POINTER(ctypes.c_double)
        vec = lambda v: None if v is None else (ctypes.c_double * 3)(*[float(x) for x in v])
        e, lk = vec(eye), vec(look)
        msg = ctypes.create_string_buffer(2048)
        st = lib.bn_flat_render(self._h, w, h, int(spp or 0), ctypes.cast(e, Dp) if e else None,
                                ctypes.cast(lk, Dp) if lk else None, float(fov or 0), int(smooth),
                                _name("gather", gname), out.ctypes.data_as(ctypes.POINTER(ctypes.c_float)),
                                msg, len(msg))
        if st != 0:
            _raise(lib, st, msg)
        buf = ctypes.create_string_buffer(32)
        return {lib.bn_flat_layer_name(self._h, k, buf, len(buf)).decode(): _frozen(out[k]) for k in range(nl)}

    def _set(self, vocabularies: Sequence[str], more: Mapping[str, Any]) -> None:
        """The call's further options into the library (bn_flat_set: those not given are reset)."""
        msg = ctypes.create_string_buffer(2048)
        st = self._lib.bn_flat_set(self._h, _more_text(vocabularies, more), msg, len(msg))
        if st != 0:
            _raise(self._lib, st, msg)

    def __del__(self):
        if getattr(self, "_h", None) and getattr(self, "_scene", None) is None:
            self._lib.bn_flat_free(self._h)
        self._h = None

    def __repr__(self) -> str:
        return "<bounce.Result %d patches, %s on %s, %s after %d iterations, %d terms>" % (
            self.patches, self.method, self.transport, self.stop_reason, self.iterations, len(self.terms))


_DIAG = ("row_sum_min", "row_sum_max", "row_sum_rms_dev", "reciprocity_residual", "k_norm_inf",
         "occluded_fraction", "rays", "nonzeros", "bytes", "seconds", "rows_above_one", "row_sum_tol")


def _gather_name(gather: Union[bool, str]) -> str:
    """True: the final gather (the library's first gather name), False: none; a name as it is."""
    return names("gather")[0 if gather else 1] if isinstance(gather, bool) else gather


def _name(option, v):
    """A name option as C wants it; None or a non-string raises, naming the option."""
    if not isinstance(v, str):
        raise BounceError("EUSAGE", "%s must be a string, not %r" % (option, v))
    return v.encode()


def _int(option, v, unsigned=False, bits=64):
    """An integer option for a C int (bits=32) or size_t (unsigned): bool and float refused, and a
    value the C type cannot hold raises here, before ctypes would wrap it. Ranges within the type
    are the library's to check."""
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise BounceError("EUSAGE", "%s must be an integer, not %r" % (option, v))
    if unsigned and v < 0:
        raise BounceError("EUSAGE", "%s %d is negative" % (option, v))
    lo, hi = (0, 2**bits) if unsigned else (-2**(bits - 1), 2**(bits - 1))
    if not lo <= v < hi:
        raise BounceError("EUSAGE", "%s %d is out of range" % (option, v))
    return int(v)


def _float(option, v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise BounceError("EUSAGE", "%s must be a number, not %r" % (option, v))
    return float(v)


# The command line's further solve options, by the same names (None: the library's default).
_MORE = ("max_iter", "atol", "stop", "seed", "precision", "storage", "cache", "ff")


def _more_text(vocabularies: Sequence[str], more: Mapping[str, Any]) -> Optional[bytes]:
    """The library's further options (names("scene_options"), ...: the command line's flags by their
    struct names) as its `name=value` lines: bools as 1/0, numbers as they are, (x, y, z) as x,y,z,
    names as strings; None values left out. Names the library does not take raise BounceError."""
    known = [n for v in vocabularies for n in names(v)]
    lines = []
    for k, v in more.items():
        if k not in known:
            raise BounceError("EUSAGE", "unknown option %s (here: %s)" % (k, ", ".join(known)))
        if v is None:
            continue
        if isinstance(v, (bool, np.bool_)):
            text = "1" if v else "0"
        elif isinstance(v, (int, float, np.integer, np.floating)):
            text = repr(float(v)) if isinstance(v, (float, np.floating)) else str(int(v))
        elif isinstance(v, str) and "\n" not in v and v:
            text = v
        elif isinstance(v, (list, tuple, np.ndarray)) and len(v) == 3:
            text = ",".join(repr(_float(k, x)) for x in v)
        else:
            raise BounceError("EUSAGE", "%s: %r is not a flag, a number, a name or three numbers" % (k, v))
        lines.append("%s=%s" % (k, text))
    return "\n".join(lines).encode() if lines else None


def _more(o: Any, more: Mapping[str, Any]) -> None:
    """max_iter, atol, stop, seed, precision, storage, cache, ff into the flat options, the rest
    (names("scene_options"), names("solve_options")) into its `more` lines (types checked here,
    values and names by the library)."""
    o.more = _more_text(("scene_options", "solve_options"), {k: v for k, v in more.items() if k not in _MORE})
    if more.get("max_iter") is not None:
        o.max_iter = _int("max_iter", more["max_iter"], unsigned=True)
    if more.get("atol") is not None:
        o.atol = _float("atol", more["atol"])
    if more.get("seed") is not None:
        o.seed = _int("seed", more["seed"], unsigned=True)
    for name in ("stop", "precision", "storage", "ff"):
        if more.get(name) is not None:
            setattr(o, name, _name(name, more[name]))
    if more.get("cache") is not None:
        o.cache = os.fsencode(os.fspath(more["cache"]))


def _opts(lib, unit="m", method="auto", transport="auto", bounces=3, tol=None, patches=None, patch_size=None,
          eps=None, threads=0, progress=False, visibility="exact", **more):
    """The flat options: the library's defaults, then what was given (None: the default). Values are
    checked by the library, once for every front end; here only their Python types."""
    if "ff_visibility" in more:   # the command line's name of visibility=
        if visibility != "exact":
            raise BounceError("EUSAGE", "visibility= and ff_visibility= name the same option: give one")
        visibility = more.pop("ff_visibility")
    o = _Opts()
    lib.bn_flat_opts_default(ctypes.byref(o))
    o.unit, o.method = _name("unit", unit), _name("method", method)
    o.transport, o.visibility = _name("transport", transport), _name("visibility", visibility)
    o.bounces = _int("bounces", bounces, bits=32)
    if tol is not None:
        o.tol = _float("tol", tol)
    if patches is not None:
        o.patches = _int("patches", patches, unsigned=True)
    if patch_size is not None:
        o.patch_size = _float("patch_size", patch_size)
    if eps is not None:
        o.eps = _float("eps", eps)
    o.threads = _int("threads", threads, bits=32)
    o.quiet = 0 if progress else 1
    o.sigint = 1 if _main_thread() else 0   # Ctrl-C stops the C loops, then raises KeyboardInterrupt
    _more(o, more)
    return o


_CHECK = ("family", "alpha", "crit", "within", "worst_z", "worst_z_raw", "power_crit", "power_worst_z", "few_hits",
          "spp", "seconds")


class CrossCheck:
    """bounce crosscheck's answer (bounce.crosscheck): passed (the verdict), the figures of its verdict
    line (family, alpha, crit, within, worst_z, worst_z_raw, power_crit, power_worst_z, few_hits, spp,
    seconds), and per layer (E .. K^b E, rest, L) what was compared, arrays (entries, 3): radiosity,
    trace (the tracer's mean), error (its standard error) and allowance (what the two may differ by
    without an error: 0 under the default patch model). z(name) is (radiosity - trace) / error."""

    passed: bool
    family: int
    alpha: float
    crit: float
    within: int
    worst_z: float
    worst_z_raw: float
    power_crit: float
    power_worst_z: float
    few_hits: int
    spp: int
    seconds: float

    def __init__(self, lib: Any, h: Any, bounces: int) -> None:
        f = (ctypes.c_double * len(_CHECK))()
        lib.bn_flat_check_figures(h, f)
        for k, v in zip(_CHECK, f):
            setattr(self, k, int(v) if k in ("family", "within", "few_hits", "spp") else float(v))
        self.passed = bool(lib.bn_flat_check_pass(h))
        nl, n = lib.bn_flat_check_layers(h), lib.bn_flat_check_entries(h)
        a = [np.zeros((nl, n, 3)) for _ in range(4)]
        Dp = ctypes.POINTER(ctypes.c_double)
        lib.bn_flat_check_arrays(h, *[x.ctypes.data_as(Dp) for x in a])
        self.layers = _layer_names(lib, bounces)
        self.radiosity, self.trace, self.error, self.allowance = (
            {k: _frozen(x[i]) for i, k in enumerate(self.layers)} for x in a)

    def z(self, layer: str) -> np.ndarray:
        """(radiosity - trace) / error per entry and channel (NaN where the error is 0: exact, e.g. E)."""
        e = self.error[layer]
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(e > 0, (self.radiosity[layer] - self.trace[layer]) / e, np.nan)

    def __repr__(self) -> str:
        return "<bounce.CrossCheck %s: worst z %.3g (crit %.3g), %d/%d within, %d samples>" % (
            "pass" if self.passed else "FAIL", self.worst_z, self.crit, self.within, self.family, self.spp)


def crosscheck(path: PathLike, unit: UnitName = "m", spp: int = 1024, bounces: int = 3, alpha: float = 0.01,
               model: Name = "patch", patches: Optional[int] = None, transport: TransportName = "auto",
               visibility: VisibilityName = "exact", threads: int = 0, progress: bool = False,
               **more: Any) -> CrossCheck:
    """`bounce crosscheck` from Python: radiosity (solved to 1e-10) against the independent path tracer
    (spp samples per patch) on the same patches, every term compared per patch and channel at the
    family-wise false-failure rate alpha. model "patch" (the tracer estimates the patch-constant
    transport) or "continuous" (the light itself; a second mesh level's allowance). Options as solve()
    takes them (seed also keys the tracer). The verdict is CrossCheck.passed; a failed check is an
    answer, not an exception."""
    lib = _load()
    o = _opts(lib, unit, "auto", transport, bounces, None, patches, None, None, threads, progress, visibility, **more)
    h = ctypes.c_void_p()
    msg = ctypes.create_string_buffer(2048)
    st = lib.bn_flat_crosscheck(os.fsencode(path), ctypes.byref(o), _int("spp", spp, unsigned=True),
                                _int("bounces", bounces, bits=32), _float("alpha", alpha), _name("model", model),
                                ctypes.byref(h), msg, len(msg))
    if st != 0:
        _raise(lib, st, msg)
    try:
        return CrossCheck(lib, h, bounces)
    finally:
        lib.bn_flat_check_free(h)


class Study:
    """bounce study's table (bounce.study): one row per setting (and per method where the study compares
    methods); columns[name] is a float array over the rows (x, patches, iterations, err_inf,
    err_max_rel, err_rms_rel, err_surface_max, bound, estimate, t_solve, t_total, ... as the CLI's CSV
    names them; NaN where a figure does not apply), method and value the rows' labels, reference what
    they were measured against and ref_error its estimated error."""

    def __init__(self, lib: Any, h: Any) -> None:
        names_ = lib.bn_flat_study_columns().decode().split(",")
        n = lib.bn_flat_study_rows(h)
        table = np.zeros((n, len(names_)))
        Dp = ctypes.POINTER(ctypes.c_double)
        for r in range(n):
            lib.bn_flat_study_row(h, r, table[r].ctypes.data_as(Dp))
        self.columns: Dict[str, np.ndarray] = {k: _frozen(table[:, i].copy()) for i, k in enumerate(names_)}
        self.method: List[str] = [lib.bn_flat_study_label(h, r, 0).decode() for r in range(n)]
        self.value: List[str] = [lib.bn_flat_study_label(h, r, 1).decode() for r in range(n)]
        e = ctypes.c_double()
        self.reference: str = lib.bn_flat_study_reference(h, ctypes.byref(e)).decode()
        self.ref_error: float = e.value

    def __len__(self) -> int:
        return len(self.method)

    def rows(self, method: str) -> Dict[str, np.ndarray]:
        """The columns of one method's rows ("truncated", "jacobi", ..., or "trace")."""
        keep = np.array([m == method for m in self.method], dtype=bool)
        return {k: v[keep] for k, v in self.columns.items()}

    def __repr__(self) -> str:
        return "<bounce.Study %d rows (%s) against %s>" % (len(self), ",".join(sorted(set(self.method))),
                                                          self.reference[:60])


def study(path: PathLike, vary: str, values: Sequence[Union[float, str]], unit: UnitName = "m",
          method: MethodName = "auto", patches: Optional[int] = None, transport: TransportName = "auto",
          visibility: VisibilityName = "exact", threads: int = 0, progress: bool = False, **more: Any) -> Study:
    """`bounce study --vary VARY=VALUES` from Python: vary "bounces", "max-iter", "tol", "patches",
    "patch-size", "samples", "ff", "spp", "precision" or "eps" over values (names for ff and precision),
    the other settings as solve() takes them (method: the study's default, direct, unless named).
    Returns the table as arrays (Study.columns, Study.rows(method))."""
    lib = _load()
    vocab = {"ff": "ff", "precision": "precision"}.get(vary)
    nums = []
    for v in values:
        if vocab and isinstance(v, str):
            if v not in names(vocab):
                raise BounceError("EUSAGE", "%s %r is not one of %s" % (vary, v, "|".join(names(vocab))))
            nums.append(float(names(vocab).index(v)))
        else:
            nums.append(_float("values", v))
    o = _opts(lib, unit, method, transport, 3, None, patches, None, None, threads, progress, visibility, **more)
    arr = (ctypes.c_double * max(len(nums), 1))(*nums)
    h = ctypes.c_void_p()
    msg = ctypes.create_string_buffer(2048)
    st = lib.bn_flat_study_run(os.fsencode(path), ctypes.byref(o), _name("vary", vary), arr, len(nums),
                               ctypes.byref(h), msg, len(msg))
    if st != 0:
        _raise(lib, st, msg)
    try:
        return Study(lib, h)
    finally:
        lib.bn_flat_study_free(h)


class Scene(_Traceable):
    """A scene file loaded and cut into patches, with its per-patch arrays (numpy): area (scene
    units^2), normal, centroid, reflectance, emission (W m^-2 sr^-1), face (the input polygon).
    form_factors() builds F (with the meshing options given here) and returns it;
    bounce.solve(scene, ...) solves it."""

    path: str
    options: Dict[str, Any]
    patches: int
    area: np.ndarray
    normal: np.ndarray
    centroid: np.ndarray
    reflectance: np.ndarray
    face: np.ndarray
    emission: np.ndarray
    diagnostics: Optional[Dict[str, float]]
    _lib: Any
    _h: Any

    @classmethod
    def load(cls, path: PathLike, unit: UnitName = "m", patches: Optional[int] = None,
             patch_size: Optional[float] = None, transport: TransportName = "auto", eps: Optional[float] = None,
             threads: int = 0, progress: bool = False, visibility: VisibilityName = "exact", **more: Any) -> "Scene":
        lib = _load()
        self = cls()
        self.path = os.fspath(path)
        self.options = dict(unit=unit, patches=patches, patch_size=patch_size, transport=transport, eps=eps,
                            threads=threads, progress=progress, visibility=visibility, **more)
        o = _opts(lib, **self.options)
        h = ctypes.c_void_p()
        msg = ctypes.create_string_buffer(2048)
        st = lib.bn_flat_load(os.fsencode(path), ctypes.byref(o), ctypes.byref(h), msg, len(msg))
        if st != 0:
            _raise(lib, st, msg)
        self._lib, self._h = lib, h
        self.patches = lib.bn_flat_patches(h)
        self._refresh()
        self.diagnostics = None
        return self

    def _refresh(self) -> None:
        """The per-patch arrays from the library (again after a relight of a result solved on this scene)."""
        n, lib, h = self.patches, self._lib, self._h
        self.area, self.normal, self.centroid, self.reflectance, self.face = _patch_data(lib, h, n)
        self.emission = _frozen(np.ctypeslib.as_array(lib.bn_flat_emission(h), shape=(n, 3)).copy())

    def form_factors(self, sparse: bool = False) -> Any:
        """F (patches x patches, row i: the share of patch i's view that each patch fills, with
        visibility), as bounce assembles it for the solve. A dense numpy array, or with sparse=True
        a scipy.sparse CSR matrix when scipy is installed. self.diagnostics then holds the
        assembly's report (row sums, reciprocity, ||K||_inf, rays, seconds, ...)."""
        msg = ctypes.create_string_buffer(2048)
        st = self._lib.bn_flat_operator(self._h, msg, len(msg))
        if st != 0:
            _raise(self._lib, st, msg)
        d = (ctypes.c_double * 12)()
        self._lib.bn_flat_ff_diagnostics(self._h, d)
        self.diagnostics = dict(zip(_DIAG, list(d)))
        return _form_factors(self._lib, self._h, self.patches, sparse)

    def __del__(self):
        if getattr(self, "_h", None):
            self._lib.bn_flat_free(self._h)
            self._h = None


class Operator:
    """A transport operator of your own: apply(x) returns K x for x of shape (patches, 3) (radiance
    per patch and channel; K includes the reflectance). bounce's Jacobi iteration, Neumann series and
    per-bounce terms run on it; give row(i, x) returning (K x)_i (3 values) too and Gauss-Seidel runs
    on it as well (one call per patch per sweep). The direct solve needs entries and is refused. Pass
    it to bounce.solve with the emission E (patches x 3)."""

    def __init__(self, patches: int, apply: Callable[[np.ndarray], npt.ArrayLike],
                 row: Optional[Callable[[int, np.ndarray], npt.ArrayLike]] = None) -> None:
        self.patches = _int("patches", patches, unsigned=True)
        if not callable(apply) or (row is not None and not callable(row)):
            raise BounceError("EUSAGE", "apply (and row, if given) must be callable")
        self.apply = apply
        self.row = row


def _operator_output(what, v, shape):
    """An operator's return value as a float array of `shape`, or BounceError naming what it was."""
    if v is None:
        raise BounceError("EINPUT", "the operator's %s returned None, not an array of shape %s" % (what, shape))
    a = np.asarray(v, dtype=np.float64)
    if a.shape != shape:
        raise BounceError("EINPUT", "the operator's %s returned shape %s, not %s" % (what, a.shape, shape))
    return a


def _solve_operator(op, emission, method, bounces, tol, threads, progress, **more):
    lib = _load()
    n = op.patches
    E = np.ascontiguousarray(emission, dtype=np.float64)
    if E.shape != (n, 3):
        raise BounceError("EUSAGE", "emission has shape %s, not (%d, 3)" % (E.shape, n))
    caught = []

    def tramp(_user, x, y):
        try:
            xa = np.ctypeslib.as_array(x, shape=(n, 3))
            ya = np.ctypeslib.as_array(y, shape=(n, 3))
            ya[...] = _operator_output("apply", op.apply(xa), (n, 3))
            return 0
        except BaseException as e:   # raised again below, after the C loop has stopped
            caught.append(e)
            return 1

    def rtramp(_user, i, x, out):
        try:
            xa = np.ctypeslib.as_array(x, shape=(n, 3))
            oa = np.ctypeslib.as_array(out, shape=(3,))
            oa[...] = _operator_output("row", op.row(i, xa), (3,))
            return 0
        except BaseException as e:
            caught.append(e)
            return 1

    cb = _APPLY(tramp)
    rb = _ROW(rtramp) if op.row is not None else _ROW()
    o = _opts(lib, method=method, bounces=bounces, tol=tol, threads=threads, progress=progress, **more)
    h = ctypes.c_void_p()
    msg = ctypes.create_string_buffer(2048)
    st = lib.bn_flat_solve_operator(n, E.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), cb, rb, None, ctypes.byref(o),
                                    ctypes.byref(h), msg, len(msg))
    if caught:
        if h:
            lib.bn_flat_free(h)
        raise caught[0]
    if st != 0:
        if h:
            lib.bn_flat_free(h)
        _raise(lib, st, msg)
    return Result(h, lib)


def as_linear_operator(result: Result, reflectance: bool = True) -> Any:
    """K of a solved result (F with reflectance=False) as a scipy.sparse.linalg.LinearOperator on
    vectors of 3 x patches values in bounce's order (patch-major: x.reshape(patches, 3)), whatever
    stores it (dense, sparse, the hierarchy's links): for scipy's solvers and eigensolvers, e.g.
    gmres(I - K, E.ravel()). Each product is one application of the library's operator."""
    sp = _scipy_sparse()
    n, lib, h = result.patches, result._lib, result._h
    Dp = ctypes.POINTER(ctypes.c_double)

    def matvec(x: np.ndarray) -> np.ndarray:
        xa = np.ascontiguousarray(np.asarray(x, dtype=np.float64).reshape(3 * n))
        y = np.empty(3 * n)
        msg = ctypes.create_string_buffer(1024)
        st = lib.bn_flat_apply(h, int(reflectance), xa.ctypes.data_as(Dp), y.ctypes.data_as(Dp), msg, len(msg))
        if st != 0:
            _raise(lib, st, msg)
        return y

    return sp.linalg.LinearOperator((3 * n, 3 * n), matvec=matvec, dtype=np.float64)


def solve(path: Union[PathLike, "Scene", Operator], unit: UnitName = "m", method: MethodName = "auto",
          transport: TransportName = "auto", bounces: int = 3, tol: Optional[float] = None, patches: Optional[int] = None,
          patch_size: Optional[float] = None, eps: Optional[float] = None, threads: int = 0,
          progress: bool = False, emission: Optional[npt.ArrayLike] = None, visibility: VisibilityName = "exact",
          **more: Any) -> Result:
    """Loads, meshes, builds K and solves L = E + K L for the scene file at `path`, keeping the
    terms K^0 E .. K^bounces E. Options are those of `bounce solve` (defaults alike; visibility is
    --ff-visibility: "exact" or "rays"). Raises
    BounceError with bounce's message on bad input; an unconverged solve raises too.
    With a bounce.Operator in place of the path, K is yours and `emission` (patches x 3) is E."""
    if isinstance(path, Operator):
        if emission is None:
            raise BounceError("EUSAGE", "an Operator needs emission= (patches x 3)")
        return _solve_operator(path, emission, method, bounces, tol, threads, progress, **more)
    lib = _load()
    if isinstance(path, Scene):   # its own K (built once, kept with the scene): only the solver's options
        late = [k for k in ("seed", "precision", "storage", "cache", "ff") if more.get(k) is not None]
        if late:
            raise BounceError("EUSAGE", "%s= shapes F, which the scene keeps: give it to Scene.load" % late[0])
        so = path.options
        o = _opts(lib, so["unit"], method, so["transport"], bounces, tol, so["patches"], so["patch_size"],
                  so["eps"], threads or so["threads"], progress or so["progress"], so["visibility"],
                  **{**{k: so[k] for k in _MORE if k in so}, **more})
        msg = ctypes.create_string_buffer(2048)
        st = lib.bn_flat_solve_loaded(path._h, ctypes.byref(o), msg, len(msg))
        if st != 0:
            _raise(lib, st, msg)
        return Result(path._h, lib, scene=path)
    else:
        o = _opts(lib, unit, method, transport, bounces, tol, patches, patch_size, eps, threads, progress, visibility,
                  **more)
        file = os.fspath(path)
    h = ctypes.c_void_p()
    msg = ctypes.create_string_buffer(2048)
    st = lib.bn_flat_solve(os.fsencode(file), ctypes.byref(o), ctypes.byref(h), msg, len(msg))
    if st != 0:
        if h:
            lib.bn_flat_free(h)
        _raise(lib, st, msg)
    return Result(h, lib)
