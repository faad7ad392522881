"""What happens in a camera folder, as it happens: the filesystem events of ``watch``.

:class:`FolderEvents` follows one folder (not its subfolders) with the operating
system's file notifications through the ``watchdog`` package (inotify on Linux,
FSEvents on macOS, ReadDirectoryChangesW on Windows) and tells its reader two things:

- **which files were closed after writing**, with the size and modification time
  they had then (:meth:`FolderEvents.closed`): a file closed and unchanged since is
  complete at once, with no waiting for its size to settle. A file renamed into the
  folder (tethering software writes ``IMG_0001.JPG.part``, then renames it) counts
  as closed too; a file written again after its close is not, until it is closed
  again.
- **that something happened** (:meth:`FolderEvents.wait` returns early), so the
  folder is looked at within milliseconds of a camera finishing a file, not at the
  next poll.

The events only make things faster, never decide alone: the reader still looks at
the folder every poll interval, and a file with no close event is complete when its
size and time stay the same (the polling rule). Polling alone is used, and why is
said (:attr:`FolderEvents.why_polling`), when:

- ``mode="poll"`` is asked for;
- ``watchdog`` is not installed;
- the folder is on a network file system (NFS, SMB/CIFS, sshfs, ...): its
  notifications only see what this computer writes, not what the camera's computer
  does;
- the notifications cannot be set up (Linux's inotify watch or instance limit
  reached, ``fs.inotify.max_user_watches``).

A folder that disappears (a card taken out) stops its notifications; they are set
up again when the folder is back (:meth:`FolderEvents.rearm`).
"""

from __future__ import annotations

import logging
import os
import stat
import threading
from pathlib import Path

__all__ = ["FolderEvents", "EVENT_MODES", "network_filesystem", "NETWORK_FILESYSTEMS"]

logger = logging.getLogger(__name__)
# watchdog's threads log their own shutdown races (an emitter asked for events after
# stop()) at ERROR; with no handler of the application's, Python's last-resort handler
# would print them on a user's terminal. What the events miss, the polling sees.
logging.getLogger("watchdog").addHandler(logging.NullHandler())

#: Longest wait (s) for the observer to stop or drop a folder. Its reading thread can
#: stay blocked in ``read()`` on the inotify descriptor when no event wakes it (a
#: known watchdog behaviour on Linux); the wait is bounded so that ``watch`` always
#: ends on Ctrl-C, and the threads, daemons, end with the process.
STOP_WAIT_S = 2.0


def _bounded(action, what: str) -> None:
    """Run `action` in a daemon thread and wait for it at most :data:`STOP_WAIT_S`;
    its errors (a folder already gone, an observer never started) are logged at
    debug level, never raised."""
    def run():
        try:
            action()
        except (KeyError, OSError, RuntimeError) as exc:
            logger.debug("%s: %s", what, exc)

    worker = threading.Thread(target=run, name="vision-torsion-events-stop", daemon=True)
    worker.start()
    worker.join(timeout=STOP_WAIT_S)
    if worker.is_alive():
        logger.debug("%s did not finish within %g s; left to end with the process", what, STOP_WAIT_S)


#: The ways a folder can be followed: "auto" (filesystem events where they work,
#: else polling) and "poll" (polling only).
EVENT_MODES = ("auto", "poll")

#: File system types (Linux ``/proc/self/mountinfo`` names) whose change
#: notifications do not see writes made by another computer. ``fuse.*`` types are
#: matched by what follows the dot.
NETWORK_FILESYSTEMS = frozenset({
    "nfs", "nfs4", "cifs", "smb3", "smbfs", "ncpfs", "afs", "9p", "ceph", "glusterfs", "lustre",
    "gpfs", "beegfs", "davfs", "sshfs", "rclone", "s3fs", "gcsfuse", "davfs2", "curlftpfs",
})


def _unescape(field: str) -> str:
    """A mountinfo path field with its octal escapes (``\\040`` for a space) decoded."""
    out, i = [], 0
    while i < len(field):
        if field[i] == "\\" and field[i + 1:i + 4].isdigit():
            out.append(chr(int(field[i + 1:i + 4], 8)))
            i += 4
        else:
            out.append(field[i])
            i += 1
    return "".join(out)


