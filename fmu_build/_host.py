"""Running the FMUs in a non-Python FMI host (ecos, libcosim's C++ tools, ...).

A pythonfmu FMU embeds a Python interpreter. A Python host (fmpy,
libcosimpy) already has one; a native host does not, and then the FMU's
library fails to load (undefined Python symbols) or its slave cannot import
numpy. The recipe, checked with the native ``ecos`` tool here: preload the
Python shared library, point ``PYTHONHOME`` at the Python installation and
``PYTHONPATH`` at the site-packages that hold numpy and scipy.

``ecos`` comes with the ``ecospy`` package as a binary in its
site-packages folder, installed without the execute bit and off ``PATH``;
`ecos_executable` finds it, makes it executable and checks the shared
library it needs (Intel TBB, Debian's ``libtbb12``).
"""

import ctypes
import importlib.util
import os
import site
import stat
import sys
import sysconfig
from pathlib import Path

__all__ = ["native_host_env", "ecos_executable"]

# The shared libraries the ecos binary links beyond the C/C++ runtime, and the
# Debian package that provides each.
_ECOS_LIBRARIES = {"linux": [("libtbb.so.12", "libtbb12")]}


def native_host_env(base=None):
    """Environment variables a native FMI host needs to run these FMUs.

    Parameters
    ----------
    base : mapping, optional
        Environment to extend (default: ``os.environ``).

    Returns
    -------
    dict
        ``base`` plus ``LD_PRELOAD`` (the Python shared library),
        ``PYTHONHOME`` and ``PYTHONPATH``, for the Python running this code.

    Examples
    --------
    >>> env = native_host_env({})
    >>> sorted(env)
    ['LD_PRELOAD', 'PYTHONHOME', 'PYTHONPATH']
    """
    env = dict(os.environ if base is None else base)
    libdir = sysconfig.get_config_var("LIBDIR") or ""
    soname = sysconfig.get_config_var("INSTSONAME") or sysconfig.get_config_var("LDLIBRARY") or ""
    library = os.path.join(libdir, soname)
    if not os.path.exists(library):
        raise FileNotFoundError(
            f"no shared Python library at {library!r}: this Python was built without --enable-shared, "
            "and a native FMI host cannot embed it"
        )
    env["LD_PRELOAD"] = " ".join(p for p in (library, env.get("LD_PRELOAD", "")) if p)
    env["PYTHONHOME"] = sys.base_prefix
    paths = [p for p in site.getsitepackages() + [site.getusersitepackages()] if os.path.isdir(p)]
    env["PYTHONPATH"] = os.pathsep.join(paths + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return env


def ecos_executable():
    """The ``ecos`` binary shipped by ``ecospy``, made executable.

    Returns
    -------
    pathlib.Path
        The binary, with its execute bits set.

    Raises
    ------
    FileNotFoundError
        When ``ecospy`` is not installed, ships no binary for this platform,
        or a shared library the binary needs is missing; the message says
        what to install.

    Examples
    --------
    >>> try:
    ...     exe = ecos_executable()
    ... except FileNotFoundError as exc:  # ecospy or libtbb12 not installed: says which
    ...     exe = None
    >>> exe is None or (exe.name.startswith("ecos") and os.access(exe, os.X_OK))
    True
    """
    # find_spec does not import ecospy: its import loads libecosc.so with
    # ctypes and dies with OSError when libtbb is missing.
    spec = importlib.util.find_spec("ecospy")
    if spec is None or not spec.origin:
        raise FileNotFoundError("ecos is not installed: python -m pip install ecospy (or the `test` extra)")
    exe = Path(spec.origin).parent / "binaries" / ("ecos.exe" if sys.platform == "win32" else "ecos")
    if not exe.exists():
        raise FileNotFoundError(f"ecospy ships no ecos binary for this platform ({sys.platform}): expected {exe}")
    for soname, package in _ECOS_LIBRARIES.get(sys.platform, []):
        try:
            ctypes.CDLL(soname)
        except OSError:
            raise FileNotFoundError(
                f"ecos needs {soname}: install it with `apt-get install {package}` (the .ci/run script does)"
            ) from None
    mode = exe.stat().st_mode
    wanted = mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH
    if mode != wanted:
        exe.chmod(wanted)  # wheels drop the execute bit
    return exe
