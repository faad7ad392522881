"""The results cache's append-only logs: cut lines ignored, merging, other runs' logs kept."""

from __future__ import annotations

import json

from vision_torsion import fileio
from vision_torsion.session.cache import CacheLog, cache_line, count_entries, merge_cache, read_cache, read_logs

KEY_A, KEY_B, KEY_C = "a" * 64, "b" * 64, "c" * 64


def _entry(value, status="ok"):
    return json.dumps({"status": status, "value": value}, sort_keys=True)


def test_log_lines_are_read_back_and_a_cut_line_is_ignored(tmp_path):
    log = CacheLog(tmp_path / "cache", "run1")
    log.append(KEY_A, _entry(1))
    log.append(KEY_B, _entry(2, "failed"))
    log.close()
    (path,) = log.files()
    with open(path, "a", encoding="utf-8") as f:  # a write cut short by a kill
        f.write(f"{KEY_C} {_entry(3)[:10]}")
    entries, files = read_cache(tmp_path / "cache")
    assert files == [path]
    assert entries == {KEY_A: {"status": "ok", "value": 1}, KEY_B: {"status": "failed", "value": 2}}


def test_damaged_lines_and_unfinished_entries_are_ignored(tmp_path, caplog):
    folder = tmp_path / "cache"
    folder.mkdir()
    changed = cache_line(KEY_B, _entry(6)).replace("6", "7")  # one digit changed
    fileio.atomic_write_text(folder / "run-x-1.jsonl",  # recorded: the cache's own
        cache_line(KEY_A, "{not json}")            # damaged
        + cache_line(KEY_B[:10], _entry(2))        # bad key
        + cache_line(KEY_C, _entry(3, "running"))  # not a result
        + f"{KEY_C}{_entry(4)}\n"                 # no separator
        + f"{KEY_C} {_entry(4)}\n"                # no checksum (an older layout)
        + changed                                  # checksum mismatch
        + cache_line(KEY_A, _entry(5)))
    assert read_cache(folder)[0] == {KEY_A: {"status": "ok", "value": 5}}
    assert "cache line(s): checksum mismatch" in caplog.text
    assert read_cache(tmp_path / "missing") == ({}, [])


def test_entries_failing_the_schema_check_are_ignored(tmp_path, caplog):
    folder = tmp_path / "cache"
    folder.mkdir()
    fileio.atomic_write_text(folder / "merged.jsonl", cache_line(KEY_A, _entry(1)) + cache_line(KEY_B, _entry("x")))
    entries, _ = read_cache(folder, check=lambda e: isinstance(e["value"], int))
    assert entries == {KEY_A: {"status": "ok", "value": 1}}
    assert "1 cache line(s): wrong shape ignored; those images are measured again" in caplog.text


def test_merge_keeps_the_latest_entry_per_key_and_leaves_other_runs_logs(tmp_path):
    folder = tmp_path / "cache"
    first, second, other = CacheLog(folder, "r1"), CacheLog(folder, "r2"), CacheLog(folder, "r3")
    first.append(KEY_A, _entry(1))
    second.append(KEY_A, _entry(2))
    second.append(KEY_B, _entry(3))
    other.append(KEY_C, _entry(4))
    for log in (first, second, other):
        log.close()
    logs = first.files() + second.files()
    merged = merge_cache(folder, read_logs(logs), logs)
    assert sorted(p.name for p in folder.iterdir()) == sorted([merged.name, other.files()[0].name,
                                                               fileio.RECORD_NAME])
    assert read_cache(folder)[0] == {KEY_A: {"status": "ok", "value": 2},
                                     KEY_B: {"status": "ok", "value": 3},
                                     KEY_C: {"status": "ok", "value": 4}}
    # merging the merged log again changes nothing
    text = merged.read_text()
    assert merge_cache(folder, read_logs([merged]), [merged]).read_text() == text
    assert count_entries(folder) == 3