def network_filesystem(folder, *, mount_table="/proc/self/mountinfo") -> str | None:
    """The network file system `folder` is on, or None (local, or not known).

    Parameters
    ----------
    folder : path-like
        An existing folder.
    mount_table : path-like
        Linux's table of mounts (the format of ``/proc/self/mountinfo``). Where it
        cannot be read (another system), None is returned.

    Returns
    -------
    str or None
        The file system type (e.g. "nfs4", "cifs", "fuse.sshfs") when it is one of
        :data:`NETWORK_FILESYSTEMS`, else None.
    """
    try:
        lines = Path(mount_table).read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    target = Path(os.path.realpath(folder))
    best, best_type = -1, None
    for line in lines:
        left, sep, right = line.partition(" - ")
        fields, tail = left.split(), right.split()
        if not sep or len(fields) < 5 or not tail:
            continue
        mount = Path(_unescape(fields[4]))
        if (target == mount or mount in target.parents) and len(mount.parts) > best:
            best, best_type = len(mount.parts), tail[0]
    if best_type is None:
        return None
    kind = best_type.removeprefix("fuse.") if best_type.startswith("fuse.") else best_type
    return best_type if kind in NETWORK_FILESYSTEMS else None


class FolderEvents:
    """The filesystem events of one folder (see the module docstring).

    Parameters
    ----------
    folder : path-like
        The folder to follow (its files; subfolders are not looked into). It may not
        exist yet: the notifications are set up by :meth:`rearm` once it does.
    mode : {"auto", "poll"}
        "auto": notifications where they work (else polling, with the reason);
        "poll": polling only.
    observer : callable, optional
        Makes the ``watchdog`` observer (``watchdog.observers.Observer`` by
        default); an observer whose ``schedule`` or ``start`` raises ``OSError``
        (the inotify limits) leaves the folder polled.
    mount_table : path-like
        Passed to :func:`network_filesystem`.

    Raises
    ------
    ValueError
        `mode` is not one of :data:`EVENT_MODES`.

    Use as a context manager, or call :meth:`close`: it stops the observer's threads.
    """

    def __init__(self, folder, *, mode: str = "auto", observer=None, mount_table="/proc/self/mountinfo"):
        if mode not in EVENT_MODES:
            raise ValueError(f"mode must be one of {', '.join(EVENT_MODES)}, got {mode!r}")
        self.folder = Path(folder)
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closed: dict[str, tuple[int, int]] = {}
        self._observer = None
        self._watch = None
        self._identity = None  # (device, inode) of the folder the notifications are on
        self._make_observer = observer
        self._mount_table = mount_table
        #: Why the folder is only polled ("" while notifications are used).
        self.why_polling = "polling was asked for" if mode == "poll" else ""
        if mode == "auto":
            self.rearm()

    # -- the reader's side -------------------------------------------------------

    @property
    def active(self) -> bool:
        """Notifications are being received."""
        return self._watch is not None and not self.why_polling

    def closed(self) -> dict[str, tuple[int, int]]:
        """name -> (size in bytes, modification time in ns) of the files closed after
        writing (or renamed into the folder) and not written since."""
        with self._lock:
            return dict(self._closed)

    def wait(self, timeout: float) -> bool:
        """Wait until something happens in the folder, at most `timeout` seconds;
        True when something did. Polling only: just waits."""
        happened = self._wake.wait(timeout)
        self._wake.clear()
        return happened

    def ensure(self) -> bool:
        """Notifications on the folder as it is now: set up again when the folder was
        gone and is back, or was replaced by another of the same name (its
        notifications stopped with it). True when they are on; cheap (one stat)."""
        if self.why_polling:
            return False
        try:
            st = os.stat(self.folder)
        except OSError:
            return False
        if self._watch is not None and self._identity == (st.st_dev, st.st_ino) and self._alive():
            return True
        return self.rearm()

    def _alive(self) -> bool:
        """The notifications of the folder still come (they stop with the folder,
        which a new one may replace under the same inode number)."""
        emitters = getattr(self._observer, "emitters", None)
        if emitters is None:  # an observer without the listing: trusted
            return True
        return any(e.watch == self._watch and e.is_alive() for e in emitters)

    def rearm(self) -> bool:
        """Set the notifications up (again); True when they are on. Does nothing
        while polling was asked for or decided."""
        if self.why_polling:
            return False
        self._stop_watch()
        try:
            st = os.stat(self.folder)
        except OSError:
            return False  # not there (yet): polled until it is back
        if not stat.S_ISDIR(st.st_mode):
            return False  # a file in its place: polled (and said so by its reader)
        self._identity = (st.st_dev, st.st_ino)
        kind = network_filesystem(self.folder, mount_table=self._mount_table)
        if kind is not None:
            return self._poll_only(f"{self.folder} is on a network file system ({kind}), whose "
                                   "notifications miss what another computer writes")
        try:
            if self._observer is None:
                make = self._make_observer
                if make is None:
                    from watchdog.observers import Observer as make
                self._observer = make()
                self._observer.start()
            self._watch = self._observer.schedule(_Handler(self), str(self.folder), event_filter=_event_filter())
        except ImportError:
            return self._poll_only("the watchdog package is not installed")
        except OSError as exc:  # inotify: watch limit (ENOSPC), instance limit (EMFILE)
            return self._poll_only(f"the file notifications could not be set up ({exc.strerror or exc}; on "
                                   "Linux, fs.inotify.max_user_watches or max_user_instances)")
        return True

    def close(self) -> None:
        """Stop the observer (once), waiting at most :data:`STOP_WAIT_S` for it."""
        observer, self._observer = self._observer, None
        self._watch = None
        if observer is not None:
            def stop():
                observer.stop()
                observer.join(timeout=STOP_WAIT_S)

            _bounded(stop, "stopping the file notifications")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    # -- the observer's side -----------------------------------------------------

    def _poll_only(self, why: str) -> bool:
        logger.info("%s; the folder is polled", why)
        self.why_polling = why
        self.close()
        return False

    def _stop_watch(self) -> None:
        watch, self._watch = self._watch, None
        if watch is not None and self._observer is not None:
            observer = self._observer
            _bounded(lambda: observer.unschedule(watch), f"unscheduling {self.folder}")

    def _changed(self, name: str) -> None:
        with self._lock:
            self._closed.pop(name, None)

    def _complete(self, name: str) -> None:
        try:
            st = os.stat(self.folder / name)
        except OSError:  # gone again already
            self._changed(name)
        else:
            with self._lock:
                self._closed[name] = (st.st_size, st.st_mtime_ns)
        self._wake.set()

    def _gone(self, name: str) -> None:
        self._changed(name)
        self._wake.set()


