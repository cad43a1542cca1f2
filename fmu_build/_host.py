"""Running the FMUs in a non-Python FMI host (ecos, libcosim's C++ tools, ...).

A pythonfmu FMU embeds a Python interpreter. A Python host (fmpy,
libcosimpy) already has one; a native host does not, and then the FMU's
library fails to load (undefined Python symbols) or its slave cannot import
numpy. The recipe, checked with the native ``ecos`` tool here: preload the
Python shared library, point ``PYTHONHOME`` at the Python installation and
``PYTHONPATH`` at the site-packages that hold numpy and scipy.
"""

import os
import site
import sys
import sysconfig

__all__ = ["native_host_env"]


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
