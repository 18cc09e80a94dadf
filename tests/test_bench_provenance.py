"""bench/throughput.py's provenance hashes the core's sources as scripts/setup.sh does, so
``build_matches_sources`` is true for a build of the tree (it was false after setup.sh's hash
took in the list of Python modules: every JSON line warned of a stale build)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
import throughput  # noqa: E402


def test_the_bench_hashes_the_sources_as_setup_does():
    text = (ROOT / "scripts" / "setup.sh").read_text()
    m = re.search(r"^SRC_HASH=\$\((.*?)\)\s*$", text, re.M | re.S)
    assert m, "setup.sh's SRC_HASH line"
    setup_hash = subprocess.run(["bash", "-c", m.group(1)], cwd=ROOT, capture_output=True,
                                text=True, check=True).stdout.strip()
    assert len(setup_hash) == 64
    assert throughput.provenance()["cpp_source_hash"] == setup_hash[:12]
