"""Print what a CI run's numbers depend on: the interpreter, the packages pip chose, the BLAS and its threads."""
import importlib.metadata as md
import os
import platform
import sys

PACKAGES = ("numpy", "scipy", "sympy", "fmpy", "pythonfmu", "libcosimpy", "ecospy", "scikit-sundae", "pytest",
            "pytest-xdist", "threadpoolctl")

print(f"python {platform.python_version()} ({sys.executable})")
for name in PACKAGES:
    try:
        version = md.version(name)
    except md.PackageNotFoundError:
        version = "not installed"
    print(f"{name} {version}")
try:
    import numpy  # noqa: F401  (loads numpy's BLAS)
    import scipy.linalg  # noqa: F401  (and scipy's)
    from threadpoolctl import threadpool_info
except ImportError as exc:
    print(f"BLAS: unknown ({exc})")
else:
    for pool in threadpool_info():
        print(f"{pool['internal_api']} {pool['version']} ({pool.get('architecture')}): {pool['num_threads']} threads "
              f"by default ({pool['filepath']})")
print(f"cores: {len(os.sched_getaffinity(0))}; BLAS threads in the suite's processes: "
      f"{os.environ.get('OPENBLAS_NUM_THREADS', '1 (tests/conftest.py)')}")
