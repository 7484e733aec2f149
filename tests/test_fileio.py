"""Atomic writes and resumable JSONL logs never lose or corrupt a record."""

import os

import pytest

from mani_skill_softvt.fileio import append_jsonl, atomic_write, atomic_write_json, read_jsonl


def test_torn_last_line_is_dropped_and_the_next_record_stands_alone(tmp_path):
    log = tmp_path / "log.jsonl"
    append_jsonl(log, {"episode": 1})
    with open(log, "a") as f:
        f.write('{"episode": 2, "succ')  # killed mid-write
    assert read_jsonl(log) == [{"episode": 1}]
    append_jsonl(log, {"episode": 2})
    assert read_jsonl(log) == [{"episode": 1}, {"episode": 2}]


def _append_many(path, writer, n):
    for i in range(n):
        append_jsonl(path, {"writer": writer, "i": i, "pad": "x" * 2000})


def test_processes_logging_to_one_file_lose_no_line(tmp_path):
    # The recipe search runs two processes that log to one results file.
    import multiprocessing

    log = tmp_path / "log.jsonl"
    ctx = multiprocessing.get_context("fork")
    procs = [ctx.Process(target=_append_many, args=(log, w, 150)) for w in range(3)]
    for p in procs:
        p.start()
    for p in procs:
        p.join()
    records = read_jsonl(log)
    assert sorted((r["writer"], r["i"]) for r in records) == [(w, i) for w in range(3) for i in range(150)]


def test_failed_atomic_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "card.json"
    atomic_write_json(target, {"v": 1})

    def crash(p):
        p.write_text("half")
        raise RuntimeError("killed")
    with pytest.raises(RuntimeError):
        atomic_write(target, crash)
    assert target.read_text().strip().startswith("{") and os.listdir(tmp_path) == ["card.json"]
