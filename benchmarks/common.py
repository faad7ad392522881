"""Helpers shared by the benchmarks: one core per process, the machine, the commit."""

from __future__ import annotations

import contextlib
import datetime as _dt
import os
import platform
import subprocess
from pathlib import Path

#: Thread-pool variables of the numerical libraries; set before NumPy is imported so
#: that every process uses exactly one core and "ms per image on one core" means that.
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")


def one_core() -> None:
    """Restrict this process's numerical libraries (BLAS, OpenCV) to one thread each.

    The environment variables reach worker processes started later; threadpoolctl
    limits the BLAS already loaded here (otherwise its waiting threads count as
    CPU time, and compete with other processes)."""
    for var in THREAD_VARS:
        os.environ.setdefault(var, "1")
    import cv2
    from threadpoolctl import threadpool_limits

    cv2.setNumThreads(1)
    threadpool_limits(1)


def compile_package() -> None:
    """Byte-compile the vision_torsion package as an install leaves it.

    ``pip install`` compiles it; an editable install writes the bytecode at the first
    import, unless ``PYTHONDONTWRITEBYTECODE`` is set (as on some CI machines and this
    one), and then every timed command would compile the modules it imports again."""
    import compileall
    from pathlib import Path

    import vision_torsion

    compileall.compile_dir(str(Path(vision_torsion.__file__).parent), quiet=1)


def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo (platform.processor() elsewhere)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine_info() -> dict:
    """Date, CPU, core count, load and library versions, for comparing runs over time."""
    import cv2
    import numpy
    import scipy
    import skimage

    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:  # pragma: no cover - not on Linux
        load = None
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        usable = os.cpu_count()
    return {
        "date": _dt.datetime.now().astimezone().isoformat(timespec="seconds"),
        "cpu_model": cpu_model(),
        "cores": os.cpu_count(),
        "cores_usable": usable,
        "load_average_1_5_15min": load,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "opencv": cv2.__version__,
        "scikit_image": skimage.__version__,
    }


def git_commit() -> str | None:
    """The benchmarks' checkout's short git commit (None outside a git checkout)."""
    try:
        out = subprocess.run(
            ["git", "-C", str(Path(__file__).resolve().parent), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        )
    except (OSError, subprocess.CalledProcessError):
        return None
    return out.stdout.strip() or None


def write_result(path, content) -> Path:
    """Write a benchmark's own result file atomically: a dict or list as JSON (as
    :func:`vision_torsion.fileio.json_text` writes it), a string as it is.

    These are the repository's files, replaced at every run, so they are written
    here and not through the package's writers, whose folder contract refuses to
    replace a file the tool cannot prove it wrote (the rule for a user's folders).
    """
    import tempfile

    from vision_torsion.fileio import json_text

    path = Path(path)
    text = content if isinstance(content, str) else json_text(content)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path
