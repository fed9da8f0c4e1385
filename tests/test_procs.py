"""tests/procs.py, the suite's one walk over /proc: whole command lines (a deep clone's paths run past 80 characters,
past a page here), a process's children and theirs, its session, and the states a test waits on (stopped, gone)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import procs
import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

WAIT = "import sys; sys.stdin.read()"  # lives until its stdin closes (or it is killed)


def _until(what, seconds: float = 30.0) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not what():
        time.sleep(0.02)
    return bool(what())


def test_a_command_line_is_read_whole_however_long(tmp_path):
    deep = "/check/work/main/" + "/".join(["folder"] * 1000) + "/league.db"  # 7,000 characters
    p = subprocess.Popen([sys.executable, "-c", WAIT, deep, "last"], stdin=subprocess.PIPE)
    try:
        (found,) = [x for x in procs.naming("league.db") if x.pid == p.pid]
        assert found.argv == (sys.executable, "-c", WAIT, deep, "last")
        assert found.cmdline.endswith(f"{deep} last") and found.ppid == os.getpid() and not found.zombie
        assert [x.pid for x in procs.naming(deep + " last")] == [p.pid]
    finally:
        p.kill()
        p.communicate()
    assert procs.read(p.pid) is None and procs.gone(p.pid) and not procs.naming(deep)


def test_children_descendants_and_a_session_of_its_own():
    code = (f"import subprocess, sys; c = subprocess.Popen([sys.executable, '-c', {WAIT!r}]); "
            "print(c.pid, flush=True); sys.stdin.read(); c.kill(); c.wait()")
    parent = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                              start_new_session=True)
    try:
        child = int(parent.stdout.readline())
        assert procs.children(parent.pid) == [child] and parent.pid in procs.children(os.getpid())
        assert [p.pid for p in procs.descendants(parent.pid)] == [child]
        assert {p.pid for p in procs.descendants(os.getpid())} >= {parent.pid, child}
        assert sorted(p.pid for p in procs.session(parent.pid)) == sorted([parent.pid, child])
        assert procs.read(child).start.isdigit() and procs.read(child).sid == parent.pid
    finally:
        parent.communicate("")
    assert procs.gone(child) and procs.session(parent.pid) == []


def test_holding_names_the_processes_with_a_file_open(tmp_path):
    path = tmp_path / "league.db"
    path.write_text("")
    assert os.getpid() not in procs.holding(path)
    with open(path):
        assert os.getpid() in procs.holding(path)
    assert os.getpid() not in procs.holding(path)


def test_stopped_is_every_thread_stopped_and_gone_takes_a_zombie_for_dead():
    p = subprocess.Popen([sys.executable, "-c", "import threading, sys; threading.Thread(target=sys.stdin.read, "
                          "daemon=True).start(); sys.stdin.read()"], stdin=subprocess.PIPE)
    try:
        assert _until(lambda: len(list((procs.PROC / str(p.pid) / "task").iterdir())) == 2)  # its two threads
        assert not procs.stopped(p.pid)
        os.kill(p.pid, signal.SIGSTOP)
        assert _until(lambda: procs.stopped(p.pid)) and procs.read(p.pid).state == "T"
        os.kill(p.pid, signal.SIGCONT)
        assert _until(lambda: not procs.stopped(p.pid))
        os.kill(p.pid, signal.SIGKILL)
        assert _until(lambda: procs.read(p.pid) is not None and procs.read(p.pid).zombie)  # not collected yet
        assert procs.gone(p.pid) and not procs.stopped(p.pid)
    finally:
        p.kill()
        p.communicate()
    assert procs.read(p.pid) is None and not procs.stopped(p.pid)
