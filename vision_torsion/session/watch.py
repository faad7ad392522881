"""Follow a test as it is shot: ``vision-torsion watch``.

:class:`Watcher` is the testable core: each :meth:`Watcher.tick` looks at the
camera folder once (no sleeping, the clock passed in), and returns what happened
as :class:`WatchEvent` values. :func:`watch_session` calls it in a loop, prints the
events, and ends on Ctrl-C (or when every planned image is in) by calling its
`finish` (the ``watch`` command passes one that writes the report: the report is
a layer above the session, so the session layer does not call it itself).

A tick:

1. lists the camera folder (``--camera-dir``, else ``SESSION_DIR/images``). Gone?
   Says so once, and waits for it to come back.
2. A file is complete when it was closed after writing and has not changed since
   (the filesystem events of :mod:`.events`: a tick follows within milliseconds),
   or when its size and modification time have not changed for `settle_s` (a
   camera writes in chunks; the rule when events are not available: polling), and
   it decodes (a PNG without its IEND chunk, a JPEG without its end marker is
   waited for, not measured). Files whose time is already older than `settle_s`
   when first seen (a resumed watch) are complete at once. A file larger than an
   image file may be (:data:`~vision_torsion.images.MAX_IMAGE_FILE_BYTES`) is set
   aside, naming it and the limit, without being read.
3. Each complete file, in capture order (file time, then natural name order), is
   measured (:class:`~.shots.ShotMeasurer`: ``process``'s cache, shared) and bound
   to the next planned row not yet photographed (with no ``--camera-dir``, a file
   saved under a row's planned name is bound to that row). A file not complete yet
   holds back every file after it in capture order, so none takes its row; one that
   stays undecodable for `give_up_s` (stalled half-way: a slow card, a network
   share) is bound to its row as failed, with a warning naming it, and ``process``
   fails that row. A bound file that changes (a re-shot under the same name, a
   stalled file finished late) is measured again and announced. Non-images,
   copies (the same bytes as an earlier file) and files beyond the last row are set
   aside with a message naming them; nothing is ever written in the camera folder.
4. Its angle (against its orientation's reference image, ``angle_sign`` applied),
   Δangle and the step checks of :mod:`.steps`, plus the marker search failing, a
   blurred image (marker edges > 1.5× as wide as in the reference) or a saturated
   one (> 0.5 % of the pixels at full scale), are returned at once as events. The
   steps of a later orientation are also compared with the same steps of the
   orientations before it. After a missed shot decided in an orientation (its files
   a row early) its last row is left for no photograph, and after an extra shot
   (its files a row late) its last photograph is set aside with a message, so that
   the next orientation's photographs bind to its own rows (``bind`` with the fix
   binds them all). A shot missed at an orientation's second-to-last row is said at
   that image (its step is already two planned steps in one against the same steps
   elsewhere); the photograph next in line for the last row, out of line there while
   the one before it fits as the last row's, is the next orientation's reference:
   the missed shot is decided and it binds to that reference. Where the load turns
   back a row early and a missed shot fits several rows of the branch (a soft zone
   the loop has not shown yet), those rows are named, and the photographs after it
   are checked as each of them binds them: a warning after it is said when every
   one gives it, so the shift already said is not said again as new mistakes.
5. The live page ``OUT_DIR/live.html`` (:mod:`.live`) is rewritten atomically (then
   its stamp ``live-stamp.js``: an open page reloads within 0.25 s), and
   ``binding.json`` (unless every file is under its planned name) every few
   seconds and at the end.

Resuming is running it again: the complete files are bound in the same order, from
the cache, and a ``binding.json`` written by ``bind`` keeps its skipped files and
missing rows.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import shlex
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import SessionError
from ..fileio import atomic_write_text, check_output_dir, check_replaceable, same_folder
from ..images import IMAGE_SUFFIXES, MAX_IMAGE_FILE_BYTES
from ..measure import natural_key
from ..measurements import output_folder
from .bind import row_text
from .binding import Binding, load_binding, write_binding
from .events import EVENT_MODES, FolderEvents
from .live import LIVE_PAGE_NAME, LIVE_STAMP_NAME, LivePoint, live_page, stamp_script
from .load import load_session
from .steps import StepPoint, StepWarning, check_steps, gear_kinks

__all__ = ["WatchEvent", "Watcher", "watch_session", "WatchResult", "printable"]

logger = logging.getLogger(__name__)



@dataclass(frozen=True)
class WatchEvent:
    """Something a tick saw.

    Attributes
    ----------
    kind : str
        "shot" (a photograph bound and measured), "warning" (about a photograph),
        "retracted" (a warning the next image showed to be the gear), "replaced" (a
        bound file changed: measured again), "ignored" (a file set aside), "leftover"
        (a photograph beyond the last row), "deleted",
        "folder_gone" (the camera folder is not there: gone, or not made yet),
        "folder_back", "complete" (every row has its photograph).
    file : str
        The file concerned ("" for folder events).
    message : str
        One line for the terminal, naming the file (and the row).
    line : int or None
        The manifest CSV line concerned.
    """

    kind: str
    file: str
    message: str
    line: int | None = None


@dataclass
class _Seen:
    size: int
    mtime_ns: int
    since: float  # clock time the size and time were first seen as they are
    first_undecodable: float | None = None


@dataclass
class _Bound:
    row: object
    file: str
    pair: object | None
    message: str
    warnings: list
    angle: float = math.nan
    delta: float = math.nan
    result: object | None = None  # AngleResult against the orientation's reference
    stat: tuple | None = None  # (size, mtime_ns) of the file when it was measured
    image_hash: str = ""
    stalled: str | None = None  # why a file that never completed holds its row
    own: list = field(default_factory=list)  # the image's own warnings (not its steps')


class Watcher:
    """The core of ``watch``: one :meth:`tick` at a time (see the module docstring).

    Parameters
    ----------
    session_dir : path-like
        The session folder (session.toml, manifest.csv).
    camera_dir : path-like, optional
        The camera's folder; ``SESSION_DIR/images`` by default.
    out_dir : path-like, optional
        Output folder (``SESSION_DIR/results``): the shared cache and live.html.
    settle_s : float
        Seconds a file's size and time must stay the same before it is read.
    give_up_s : float
        Seconds a settled file may stay undecodable (half-written: a slow card, a
        network share) before it is bound to its row as failed, with a warning
        naming it; the files after it in capture order wait for it meanwhile, so
        none of them takes its row. It is measured again when it changes.
    page : bool
        Write the live page (after every tick that took in a photograph).
    binding_every_s : float
        Seconds between rewrites of ``binding.json`` (also written when every row has
        its photograph, and on closing).
    clock : callable
        Monotonic clock (seconds); tests pass their own.
    events : {"auto", "poll"}
        Follow the camera folder's filesystem events (:mod:`.events`; polling where
        they do not work, :attr:`events` ``.why_polling`` says why), or only poll.

    Raises
    ------
    SessionError
        The session is unusable, the camera folder is the output folder,
        `settle_s` or `give_up_s` is not a finite number of seconds >= 0, or
        `events` is not one of "auto", "poll".
    OutputError
        The output folder, or with a camera folder the session folder (where
        ``binding.json`` goes), cannot be written, or the output folder holds a
        ``live.html`` or ``live-stamp.js`` this tool did not write: said before any
        photograph.

    Use as a context manager (or call :meth:`close`): closing merges the cache.
    """

    def __init__(self, session_dir, *, camera_dir=None, out_dir=None, settle_s: float = 1.0,
                 give_up_s: float = 10.0, page: bool = True, binding_every_s: float = 5.0,
                 clock=time.monotonic, events: str = "auto"):
        from .shots import ShotMeasurer

        for what, value in (("settle_s", settle_s), ("give_up_s", give_up_s)):
            if not (isinstance(value, (int, float)) and 0 <= value < math.inf):
                raise SessionError(f"{what} = {value!r}: expected a finite number of seconds >= 0",
                                   reason="bad_option")
        if events not in EVENT_MODES:
            raise SessionError(f"events = {events!r}: expected one of {', '.join(EVENT_MODES)}",
                               reason="bad_option")
        self.session = load_session(session_dir, check_files=False)
        folder = self.session.folder
        self.camera_mode = camera_dir is not None
        self.camera = Path(camera_dir).absolute() if camera_dir is not None else folder / "images"
        self.out = output_folder(folder, out_dir)
        if same_folder(self.camera, self.out):
            raise SessionError(f"{self.camera}: the camera folder cannot be the output folder")
        # before the first photograph: a watch must not announce itself and then die
        check_output_dir(self.out)  # live.html and the cache
        if page:  # another program's page or stamp is refused before anything is written
            check_replaceable([self.out / LIVE_PAGE_NAME, self.out / LIVE_STAMP_NAME])
        if self.camera_mode:
            check_output_dir(folder)  # binding.json
        self.settle_s, self.give_up_s, self.page, self.clock = settle_s, give_up_s, page, clock
        rows = self.session.manifest.rows
        self.rows = rows
        prior = load_binding(folder) if self.camera_mode else None
        same = prior is not None and prior.camera_dir.resolve() == self.camera.resolve()
        self.skipped = set(prior.skipped) if same else set()
        self.missing = set(prior.missing) if same else set()
        self.by_name = {row.image: row for row in rows} if not self.camera_mode else {}
        self.seen: dict[str, _Seen] = {}
        self.done: set[str] = set()
        self.set_aside: dict[str, str] = {}
        self.hashes: dict[str, str] = {}
        self.bound: dict[int, _Bound] = {}  # manifest position -> photograph
        self.order: list[int] = []  # positions in capture order
        self.notices: list[str] = []
        self.folder_gone = False
        self.folder_seen = False  # a folder never seen has not "disappeared": it is not there yet
        self.timings: list[dict] = []
        cfg = self.session.config
        self.step_torque = cfg.rig.step_torque_nm
        self.torques = [self.session.torque(row).torque_nm for row in rows]
        self.sign = int(cfg.angle_sign)  # inverted when the first load turns against it
        self.sign_decided: int | None = None  # the first loaded photograph's position (-1: right)
        self.swapped: dict[int, tuple[int, str]] = {}  # position -> (its partner, the diagnosis)
        # orientation -> rows its files are off by after its decided missed (+1 each) and
        # extra (-1 each) shots: rows no photograph takes, photographs that belong before
        self.shift: dict[float, int] = {}
        self.overflow: dict[float, int] = {}  # orientation -> its photographs set aside so far
        # position where the load turned back a row early -> positions of the photographs whose
        # rows a missed shot fits (the files from one of them on are a row early)
        self.turned_early: dict[int, list[int]] = {}
        # orientation -> (its photograph that shows its last row's load, the next orientation's
        # reference that came after it): a shot missed at the orientation's second-to-last row
        self.ended_early: dict[float, tuple[int, int]] = {}
        self.measurer = ShotMeasurer(self.session, self.out).__enter__()
        self.events = FolderEvents(self.camera, mode=events)
        self._closed = False
        self.binding_every_s = binding_every_s
        self._binding_written = -math.inf

    # -- the public face ---------------------------------------------------------

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def close(self) -> None:
        """Merge the cache logs and write the final page (once)."""
        if not self._closed:
            self._closed = True
            self.events.close()
            self.measurer.__exit__(None, None, None)
            if self.bound:
                self._save(force=True)
            if self.page:
                self.write_page(finished=True)

    @property
    def complete(self) -> bool:
        """Every row has its photograph (or was declared missing)."""
        unshot = self.unshot()
        return all(i in self.bound or row.line in self.missing or i in unshot for i, row in enumerate(self.rows))

    def next_row(self):
        """(position, row) of the next row to photograph, or None."""
        unshot = self.unshot()
        for i, row in enumerate(self.rows):
            if i not in self.bound and row.line not in self.missing and i not in unshot:
                return i, row
        return None

    def _carried(self, orientation: float, n: int) -> int:
        """Rows the files after `orientation` are still off by, of the `n` its
        decided missed (+) and extra (-) shots put them off: those not realigned at
        its end (:meth:`unshot`, the photographs set aside)."""
        if n > 0:
            return 0 if orientation != self.rows[-1].orientation_deg else n
        return n + self.overflow.get(orientation, 0)

    def unshot(self) -> set[int]:
        """Positions of the rows no photograph takes as bound: the last rows of an
        orientation whose files are a row early after a decided missed shot (the
        ``bind`` fix marks the missed row instead), so that the next orientation's
        photographs bind to its own rows. None in the plan's last orientation (no
        photograph comes after it: its rows wait, as after a missed shot in a
        session of one orientation)."""
        out: set[int] = set()
        for orientation, n in self.shift.items():
            if n > 0 and orientation != self.rows[-1].orientation_deg:
                mine = [i for i, row in enumerate(self.rows) if row.orientation_deg == orientation
                        and i not in self.bound and row.line not in self.missing]
                out.update(mine[-n:])
        return out

    def wait(self, timeout: float) -> bool:
        """Wait until something happens in the camera folder (a file closed, renamed
        or deleted), at most `timeout` seconds; True when something did (polling:
        just waits)."""
        return self.events.wait(timeout)

    def _vanished(self, names) -> list[WatchEvent]:
        """A notice for each file seen before that is no longer among `names`."""
        events = []
        for name in sorted(set(self.seen) - names):
            info = self.seen.pop(name)
            if name in self.done:
                pos = next((p for p, b in self.bound.items() if b.file == name), None)
                where = f", bound to {row_text(self.rows[pos])}" if pos is not None else ""
                events.append(self._notice("deleted", name, f"{name} was deleted after it was "
                                           f"measured{where}; its measurement is kept (cache), "
                                           "but process and bind will need the file back"))
            elif info is not None:
                events.append(self._notice("deleted", name, f"{name} was deleted before it was "
                                           "complete; not bound"))
        return events

    def _camera_entries(self, events: list[WatchEvent]) -> list | None:
        """The camera folder's files, or None when the folder is not there (gone, or not
        made yet: said once, in `events`, as is its coming back)."""
        try:
            entries = [e for e in os.scandir(self.camera) if e.is_file()]
        except (FileNotFoundError, NotADirectoryError):
            if not self.folder_gone:
                self.folder_gone = True
                events.append(self._notice("folder_gone", "", f"{self.camera}: the camera folder "
                                           "has disappeared; waiting for it to come back "
                                           "(nothing measured so far is lost; Ctrl-C to stop)"
                                           if self.folder_seen else f"{self.camera}: no such "
                                           "folder yet; waiting for it (check --camera-dir if the "
                                           "camera does not make it; Ctrl-C to stop)"))
            return None
        if self.folder_gone:
            self.folder_gone = False
            events.append(self._notice("folder_back", "", f"{self.camera}: the camera folder is "
                                       + ("back" if self.folder_seen else "there")))
        self.folder_seen = True
        return entries

    def tick(self, now: float | None = None) -> list[WatchEvent]:
        """Look at the camera folder once; return what happened (module docstring)."""
        now = self.clock() if now is None else now
        events: list[WatchEvent] = []
        entries = self._camera_entries(events)
        if entries is None:
            return events
        events += self._vanished({e.name for e in entries})
        self.events.ensure()  # on again after the folder was gone or replaced
        closed = self.events.closed()
        ready, unsettled, changed_bound = [], [], []
        wall = time.time()
        for e in entries:
            name = e.name
            if name in self.set_aside:
                continue
            if name not in self.done and Path(name).suffix.lower() not in IMAGE_SUFFIXES:
                self.set_aside[name] = "not an image"
                events.append(self._notice("ignored", name, f"{name}: not an image file (expected "
                                           f"{', '.join(IMAGE_SUFFIXES)}); not bound"))
                continue
            if name in self.skipped:
                self.set_aside[name] = "skipped"
                continue
            try:
                st = e.stat()
            except OSError:  # vanished meanwhile: the next tick says so
                continue
            if (big := self._too_large(name, st.st_size)) is not None:
                events.append(big)
                continue
            info = self.seen.get(name)
            if info is None or (info.size, info.mtime_ns) != (st.st_size, st.st_mtime_ns):
                old = wall - st.st_mtime > self.settle_s
                self.seen[name] = info = _Seen(st.st_size, st.st_mtime_ns,
                                               -math.inf if old else now)
            # closed after writing and unchanged since, or unchanged for settle_s
            settled = (now - info.since >= self.settle_s
                       or closed.get(name) == (st.st_size, st.st_mtime_ns))
            order = (st.st_mtime_ns, natural_key(name), name)
            if name in self.done:
                pos = self._position(name)
                if pos is not None and self.bound[pos].stat != (st.st_size, st.st_mtime_ns) and settled:
                    changed_bound.append((pos, name))
            elif settled:
                ready.append(order)
            else:
                unsettled.append(order)
        changed = False
        for pos, name in changed_bound:
            new = self._remeasure(pos, name, now)
            changed = changed or bool(new)
            events += new
        # capture order is binding order: a file still being written (or stalled
        # half-way) holds back every file after it, so none takes its row
        first_unsettled = min(unsettled, default=None)
        for order in sorted(ready):
            if first_unsettled is not None and order > first_unsettled:
                break
            name = order[2]
            new = self._handle(name, now)
            changed = changed or bool(new)
            events += new
            if name not in self.done and name not in self.set_aside:
                break  # waited for (not decodable yet): the files after it wait too
        if changed and self.complete:
            events.append(WatchEvent("complete", "", f"all {len(self.rows)} planned images are in"))
        if changed:
            self._save(now=now)
        return events

    # -- one file ----------------------------------------------------------------

    def _notice(self, kind, name, message, line=None) -> WatchEvent:
        self.notices.append(message)
        return WatchEvent(kind, name, message, line)

    def _too_large(self, name: str, size: int) -> WatchEvent | None:
        """A file not bound yet and larger than the image reader accepts: set aside
        without being read (its notice), else None."""
        if size <= MAX_IMAGE_FILE_BYTES or name in self.done:
            return None
        self.set_aside[name] = "too large"
        return self._notice("ignored", name, f"{name}: {size} bytes, larger than an image file may be "
                            f"({MAX_IMAGE_FILE_BYTES} bytes); not read, not bound")

    def _position(self, name: str) -> int | None:
        return next((p for p, b in self.bound.items() if b.file == name), None)

    def _handle(self, name: str, now: float) -> list[WatchEvent]:
        """A file that looks complete: measure it and bind it, or wait."""
        t0 = time.perf_counter()
        path = self.camera / name
        shot = self.measurer.measure(path)
        info = self.seen.get(name)
        stalled = None
        if shot.undecodable:
            if info is not None and info.first_undecodable is None:
                info.first_undecodable = now
            if info is not None and now - info.first_undecodable < self.give_up_s:
                return []  # still being written, most likely: wait
            # stalled half-written (a slow card, a network share): it takes its row
            # as a failed image, so the photographs after it keep theirs
            stalled = (f"still not a complete image after {self.give_up_s:g} s ({shot.message}); "
                       "bound to this row as failed, so that the photographs after it keep "
                       "their rows. It is measured again when it changes; if it is not a "
                       f"photograph of this row, leave it out with `vision-torsion bind "
                       f"--skip {name}`")
        elif not shot.image_hash:
            return []  # unreadable: deleted meanwhile (the next tick says so), or no access
        digest = shot.image_hash
        if stalled is None and digest in self.hashes:
            self.set_aside[name] = "copy"
            return [self._notice("ignored", name, f"{name}: the same bytes as {self.hashes[digest]} "
                                 "(a copy, not a new photograph); not bound")]
        if stalled is None:
            self.hashes[digest] = name
        pos = None
        if not self.camera_mode:
            row = self.by_name.get(f"images/{name}")
            pos = self.rows.index(row) if row is not None and self.rows.index(row) not in self.bound else None
        if pos is None:
            nxt = self.next_row()
            if (nxt is not None and self.order and self.camera_mode
                    and (last := self.rows[self.order[-1]]).orientation_deg != nxt[1].orientation_deg
                    and self.overflow.get(last.orientation_deg, 0) < -self.shift.get(last.orientation_deg, 0)):
                # after an extra shot the files are a row late: this is the orientation's last one
                o = last.orientation_deg
                self.overflow[o] = self.overflow.get(o, 0) + 1
                self.set_aside[name] = "a row late"
                return [self._notice("ignored", name, f"{name}: orientation {o:g}'s last photograph (its files "
                                     "are a row late after the extra shot warned about): not bound here, so that "
                                     f"the next photograph binds to {row_text(nxt[1])}; `bind` with the fix "
                                     "binds it to its row")]
            if nxt is None:
                self.done.add(name)
                return [self._notice("leftover", name, f"{name}: every planned row already has its "
                                     f"photograph ({len(self.rows)} rows); not bound (an extra shot?)")]
            pos = nxt[0]
            pos = self._next_reference(pos, shot)
        self.done.add(name)
        self._bind(pos, name, shot, info)
        self.bound[pos].stalled = stalled
        events = self._check(pos, shot)
        self.timings.append({**shot.timings, "live": time.perf_counter() - t0 - shot.timings.get("decode", 0.0),
                             "file": name, "cached": shot.cached})
        return events

    def _bind(self, pos: int, name: str, shot, info) -> None:
        b = _Bound(self.rows[pos], name, shot.pair, shot.message, [],
                   stat=None if info is None else (info.size, info.mtime_ns), image_hash=shot.image_hash)
        if pos not in self.bound:
            self.order.append(pos)
        self.bound[pos] = b

    def _remeasure(self, pos: int, name: str, now: float) -> list[WatchEvent]:
        """A bound file whose size or time changed (a re-shot under the same name, or
        a stalled file finished late): measured again, and said so."""
        old = self.bound[pos]
        info = self.seen.get(name)
        shot = self.measurer.measure(self.camera / name)
        if shot.undecodable:
            if info is not None and info.first_undecodable is None:
                info.first_undecodable = now
            if info is not None and now - info.first_undecodable < self.give_up_s:
                return []  # being rewritten: wait for it
        if not shot.image_hash and (shot.undecodable or not shot.message):
            return []
        # an unreadable replacement (too large, no permission) is no longer the image measured:
        # its row fails with the reason, as in `process`, instead of keeping the old angle
        if shot.image_hash == old.image_hash:  # touched, not changed
            old.stat = None if info is None else (info.size, info.mtime_ns)
            return []
        if self.hashes.get(old.image_hash) == name:
            del self.hashes[old.image_hash]
        if shot.image_hash and not shot.undecodable:
            self.hashes.setdefault(shot.image_hash, name)
        self._bind(pos, name, shot, info)
        b = self.bound[pos]
        b.stalled = None if not shot.undecodable else old.stalled
        for x in self.bound.values():  # the reference may be the one replaced: angles again
            if x.row.orientation_deg == b.row.orientation_deg:
                x.result = None
        notice = self._notice("replaced", name, f"{name} changed after it was measured (a re-shot, "
                              "or a file written late): measured again for "
                              f"{row_text(b.row)}; its old result is dropped", b.row.line)
        return [notice] + self._check(pos, shot)

    def _check(self, pos: int, shot) -> list[WatchEvent]:
        """The image checks of the new photograph, then its orientation's (angles,
        steps, swaps, the axis, the sign); events: its line, then the warnings
        found now, in capture order (on it, or on an image before it that it
        decided)."""
        from .shots import image_warnings, other_polarity_mismatch, polarity_note

        b = self.bound[pos]
        row = b.row
        own: list[str] = []
        if b.stalled is not None:
            own.append(b.stalled)
        elif shot.pair is None:  # no hash: the file could not be read at all
            own.append(f"{'marker not found' if shot.image_hash else 'not read'}: {shot.message}")
        ref = self._reference(row.orientation_deg)
        reference = self.bound[ref].pair if ref is not None and ref != pos else None
        own += image_warnings(shot.pair, reference, shot.saturated_fraction)
        if mismatch := other_polarity_mismatch(shot.pair, reference, self.session.settings.polarity):
            own.append(mismatch)  # process fails its row
        b.own = own
        before = {p: list(x.warnings) for p, x in self.bound.items()}
        derived: dict[int, list[str]] = {p: [] for p in self.bound}
        steps: list[tuple[int, object]] = []
        loops: list = []  # the step points of the orientations before, each judged against them
        for orientation in dict.fromkeys(x.row.orientation_deg for x in self.bound.values()):
            steps += self._analyse(orientation, derived, loops)
        kinks = gear_kinks([w for _, w in steps])  # the gear's own, seen twice: not mistakes
        options: list[str] = []  # every fix so far, in capture order: one bind command applies them all
        net: dict[float, int] = {}
        for n, (p, w) in sorted(enumerate(steps), key=lambda t: self.order.index(t[1][0])):
            if n not in kinks:
                # the files after an extra shot are a row late, after a missed shot a row early
                # (in the orientation of the mistake, and after it where not realigned)
                o = self.bound[p].row.orientation_deg
                new = self.step_fix(p, w, net.get(o, 0) + sum(self._carried(x, k) for x, k in net.items() if x != o))
                if w.awaiting_next:  # not decided: the fix it would take, not applied to the files after it
                    derived[p].insert(0, w.message + ("; if so, " + self.bind_fix(*options, *new) if new else ""))
                    continue
                net[o] = (net.get(o, 0) + new.count("--missing") - new.count("--skip")
                          + (p in self.turned_early))
                options += new
                derived[p].insert(0, w.message + ("; " + self.bind_fix(*options) if new else ""))
        self.shift = net
        if self.sign_decided in derived:
            derived[self.sign_decided].insert(0, self.sign_message(self.sign_decided))
        for p, x in self.bound.items():
            x.warnings = x.own + derived[p]
        number = self.order.index(pos) + 1
        line = (f"{number:4d}/{len(self.rows)}  {b.file} → {row_text(row)}  "
                f"τ={self.torques[pos]:+.5f} N·m  "
                + (f"θ={b.angle:+.4f}°  Δθ=" + (f"{b.delta:+.4f}°" if math.isfinite(b.delta) else "—")
                   if math.isfinite(b.angle) else "θ=—")
                + (f"  ({note})" if (note := polarity_note(b.pair, self.session.settings.polarity)) else ""))
        events = [WatchEvent("shot", b.file, line, row.line)]
        for p in sorted(self.bound, key=self.order.index):
            x = self.bound[p]
            old = [] if p == pos else before.get(p, [])
            for w in x.warnings:
                if w not in old:
                    events.append(WatchEvent("warning", x.file, f"{x.file} ({row_text(x.row)}): {w}",
                                             x.row.line))
            if old and not x.warnings:
                events.append(WatchEvent("retracted", x.file, f"{x.file} ({row_text(x.row)}): "
                                         "not a mistake after all: the gear's own change of stiffness "
                                         "(the same step elsewhere in the loop shows it too)", x.row.line))
        return events

    def _reference(self, orientation: float) -> int | None:
        return next((p for p in sorted(self.bound) if self.bound[p].row.orientation_deg == orientation
                     and self.bound[p].row.phase == "reference"), None)

    def _analyse(self, orientation: float, derived: dict, loops: list) -> list[tuple[int, object]]:
        """Angles, step checks, swaps, the axis and the sign of one orientation's
        photographs so far: the step warnings [(position, StepWarning)]; the swaps'
        and the axis' messages are added to `derived` (position -> messages). The
        steps are compared with the same steps of `loops` (the step points of the
        orientations photographed before) where this one has not shown them yet;
        its own points are appended to `loops`."""
        from ..angle import pair_angle
        from .axis import check_axis
        from .steps import first_load_inverted

        same = [p for p in self.bound if self.bound[p].row.orientation_deg == orientation]
        ref = self._reference(orientation)
        if ref is None or self.bound[ref].pair is None:
            return []
        rb = self.bound[ref]
        seq = sorted((p for p in same if p >= ref), key=self.order.index)
        ok = [p for p in seq if self.bound[p].pair is not None]
        self._angles(rb, ok, pair_angle)
        points = self._points(ok)
        if self.sign_decided is None:
            inverted = first_load_inverted(points)
            if inverted is not None or any(self.torques[p] != 0 for p in ok[1:]):
                self.sign_decided = ok[inverted] if inverted is not None else -1
            if inverted is not None:
                self.sign = -self.sign
                for x in self.bound.values():
                    x.result = None
                self._angles(rb, ok, pair_angle)
                points = self._points(ok)
        unshot = self.unshot()
        open_end = any(row.orientation_deg == orientation and i not in self.bound and i not in unshot
                       and row.line not in self.missing for i, row in enumerate(self.rows))
        # the plan's loads after the newest photograph's row (in this orientation)
        after = [self.torques[i] for i in range(ok[-1] + 1, len(self.rows)) if self.rows[i].orientation_deg
                 == orientation and i not in unshot and self.rows[i].line not in self.missing] if ok else None
        # verdicts from the images so far and the next only: a warning once said stays
        warns = check_steps(points, step_torque_nm=self.step_torque, open_end=open_end, hindsight=False,
                            earlier=loops, plan_after=after)
        if warns and warns[-1].index == len(ok) - 1 and len(ok) >= 3:
            self._try_swap(ok, points, warns, open_end, loops, after)
            points = self._points(ok)
            warns = check_steps(points, step_torque_nm=self.step_torque, open_end=open_end, hindsight=False,
                                earlier=loops, plan_after=after)
        # a missed shot's signature is said before the next photograph only where that one may
        # never come or be the next orientation's (the second-to-last row): elsewhere it decides
        warns = [w for w in warns if not w.awaiting_next or self._second_to_last(ok[w.index])]
        turn = next((k for k, p in enumerate(ok) if p in self.turned_early), None)
        warns = [self._turned_early(ok, points, w, loops) if turn is None or w.index <= turn else w
                 for w in warns]
        turn = next((k for k, p in enumerate(ok) if p in self.turned_early), None)
        if turn is not None:
            warns, points = self._after_turn(ok, points, warns, turn, loops, open_end)
        if orientation in self.ended_early:
            warns = self._ended_early(orientation, ok, points, warns)
        loops.append(points)
        for p in ok:
            if p in self.swapped:
                derived[p].append(self.swapped[p][1])
        for moved in check_axis([self.bound[p].pair for p in ok]):
            derived[ok[moved.index]].append(moved.message)
            # the orientation is to be shot again from there: the steps into the moved image and
            # after it (the turn of the view added to one of them) are not mistakes of their own
            warns = [w for w in warns if w.index < moved.index]
        return [(ok[w.index], w) for w in warns]

    def _angles(self, rb, ok, pair_angle) -> None:
        """Each photograph's angle (``sign`` applied) and Δangle, in capture order;
        only the new ones are measured (the recurrence of sequence_angles)."""
        prev = math.nan
        for p in ok:
            x = self.bound[p]
            if x.result is None:
                near = 0.0 if not math.isfinite(prev) else self.sign * prev
                x.result = pair_angle(rb.pair, x.pair, near_deg=near)
            x.angle = self.sign * x.result.angle_deg
            x.delta = x.angle - prev
            prev = x.angle

    def _points(self, ok) -> list[StepPoint]:
        """The step points, the angles of two photographs found swapped exchanged."""
        def angle(p):
            return self.bound[self.swapped[p][0] if p in self.swapped else p].angle

        return [StepPoint(self.torques[p], angle(p), self.bound[p].result.angle_std_deg) for p in ok]

    def _try_swap(self, ok, points, warns, open_end, loops, plan_after=None) -> None:
        """The newest photograph warned: were it and the one before taken the other way
        round? If exchanging them makes their steps fit, they are recorded as swapped
        (with the ``bind`` fix) and checked that way from now on."""
        a, b = ok[-2], ok[-1]
        before = ok[-3]
        if a in self.swapped or b in self.swapped or warns[-1].kind != "wrong_direction":
            return
        torques = [self.torques[p] for p in (before, a, b)]
        if (torques[1] - torques[0]) * (torques[2] - torques[1]) <= 0:
            return  # across a reversal of the load: a swap cannot be told from the gear there
        trial = points[:-2] + [StepPoint(points[-2].torque_nm, points[-1].angle_deg, points[-1].angle_std_deg),
                               StepPoint(points[-1].torque_nm, points[-2].angle_deg, points[-2].angle_std_deg)]
        # at the plan's turning load the newest photograph turning back is also what a shot missed
        # earlier in the branch gives (its files a row early): the exchanged pair's newest step must
        # then fit as well (judged as if closed), not wait undecided
        turning = bool(plan_after) and (plan_after[0] - torques[2]) * (torques[2] - torques[1]) < 0
        after = check_steps(trial, step_torque_nm=self.step_torque, open_end=open_end and not turning,
                            hindsight=False, earlier=loops, plan_after=plan_after)
        if any(w.index >= len(ok) - 3 for w in after) or len(after) >= len(warns):
            return
        if turning:  # where the newest photograph shows the first step back just as well, wait for the next
            back = points[:-1] + [StepPoint(plan_after[0], points[-1].angle_deg, points[-1].angle_std_deg)]
            if not [w for w in check_steps(back, step_torque_nm=self.step_torque, open_end=False, hindsight=False,
                                           earlier=loops) if w.index >= len(back) - 1]:
                return
        fa, fb = self.bound[a].file, self.bound[b].file
        fix = (self.bind_fix("--swap", fa, fb) if self.camera_mode
               else f"fix: exchange the names of {fa} and {fb}")
        text = (f"{fa} and {fb} look swapped: {fa} shows the load of line {self.bound[b].row.line} "
                f"and {fb} that of line {self.bound[a].row.line} (their angle steps fit the plan the "
                f"other way round); {fix}")
        self.swapped[a] = (b, text)
        self.swapped[b] = (a, text)

    def _second_to_last(self, pos: int) -> bool:
        """Whether row `pos` is its orientation's second-to-last."""
        o = self.rows[pos].orientation_deg
        return (pos + 1 < len(self.rows) and self.rows[pos + 1].orientation_deg == o
                and (pos + 2 == len(self.rows) or self.rows[pos + 2].orientation_deg != o))

    def _measured(self, orientation: float) -> list[int] | None:
        """The positions of `orientation`'s photographs from its reference on, in
        capture order, that the last tick measured (a marker pair and an angle);
        None while its reference has no marker pair."""
        ref = self._reference(orientation)
        if ref is None or self.bound[ref].pair is None:
            return None
        return [p for p in sorted(self.bound, key=self.order.index) if self.rows[p].orientation_deg == orientation
                and p >= ref and self.bound[p].pair is not None and self.bound[p].result is not None]

    def _earlier_points(self, orientation: float) -> list[list[StepPoint]]:
        """The step points of the orientations photographed before `orientation`
        (their angles as the last tick measured them)."""
        out = []
        for o in dict.fromkeys(self.rows[p].orientation_deg for p in self.order):
            if o == orientation:
                break
            ok = self._measured(o)
            if ok is not None:
                out.append(self._points(ok))
        return out

    def _next_reference(self, pos: int, shot) -> int:
        """The row the photograph `shot`, next in line for row `pos`, is bound to:
        `pos`, or the next orientation's reference when `pos` is an orientation's
        last row and the photograph is not of this orientation while the one before
        it shows this last row's load (a shot missed at the second-to-last row).

        Evidence (both needed): bound to `pos`, its step from the photograph before
        is out of line (the flexspline or the target was re-oriented: a jump, or
        the angle back near the reference); and with the photograph before it
        taken as the last row's, that photograph's step over the two planned
        steps fits (the same steps elsewhere in the loop, or the branch's trend)
        while, bound as it is, it does not."""
        from ..angle import pair_angle

        row = self.rows[pos]
        if (not self.camera_mode or shot.pair is None or pos + 1 >= len(self.rows) or pos + 1 in self.bound
                or self.rows[pos + 1].orientation_deg == row.orientation_deg
                or self.rows[pos + 1].phase != "reference" or row.orientation_deg in self.ended_early):
            return pos
        o = row.orientation_deg
        ok = self._measured(o)
        if ok is None or len(ok) < 3 or ok[-1] != pos - 1:
            return pos
        ref = self._reference(o)
        points, loops = self._points(ok), self._earlier_points(o)
        last = points[-1]
        new = pair_angle(self.bound[ref].pair, shot.pair, near_deg=self.sign * last.angle_deg)
        as_bound = points + [StepPoint(self.torques[pos], self.sign * new.angle_deg, new.angle_std_deg)]
        ended = points[:-1] + [StepPoint(self.torques[pos], last.angle_deg, last.angle_std_deg)]

        def end_warned(seq):
            return [w for w in check_steps(seq, step_torque_nm=self.step_torque, open_end=False, hindsight=False,
                                           earlier=loops, plan_after=()) if w.index >= len(seq) - 2]

        jump = [w for w in end_warned(as_bound) if w.index == len(as_bound) - 1]
        if not jump or end_warned(ended):
            return pos
        self.ended_early[o] = (ok[-1], pos + 1)
        return pos + 1

    def _ended_early(self, orientation: float, ok, points, warns) -> list:
        """`warns` with the decided missed shot at the orientation's last
        photograph, which shows its last row's load (:meth:`_next_reference`)."""
        p, nxt = self.ended_early[orientation]
        if p not in ok or ok[-1] != p or len(ok) < 3:
            return warns
        k = len(ok) - 1
        d_theta = points[k].angle_deg - points[k - 1].angle_deg
        d_tau = points[k].torque_nm - points[k - 1].torque_nm
        old = next((w for w in warns if w.index == k), None)
        ratio = old.ratio if old is not None else math.nan
        nb = self.bound[nxt] if nxt in self.bound else None
        after = f"the next photograph, {nb.file}, is not of this orientation" if nb else "the next photograph is not"
        message = (f"step out of line: Δangle {d_theta:+.4f}°"
                   + (f" is {ratio:.2f}× the expected step" if math.isfinite(ratio) else "")
                   + f" for a planned torque step of {d_tau:+.5f} N·m, and {after} (its angle is off this "
                   "orientation's loop: the flexspline or the target re-oriented), so this photograph is the "
                   "orientation's last: two planned steps in one: a missed shot (this photograph shows the next "
                   f"row's load, {row_text(self.rows[p + 1])}; the next photograph is bound to "
                   f"{row_text(self.rows[nxt])})")
        decided = StepWarning(k, "large_step", d_theta, d_tau, ratio, message,
                              torque_span_nm=(points[k - 1].torque_nm, points[k].torque_nm))
        return [w for w in warns if w.index != k] + [decided]

    def _turned_early(self, ok, points, warning, loops):
        """`warning` with the diagnosis and fix when it is a photograph of a turning
        load that already turns back (a wrong direction) and a shot missed in its
        branch explains it: the rows whose photograph, marked missed, leaves the
        branch without a warning are named. Where the loop has not shown these
        steps before (its first half, in the first orientation), a soft zone or a
        switch hides the double step among its neighbours and several rows fit:
        ``bind`` after the orientation tells them apart against the rest of the
        loop, which is the fix given. Other warnings are returned as they are."""
        k = warning.index
        if warning.kind != "wrong_direction" or k < 3 or not self.camera_mode:
            return warning
        pos = ok[k]
        row, after = self.rows[pos], pos + 1
        way = self.torques[ok[k - 1]] - self.torques[ok[k - 2]]
        if (after >= len(self.rows) or self.rows[after].orientation_deg != row.orientation_deg
                or (self.torques[after] - self.torques[pos]) * way >= 0
                or (self.torques[pos] - self.torques[ok[k - 1]]) * way <= 0):
            return warning  # not the turning load of a branch the plan goes on with
        start = k - 1  # the branch's first photograph after the pre-load
        while start > 2 and (self.torques[ok[start - 1]] - self.torques[ok[start - 2]]) * way > 0:
            start -= 1
        fits = [j for j in range(start, k + 1)  # the photograph of the row bound at ok[j] was never taken
                if not check_steps(self._row_early_from(ok, points, j)[:k + 1], step_torque_nm=self.step_torque,
                                   open_end=True, hindsight=False, earlier=loops)]
        if not fits:
            return warning
        self.turned_early[pos] = [ok[j] for j in fits]  # the files are a row early from one of them on
        fix = shlex.join(["vision-torsion", "bind", str(self.session.folder), str(self.camera)])
        lines = " or ".join(str(self.bound[ok[j]].row.line) for j in fits)
        return dataclasses.replace(warning, message=(
            f"the load turned back a row early: Δangle {warning.delta_angle_deg:+.4f}° for a planned torque "
            f"step of {warning.delta_torque_nm:+.5f} N·m: a missed shot in this branch, at line "
            f"{lines} (the steps the loop has shown so far fit each; where the gear's stiffness "
            f"changes, the double step looks like its neighbours until the same steps come again); fix: after "
            f"this orientation `{fix}` names the row (--missing LINE) against the rest of the loop"))

    def _row_early_from(self, ok, points, j) -> list[StepPoint]:
        """`points` (of the photographs bound at `ok`) with the row of ``ok[j]``
        not photographed: from it on each shows the next row's load (those whose
        next row is not of their orientation left out)."""
        o = self.rows[ok[j]].orientation_deg
        return points[:j] + [StepPoint(self.torques[ok[i] + 1], p.angle_deg, p.angle_std_deg)
                             for i, p in enumerate(points[j:], start=j)
                             if ok[i] + 1 < len(self.rows) and self.rows[ok[i] + 1].orientation_deg == o]

    def _after_turn(self, ok, points, warns, k, loops, open_end):
        """The step warnings after the photograph ``ok[k]`` at which the load turned
        back a row early (:meth:`_turned_early`), and the step points to compare
        later orientations with. Its files are a row early from one of the rows
        named there on: the steps after it are checked bound that way (else each
        is compared with the wrong row's step, and the double step, already said,
        shows again as new mistakes). A warning after it is kept when every named
        row gives it (an independent mistake: the rows differ only before the
        turn), with the message of the row whose binding fits the loop best
        (:func:`~.steps.step_misfit`), whose points are returned."""
        from .steps import step_misfit

        o = self.rows[ok[k]].orientation_deg
        trials = []
        for j in (ok.index(c) for c in self.turned_early[ok[k]] if c in ok):
            trial = self._row_early_from(ok, points, j)
            last = ok[len(trial) - 1] + (len(trial) > j)  # the row the newest photograph shows
            after = [self.torques[i] for i in range(last + 1, len(self.rows))
                     if self.rows[i].orientation_deg == o and self.rows[i].line not in self.missing]
            found = [w for w in check_steps(trial, step_torque_nm=self.step_torque, open_end=open_end,
                                            hindsight=False, earlier=loops, plan_after=after)
                     if w.index > k and (not w.awaiting_next or self._second_to_last(ok[w.index] + 1))]
            trials.append((step_misfit(trial, step_torque_nm=self.step_torque, earlier=loops), trial, found))
        if not trials:
            return [w for w in warns if w.index <= k], points
        _, best, found = min(trials, key=lambda t: t[0])
        kept = [w for w in found if all(any((v.index, v.kind) == (w.index, w.kind) for v in t[2]) for t in trials)]
        return [w for w in warns if w.index <= k] + kept, best if len(best) == len(points) else points

    def bind_fix(self, *options: str) -> str:
        """"fix: " and the ``vision-torsion bind`` command line with `options`."""
        return "fix: " + shlex.join(["vision-torsion", "bind", str(self.session.folder), str(self.camera),
                                     *options])

    def step_fix(self, pos: int, warning, shift: int = 0) -> list[str]:
        """The ``bind`` options fixing a step warning on the photograph bound at
        `pos`; none when the step says no mistake for sure or the files carry their
        rows' names (nothing to re-bind). An extra shot is left out; a missed
        shot's row is marked as not photographed, so that the files from this one
        on bind one row later; a photograph with a piece forgotten is left out and
        its row marked as not photographed (its load cannot be set again without
        leaving the loop's path). The row is the one the photograph shows with the
        fixes before it applied: `shift` rows after the one it is bound to. A
        missed shot's signature awaiting the next photograph
        (:attr:`~.steps.StepWarning.awaiting_next`) gets the fix it would take."""
        if not self.camera_mode or not (warning.decided or warning.awaiting_next):
            return []
        x = self.bound[pos]
        shown = pos + shift
        line = str(self.rows[shown].line if 0 <= shown < len(self.rows) else x.row.line)
        return {"no_movement": ["--skip", x.file], "large_step": ["--missing", line],
                "small_step": ["--skip", x.file, "--missing", line]}.get(warning.kind, [])

    def sign_message(self, pos: int) -> str:
        """The one line saying the session's angle_sign is inverted (at `pos`, the
        first loaded photograph)."""
        x = self.bound[pos]
        return (f"angle_sign is inverted: this first loaded image turned {-x.angle:+.4f}° under "
                f"{self.torques[pos]:+.5f} N·m; set angle_sign = {self.sign:+d} in "
                f"{self.session.folder / 'session.toml'} (watch checks the angles with it from here on)")

    # -- outputs -----------------------------------------------------------------

    def _save(self, *, now: float | None = None, force: bool = False) -> None:
        """binding.json at most every `binding_every_s` (and at the end); the page always."""
        if self.page:
            self.write_page()
        now = self.clock() if now is None else now
        if not force and now - self._binding_written < self.binding_every_s and not self.complete:
            return
        self._binding_written = now
        images = {self.bound[p].row.image: self.bound[p].file for p in sorted(self.bound)
                  if self.camera_mode or f"images/{self.bound[p].file}" != self.bound[p].row.image}
        if images or self.camera_mode:  # files under their planned names need no binding
            write_binding(self.session.folder, Binding(camera_dir=self.camera, images=images, by="watch",
                                                       skipped=tuple(sorted(self.skipped)),
                                                       missing=tuple(sorted(self.missing))),
                          durable=False)  # watch rewrites it, and can rebuild it

    def live_points(self) -> list[LivePoint]:
        """The photographed rows for the page, in capture order."""
        out = []
        for p in self.order:
            b = self.bound[p]
            out.append(LivePoint(p + 1, b.file, b.row.line, b.row.orientation_deg,
                                 f"{b.row.phase} s{b.row.step}", self.torques[p], b.angle, b.delta,
                                 tuple(w.removeprefix("step: ") for w in b.warnings)))
        return out

    def next_step_text(self) -> tuple[str | None, float | None]:
        """What to load next, in words, and its planned torque."""
        nxt = self.next_row()
        if nxt is None:
            return None, None
        pos, row = nxt
        step_mass = self.session.config.rig.step_mass_kg
        pieces = 0 if row.mass_kg is None else round(row.mass_kg / step_mass)
        pans = "no weights" if pieces == 0 else (
            f"{'+' if row.phase.startswith('positive') else '−'} pans {1000 * row.mass_kg:g} g each "
            f"({pieces} × {1000 * step_mass:g} g)")
        return (f"{row_text(row)} · {pans} · τ = {self.torques[pos]:+.5f} N·m", self.torques[pos])

    def write_page(self, *, finished: bool = False) -> Path:
        """Write ``OUT_DIR/live.html`` atomically, then its stamp (``live-stamp.js``:
        a browser showing the page reloads it when the stamp changes); return its path."""
        text, torque = self.next_step_text()
        version = f"{time.time_ns():x}"  # unique across runs: an open page of a former watch reloads too
        page = live_page(title=str(self.session.folder.name), points=self.live_points(),
                         planned_torques=self.torques, next_step=text, next_torque_nm=torque,
                         messages=self.notices, finished=finished, version=version)
        path = atomic_write_text(self.out / LIVE_PAGE_NAME, page, durable=False)
        atomic_write_text(self.out / LIVE_STAMP_NAME, stamp_script(version), durable=False)
        return path


