"""Benchmark output for the docs: what a script prints also goes to docs/_generated/<name>.md.

The benchmarks page (docs/reference/benchmarks.md) includes every file of
docs/_generated, so its tables are always the last run of the scripts.
"""
import contextlib
import io
import os
import platform
import sys
import time
from pathlib import Path

GENERATED = Path(__file__).resolve().parent.parent / "docs" / "_generated"


class _Tee(io.TextIOBase):
    def __init__(self, *streams):
        self.streams = streams

    def write(self, s):
        for stream in self.streams:
            stream.write(s)
        return len(s)

    def flush(self):
        for stream in self.streams:
            stream.flush()


@contextlib.contextmanager
def printed_to_docs(name, title):
    """Print as usual, and write the printed text to docs/_generated/`name`.md under `title`."""
    buffer = io.StringIO()
    with contextlib.redirect_stdout(_Tee(sys.stdout, buffer)):
        yield
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "default")
    GENERATED.mkdir(parents=True, exist_ok=True)
    (GENERATED / f"{name}.md").write_text(
        f"## {title}\n\n`python examples/{name}.py`, run {time.strftime('%Y-%m-%d')} on {platform.machine()} "
        f"({os.cpu_count()} cores, OPENBLAS_NUM_THREADS={threads}, Python {platform.python_version()}):\n\n"
        f"```text\n{buffer.getvalue().rstrip()}\n```\n"
    )
