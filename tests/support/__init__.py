"""What the tests share, in one place.

``helpers.py`` holds plain functions (standard library only: the runners import it as a script's neighbour),
``problems.py`` the problems and ``(method, lam)`` pairs the library tests run over; the subprocess runners
(``*_runner.py``) and the C masters (``*.c``) sit beside them, found through `SUPPORT`.
"""
from pathlib import Path

SUPPORT = Path(__file__).resolve().parent  # the runners and C masters
ROOT = SUPPORT.parents[1]  # the repository
