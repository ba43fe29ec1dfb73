"""Loading openseespy (the optional ``crosscheck`` extra) and capturing its console output.

The Linux wheel of openseespy 3.7.1.2 does not import as installed: its bundled ``liblapack.so.3``
needs the bundled ``libblas.so.3`` and ``libgfortran.so.4``, which the dynamic loader does not find
by itself (RUNPATH is not transitive). :func:`load_opensees` preloads them globally first.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib.util
import os
import sys
from pathlib import Path

INSTALL_HINT = "pip install 'femubench[crosscheck]' (openseespy 3.7.1.2)"

_OPS = None


class OpenSeesUnavailable(RuntimeError):
    """openseespy is not installed, or is installed but cannot be imported."""


def installed() -> bool:
    """Whether an openseespy distribution is installed (nothing is imported)."""
    return importlib.util.find_spec("openseespy") is not None


def load_opensees():
    """``openseespy.opensees``, imported once (bundled libraries preloaded, see the module
    docstring).

    Raises :class:`OpenSeesUnavailable` with a one-line reason and the install command."""
    global _OPS
    if _OPS is not None:
        return _OPS
    if not installed():
        raise OpenSeesUnavailable(f"openseespy is not installed; install it with {INSTALL_HINT}")
    spec = importlib.util.find_spec("openseespylinux")
    if spec is not None and spec.origin:
        libdir = Path(spec.origin).parent / "lib"
        for name in (
            "libquadmath.so.0",
            "libgfortran.so.4",
            "libgomp.so.1",
            "libblas.so.3",
            "liblapack.so.3",
        ):
            if (libdir / name).exists():
                with contextlib.suppress(OSError):
                    ctypes.CDLL(str(libdir / name), mode=ctypes.RTLD_GLOBAL)
    try:
        import openseespy.opensees as ops
    except Exception as exc:  # noqa: BLE001 - any import failure is reported the same way
        reason = " ".join(str(exc).split())
        raise OpenSeesUnavailable(
            f"openseespy is installed but does not import ({reason}); "
            f"reinstall it with {INSTALL_HINT}"
        ) from exc
    _OPS = ops
    return ops


def openseespy_version() -> str:
    """The installed openseespy version (``?`` if unknown)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("openseespy")
    except PackageNotFoundError:
        return "?"


@contextlib.contextmanager
def captured_output(path: Path):
    """Redirect the process's stdout and stderr (file descriptors, so C++ output too) to
    ``path``."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with open(path, "ab") as f:
        os.dup2(f.fileno(), 1)
        os.dup2(f.fileno(), 2)
        try:
            yield
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
