"""The benches a user runs (issue 60 items 4 and 9): a bad input is one line naming the
option, the value and what is allowed, never a traceback, and a second run into one --out
does not replace the first one's results. The class is fixed in one place, bench/_cli.py,
which every bench's parser and main go through (bench/README.md)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
#: A bench that runs in about a second: two 30-grain elements, 5 steps, one round.
TINY = ["periodic_cost.py", "--n", "30", "--steps", "5", "--rounds", "1"]


def _bench(args, cwd, timeout=300):
    return subprocess.run([sys.executable, str(BENCH / args[0]), *args[1:]],
                          capture_output=True, text=True, cwd=cwd, timeout=timeout,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})


@pytest.mark.parametrize("args, words", [
    (["quasi_static.py", "--sweep", "nan"],
     "--sweep='nan': nan is not allowed; each must be > 0 (a finite number), and >= 1"),
    (["quasi_static.py", "--sweep", "2,,4"], "--sweep='2,,4': must be a comma-separated list"),
    (["quasi_static.py", "--seeds", "1,x"], "--seeds='1,x': 'x' is not a whole number"),
    (["quasi_static.py", "--inertial-number", "0"],
     "--inertial-number=0.0: must be > 0 (a finite number)"),
    (["fem_dem_biaxial.py", "--strain", "-0.01"], "--strain=-0.01: must be > 0 (a finite number)"),
    (["shear_band.py", "--strain", "inf"], "--strain=inf: must be > 0 (a finite number)"),
    (["element_pool.py", "--strain", "nan"], "--strain=nan: must be > 0 (a finite number)"),
    (["element_pool.py", "--grains", "abc"], "argument --grains: invalid int value: 'abc'"),
    (["periodic_shear.py", "--inertial=-1e-3"],
     "--inertial=-0.001: must be > 0 (a finite number)"),
    (["throughput.py", "--threads", "1", "-2"], "--threads=-2: must be >= 0 (a finite number)"),
    (["footing_direct_dem.py", "--settlements-mm", "0.1,nan"],
     "--settlements-mm='0.1,nan': nan is not allowed"),
    (["element_pool.py", "--out", "/proc/geogrid_dem_no_such/x.json"],
     "--out=/proc/geogrid_dem_no_such/x.json: cannot be written"),
    (["quasi_static.py", "--reanalyse", "/geogrid_dem_no_such.jsonl"],
     "FileNotFoundError: [Errno 2] No such file or directory: '/geogrid_dem_no_such.jsonl'"),
    (["periodic_cost.py", "--n", "3"], "ParameterError: loose_cloud: could not place sphere"),
])
def test_a_bad_bench_input_is_one_line_naming_it(tmp_path, args, words):
    """Before, ``--sweep nan`` and ``--inertial-number 0`` ran (a NaN sweep, a zero rate), a
    negative strain ran the other way, a missing file or a library's refusal ended in a
    traceback."""
    p = _bench(args, tmp_path)
    assert p.returncode == 2, (p.returncode, p.stderr[-2000:])
    assert words in p.stderr, p.stderr[-2000:]
    assert "Traceback" not in p.stderr
    errors = [line for line in p.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1, p.stderr


def test_a_bench_run_twice_into_one_out_keeps_the_first_run(tmp_path):
    """A bench that writes one results file: a second run into the same --out is refused
    (naming it, nothing changed) unless --overwrite; without --out the default file of an
    earlier run is kept and the new run goes to the next numbered one."""
    f = tmp_path / "cost.json"
    first = _bench([*TINY, "--out", str(f)], tmp_path)
    assert first.returncode == 0, first.stderr[-2000:]
    before = f.read_bytes()
    again = _bench([*TINY, "--out", str(f)], tmp_path)
    assert again.returncode == 2 and "Traceback" not in again.stderr
    assert (f"--out={f}: holds the results of an earlier run; give another file, or "
            "--overwrite to replace them") in again.stderr
    assert f.read_bytes() == before
    over = _bench([*TINY, "--out", str(f), "--overwrite"], tmp_path)
    assert over.returncode == 0, over.stderr[-2000:]
    assert json.loads(f.read_text())["n"] == 30
    # the default --out (results/bench_runs/periodic_cost.json), twice: numbered
    for k in range(2):
        p = _bench(TINY, tmp_path)
        assert p.returncode == 0, p.stderr[-2000:]
    runs = tmp_path / "results" / "bench_runs"
    assert sorted(x.name for x in runs.iterdir()) == ["periodic_cost.json",
                                                     "periodic_cost_001.json"]
    assert "holds an earlier run's results: writing" in p.stderr


def test_a_folder_bench_refuses_a_folder_of_an_earlier_run(tmp_path):
    """A bench that writes into a folder (``out="folder"``): a folder with files in it is
    refused unless --overwrite, at once (before any work); a file given as the folder, or
    --out under a file, is named."""
    sys.path.insert(0, str(BENCH))
    import _cli

    d = tmp_path / "runs"
    d.mkdir()
    (d / "quasi_static.jsonl").write_text("{}\n")

    def parser():
        ap = _cli.BenchParser(prog="b", out="folder")
        ap.add_argument("--out", type=Path, default=None)
        ap.add_argument("--strain", type=float, default=0.01)
        return ap

    with pytest.raises(SystemExit):
        parser().parse_args(["--out", str(d)])
    assert parser().parse_args(["--out", str(d), "--overwrite"]).out == d
    with pytest.raises(SystemExit):
        parser().parse_args(["--out", str(d / "quasi_static.jsonl")])
    with pytest.raises(SystemExit):
        parser().parse_args(["--out", str(d / "quasi_static.jsonl" / "x")])
    empty = tmp_path / "new"
    assert parser().parse_args(["--out", str(empty)]).out == empty and empty.is_dir()
    # a list option by the same rules
    assert _cli.numbers("2, 4,8", "--sweep", minimum=1) == [2.0, 4.0, 8.0]
    with pytest.raises(_cli.BenchInputError, match="--sweep='0.5': 0.5 is not allowed"):
        _cli.numbers("0.5", "--sweep", minimum=1)


def benches_outside_the_cli(bench: Path = BENCH) -> list[str]:
    """The bench scripts run as programs (a ``__main__`` guard) that do not go through
    bench/_cli.py: a plain ``argparse.ArgumentParser`` (no number checks), or a main not
    run as ``sys.exit(_cli.run(main))`` (a refusal printed its error and exited 0, or a
    library's refusal ended in a traceback)."""
    import re

    out = []
    for p in sorted(bench.glob("*.py")):
        text = p.read_text()
        if "__main__" not in text:
            continue  # (a module the benches share, or a script Yade runs)
        if ("argparse.ArgumentParser(" in text
                or not re.search(r"^\s*sys\.exit\(_cli\.run\(main\)\)\s*$", text, re.MULTILINE)):
            out.append(p.name)
    return out


def test_every_bench_goes_through_the_cli_and_exits_with_its_status(tmp_path):
    assert benches_outside_the_cli() == []
    # the check can fail: a bench that drops the status, or parses on its own, is named
    main = "if __name__ == '__main__':\n"
    (tmp_path / "a.py").write_text(main + "    _cli.run(main)\n")
    (tmp_path / "b.py").write_text("ap = argparse.ArgumentParser()\n" + main
                                   + "    sys.exit(_cli.run(main))\n")
    (tmp_path / "c.py").write_text(main + "    main()\n")
    (tmp_path / "ok.py").write_text(main + "    sys.exit(_cli.run(main))\n")
    (tmp_path / "module.py").write_text("def f():\n    pass\n")
    assert benches_outside_the_cli(tmp_path) == ["a.py", "b.py", "c.py"]


@pytest.mark.parametrize("args, words", [
    # triaxial_disc.py exited 0 after this refusal
    (["triaxial_disc.py", "--shapes", "sphere"], "--shapes='sphere'"),
    (["threads_auto.py", "--cases", "nosuch"], "--cases=nosuch: no such case; one of"),
    (["step_budget.py", "--warmup", "-1"], "--warmup=-1: must be >= 0"),
    (["memory_per_grain.py", "--k", "2"], "--k [2]: one or more edges of at least 3"),
])
def test_the_benches_brought_in_refuse_with_exit_2(tmp_path, args, words):
    p = _bench([*args, *(["--out", str(tmp_path / "x.json")] if args[0] == "triaxial_disc.py"
                         else [])], tmp_path)
    assert p.returncode == 2 and words in p.stderr, (p.returncode, p.stderr[-2000:])
