"""Ctrl-C held off a block that must finish whole: the helper, and a league transaction cut by Ctrl-C."""

from __future__ import annotations

import os
import signal

import pytest
from sqlalchemy import select

from selfplay_cli.league.models import Meta
from selfplay_cli.league.store import League
from selfplay_cli.signals import signals_held


@pytest.fixture(autouse=True)
def ctrl_c_raises():
    """Python's own SIGINT handler for each test: a suite started in the background inherits SIGINT ignored."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def test_ctrl_c_waits_for_the_block_then_interrupts():
    reached = []
    with pytest.raises(KeyboardInterrupt), signals_held():
        os.kill(os.getpid(), signal.SIGINT)
        reached.append("after the signal")
    assert reached == ["after the signal"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler, "the handler is put back"


def test_nested_blocks_hand_the_signal_outward():
    order = []
    with pytest.raises(KeyboardInterrupt), signals_held():
        with signals_held():
            os.kill(os.getpid(), signal.SIGINT)
        order.append("the inner block ended, nothing raised")
    assert order == ["the inner block ended, nothing raised"]


def test_a_term_signal_reaches_its_own_handler_after_the_block():
    got = []
    before = signal.signal(signal.SIGTERM, lambda s, f: got.append(s))
    try:
        with signals_held():
            os.kill(os.getpid(), signal.SIGTERM)
            assert got == []
        assert got == [signal.SIGTERM]
    finally:
        signal.signal(signal.SIGTERM, before)


def test_a_league_write_cut_by_ctrl_c_commits_whole_and_leaves_no_lock(tmp_path):
    league = League.open(tmp_path / "league", busy_timeout=2.0)

    def write(s):
        s.add(Meta(key="first", value="1"))
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C in the middle of the transaction
        s.add(Meta(key="second", value="2"))

    with pytest.raises(KeyboardInterrupt):
        league._unit(write)
    with league.session(readonly=True) as s:
        keys = set(s.scalars(select(Meta.key)))
    assert {"first", "second"} <= keys, "both rows of the unit were committed"
    other = League.open(tmp_path / "league", busy_timeout=0.5)  # another process's view: the write lock is free
    other._unit(lambda s: s.add(Meta(key="third", value="3")))
    other.close()
    league.close()
