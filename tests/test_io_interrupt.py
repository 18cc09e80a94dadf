"""A Ctrl-C (or SIGTERM, which the cases turn into one) that lands in an h5py destructor while a
record is written is reported through sys.unraisablehook, not raised. The writers' guards
raise it again on the way out: before, they dropped it, and about 1 Ctrl-C in 4 sent during a
record's write was lost (the run went on and finished with exit 0)."""

import gc

import pytest

from cpp_dem.io._files import _DeallocErrors, _quiet_unraisable


class _InterruptedInDel:
    def __del__(self):
        raise KeyboardInterrupt


def _drop():
    x = _InterruptedInDel()
    del x
    gc.collect()


def test_dealloc_guard_raises_a_ctrl_c_reported_by_a_destructor():
    with pytest.raises(KeyboardInterrupt):
        with _DeallocErrors() as caught:
            _drop()
    assert caught.text == ""  # (not mistaken for a write failure)


def test_quiet_guard_raises_a_ctrl_c_reported_by_a_destructor():
    with pytest.raises(KeyboardInterrupt):
        with _quiet_unraisable():
            _drop()


def test_other_destructor_reports_stay_caught():
    class _Fails:
        def __del__(self):
            raise ValueError("x")

    with _DeallocErrors() as caught:
        y = _Fails()
        del y
        gc.collect()
    assert "ValueError: x" in caught.text
    with _quiet_unraisable():  # silenced, nothing raised
        z = _Fails()
        del z