def _event_filter():
    from watchdog.events import (
        DirDeletedEvent,
        DirMovedEvent,
        FileClosedEvent,
        FileCreatedEvent,
        FileDeletedEvent,
        FileModifiedEvent,
        FileMovedEvent,
    )

    # not opened / closed without writing: watch's own reading would wake it
    return [FileClosedEvent, FileModifiedEvent, FileCreatedEvent, FileMovedEvent, FileDeletedEvent,
            DirDeletedEvent, DirMovedEvent]


def _handler_base():
    try:
        from watchdog.events import FileSystemEventHandler
    except ImportError:
        return object
    return FileSystemEventHandler


class _Handler(_handler_base()):
    """Passes watchdog's events of one folder to its FolderEvents."""

    def __init__(self, owner: FolderEvents):
        super().__init__()
        self.owner = owner

    def _name(self, path) -> str | None:
        p = Path(os.fsdecode(path))
        return p.name if p.parent == self.owner.folder else None

    def on_any_event(self, event) -> None:
        kind = event.event_type
        if event.is_directory:
            if kind in ("deleted", "moved"):  # the folder itself, or a subfolder: look again
                self.owner._wake.set()
            return
        name = self._name(event.src_path)
        if kind == "closed":
            if name:
                self.owner._complete(name)
        elif kind in ("modified", "created"):
            if name:
                self.owner._changed(name)
        elif kind == "deleted":
            if name:
                self.owner._gone(name)
        elif kind == "moved":
            if name:
                self.owner._gone(name)
            dest = self._name(event.dest_path)
            if dest:  # renamed into place: written before, complete now
                self.owner._complete(dest)
