"""Where the example scripts write: out/ always, docs/_generated only with an explicit ``--docs``.

The docs pages include the files of docs/_generated, which are tracked by git;
running a script must not change the checkout, so a script writes its reports
and figures to out/ (ignored by git) and regenerates docs/_generated only when
run with ``--docs``. Every script uses this one module for that choice.
"""
import contextlib
import io
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "docs" / "_generated"
OUT = ROOT / "out"
FLAG = "--docs"
HELP = "write the reports and figures the docs include to the tracked docs/_generated (default: out/ only)"


def docs_requested(argv=None):
    """True when the command line asks for ``--docs``."""
    return FLAG in (sys.argv[1:] if argv is None else argv)


def other_args(argv=None):
    """The command-line arguments without ``--docs`` (for scripts that read sys.argv by position)."""
    return [a for a in (sys.argv[1:] if argv is None else argv) if a != FLAG]


def output_folder(docs=None):
    """``docs/_generated`` with ``--docs``, else ``out/``; it exists afterwards."""
    folder = GENERATED if (docs_requested() if docs is None else docs) else OUT
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def output_path(filename, docs=None):
    """``docs/_generated/filename`` with ``--docs``, else ``out/filename``; the folder exists afterwards."""
    return output_folder(docs) / filename


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
    """Print as usual, and write the printed text under `title` to ``output_path(name + ".md")``."""
    buffer = io.StringIO()
    with contextlib.redirect_stdout(_Tee(sys.stdout, buffer)):
        yield
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "default")
    path = output_path(f"{name}.md")
    path.write_text(
        f"## {title}\n\n`python examples/{name}.py`, run {time.strftime('%Y-%m-%d')} on {platform.machine()} "
        f"({os.cpu_count()} cores, OPENBLAS_NUM_THREADS={threads}, Python {platform.python_version()}):\n\n"
        f"```text\n{buffer.getvalue().rstrip()}\n```\n"
    )
    print(f"wrote {path.relative_to(ROOT)}")
