"""JSON read in slices (phantomtouch/service/json_slices.py): the same document as
``json.loads`` reads, read so that another thread runs meanwhile, and the collector held
off while a large message is taken apart."""

from __future__ import annotations

import gc
import json
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from phantomtouch.service.json_slices import (
    SLICE_BYTES,
    collector_held,
    let_go,
    read_json,
    without_collection,
)
from tests.bhaptics.player_client import frame_submits

ROOT = Path(__file__).resolve().parents[2]

LEAVES = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**63 - 1)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(alphabet=st.characters(exclude_categories=("Cs",)), max_size=40)
)
VALUES = st.recursive(
    LEAVES,
    lambda children: (
        st.lists(children, max_size=6) | st.dictionaries(st.text(max_size=8), children, max_size=6)
    ),
    max_leaves=40,
)


@settings(max_examples=60, deadline=None)
@given(value=VALUES, ascii_only=st.booleans())
def test_a_large_document_reads_as_json_loads_reads_it(value: Any, ascii_only: bool) -> None:
    """Any JSON value, made longer than a slice by a long member beside it, reads back
    equal to what ``json.loads`` makes of the same text (floats to the bit: equal
    ``repr``)."""
    document = {"value": value, "padding": "x" * SLICE_BYTES}
    text = json.dumps(document, ensure_ascii=ascii_only)
    assert len(text) > SLICE_BYTES
    read = read_json(text)
    expected = json.loads(text)
    assert read == expected
    assert repr(read) == repr(expected)


def test_a_bhaptics_message_of_30000_submits_reads_whole() -> None:
    text = frame_submits(30_000)
    read = read_json(text)
    assert read == json.loads(text)
    assert len(read["Submit"]) == 30_000


PAD = '"padding": "' + "x" * SLICE_BYTES + '"'


@pytest.mark.parametrize(
    "text",
    [
        "{" + PAD + '} "trailing"',
        "{" + PAD + "}]",
        "{" + PAD + ', "open": [1, 2}',
        "{" + PAD,
        "{" + PAD + ', "nan": NaN}',
        "{" + PAD + ', "big": 1e400}',
        "{" + PAD + ', "big": 9223372036854775808}',
    ],
    ids=[
        "trailing",
        "stray bracket",
        "unclosed array",
        "cut",
        "NaN",
        "beyond a float",
        "beyond 64 bits",
    ],
)
def test_a_large_text_that_is_not_one_strict_document_is_refused(text: str) -> None:
    with pytest.raises(ValueError):
        read_json(text)


def test_a_short_text_is_json_loads() -> None:
    assert read_json('{"a": [1, 2.5, "b"]}') == {"a": [1, 2.5, "b"]}
    with pytest.raises(ValueError):
        read_json('{"a": ')


def test_another_thread_runs_while_a_large_document_is_read() -> None:
    """``json.loads`` holds the interpreter for the whole text: another thread waits the
    whole read. Read in slices, it runs throughout (a switch interval after it asks):
    its longest wait is under half the read (a few hundredths on a 2-core machine).
    Measured in an interpreter of its own (:mod:`tests.service.interleaving`), with the
    collector held, the best of three for the slices, since a loaded machine may keep
    the waiting thread off a core."""
    waits = []
    for _ in range(3):
        done = subprocess.run(
            [sys.executable, "-m", "tests.service.interleaving"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        )
        waits.append(json.loads(done.stdout))
    held, took = waits[0]["json.loads"]
    assert held > 0.75 * took, f"json.loads let another thread run ({held:.3f} of {took:.3f} s)"
    held, took = min((wait["read_json"] for wait in waits), key=lambda pair: pair[0] / pair[1])
    assert held < 0.5 * took, f"another thread waited {held:.3f} s of a {took:.3f} s read"


def test_the_collector_is_held_while_any_holds_it_and_back_after_the_last() -> None:
    assert gc.isenabled()
    entered = threading.Event()
    leave = threading.Event()

    def hold_in_a_thread() -> None:
        with collector_held():
            entered.set()
            leave.wait(5.0)

    thread = threading.Thread(target=hold_in_a_thread)
    with collector_held():
        assert not gc.isenabled()
        thread.start()
        assert entered.wait(5.0)
    assert not gc.isenabled(), "released while another thread still held it"
    leave.set()
    thread.join()
    assert gc.isenabled()
    assert without_collection(gc.isenabled) is False
    assert gc.isenabled()


def test_the_collector_stays_off_after_a_hold_if_it_was_off_before() -> None:
    gc.disable()
    try:
        with collector_held():
            pass
        assert not gc.isenabled()
    finally:
        gc.enable()


def test_a_hold_ends_when_its_work_raises() -> None:
    def fail() -> None:
        raise RuntimeError("refused")

    with pytest.raises(RuntimeError):
        without_collection(fail)
    assert gc.isenabled()


def test_let_go_empties_a_list_of_any_length() -> None:
    for count in (0, 1, 1023, 1024, 1025, 30_000):
        items: list[Any] = [{"k": [k]} for k in range(count)]
        let_go(items)
        assert items == []
