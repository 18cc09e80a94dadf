"""Progress lines of long library stages (cpp_dem.progress): quiet while short, a line with
an ETA once due, and the stages that use it."""

import io

import cpp_dem.progress as progress
from cpp_dem.progress import Progress


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_a_stage_is_quiet_until_due_then_prints_fraction_and_eta():
    buf = io.StringIO()
    progress.set_progress(buf)
    try:
        clock = Clock()
        bar = Progress("demo", first_after_s=10, every_s=10, clock=clock)
        clock.t = 5.0
        assert bar.update(0.1) is None  # short: nothing
        clock.t = 12.0
        line = bar.update(0.25, "x = 1")
        assert line == "[demo] 25 %, 12 s elapsed, ETA 36 s; x = 1"
        clock.t = 15.0
        assert bar.update(0.3) is None  # not again before every_s
        clock.t = 23.0
        assert bar.update(None) == "[demo] running, 23 s elapsed, ETA unknown"
        assert buf.getvalue().splitlines() == bar.lines
    finally:
        progress.set_progress(True)


def test_silenced_stages_print_nothing():
    progress.set_progress(False)
    try:
        clock = Clock()
        bar = Progress("demo", first_after_s=0, clock=clock)
        clock.t = 100.0
        assert bar.update(0.5) is None
    finally:
        progress.set_progress(True)


def test_the_long_stages_report_progress(monkeypatch, capsys):
    """The pull-out and the triaxial stages print progress lines when they are due (here at
    once: the first line is due after 0 s)."""
    import numpy as np

    import cpp_dem as dem
    from cpp_dem.protocols import triaxial

    monkeypatch.setattr(progress, "FIRST_AFTER_S", 0.0)
    monkeypatch.setattr(progress, "EVERY_S", 0.0)
    rng = np.random.default_rng(1)
    n = 60
    from cpp_dem.build.packing import loose_cloud

    c, r = loose_cloud(rng.uniform(0.9e-3, 1.1e-3, n), (0, 0, 0), (0.012, 0.012, 0.012), seed=1)
    sample = triaxial.build_box_sample(c, r, (0, 0, 0), (0.012, 0.012, 0.012), young=1e7,
                                       poisson=0.3, friction_deg=20, density=2650, local_damping=0.5)
    triaxial.isotropic_stage(sample, 5e3, max_steps=400)
    triaxial.deviatoric_stage(sample, 5e3, strain_rate=2.0, stop_strain=0.002,
                              record_every=50)
    out = capsys.readouterr().out
    assert "[servo stage] running" in out and "targets 5, 5, 5" in out
    assert "[triaxial deviatoric stage]" in out and "ETA" in out and "axial strain" in out
    assert dem  # imported for its side effects (threads)