@dataclass(frozen=True)
class WatchResult:
    """How a watch ended.

    Attributes
    ----------
    n_bound, n_rows : int
        Photographs bound, manifest rows.
    n_warnings : int
        Photographs with a warning.
    page : pathlib.Path or None
        The live page.
    report : object or None
        What `finish` returned (the ``watch`` command: the SessionReport), or None.
    interrupted : bool
        Ended by Ctrl-C.
    """

    n_bound: int
    n_rows: int
    n_warnings: int
    page: Path | None
    report: object | None
    interrupted: bool


def printable(text: str) -> str:
    """`text` with its control characters shown escaped (``\\x1b``): a camera file
    name must not retitle the window or clear the screen it is printed on."""
    return "".join(c if c.isprintable() or c == " " else repr(c)[1:-1] for c in text)


def watch_session(session_dir, *, camera_dir=None, out_dir=None, poll_s: float = 0.5,
                  settle_s: float = 1.0, give_up_s: float = 10.0, finish=None,
                  stop=None, echo=None, events: str = "auto") -> WatchResult:
    """Follow a session while it is shot; end with `finish` (the report).

    Parameters
    ----------
    session_dir : path-like
        The session folder.
    camera_dir : path-like, optional
        The camera's folder (read only); ``SESSION_DIR/images`` by default.
    out_dir : path-like, optional
        Output folder (``SESSION_DIR/results``).
    poll_s : float
        Longest time between looks at the folder (a filesystem event makes the next
        look come at once).
    settle_s, give_up_s, events
        See :class:`Watcher`.
    finish : callable, optional
        Called at the end, when a photograph was bound, with the session folder and
        `out_dir` (e.g. ``lambda s, o: report_session(s, out_dir=o)``); its result is
        :attr:`WatchResult.report`.
    stop : threading.Event, optional
        Set it to end the watch (besides Ctrl-C, and every row having its image).
    echo : callable, optional
        Called with each event (default: print its message; warnings to stderr).

    Returns
    -------
    WatchResult
    """
    def default_echo(event):
        stream = sys.stderr if event.kind in ("warning", "ignored", "deleted", "folder_gone",
                                              "leftover") else sys.stdout
        prefix = {"warning": "  ! ", "retracted": "  ✓ "}.get(event.kind, "")
        print(prefix + printable(event.message), file=stream, flush=True)

    echo = echo or default_echo
    interrupted = False
    with Watcher(session_dir, camera_dir=camera_dir, out_dir=out_dir, settle_s=settle_s,
                 give_up_s=give_up_s, events=events) as watcher:
        how = ("filesystem events" if not watcher.events.why_polling
               else f"polling every {poll_s:g} s: {watcher.events.why_polling}")
        echo(WatchEvent("start", "", f"watching {watcher.camera} ({how}) for {len(watcher.rows)} planned "
                                     f"images; live page: {watcher.out / LIVE_PAGE_NAME} (Ctrl-C to stop)"))
        watcher.write_page()
        try:
            while not (stop is not None and stop.is_set()):
                for event in watcher.tick():
                    echo(event)
                if watcher.complete:
                    break
                watcher.wait(poll_s)  # returns at once when a file is closed
        except KeyboardInterrupt:
            interrupted = True
            echo(WatchEvent("stopped", "", "stopped; run the same command again to resume"))
    rep = None
    if finish is not None and watcher.bound:
        rep = finish(watcher.session.folder, out_dir)
    return WatchResult(n_bound=len(watcher.bound), n_rows=len(watcher.rows),
                       n_warnings=sum(1 for b in watcher.bound.values() if b.warnings),
                       page=watcher.out / LIVE_PAGE_NAME, report=rep, interrupted=interrupted)
