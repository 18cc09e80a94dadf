"""Every case command the docs show parses with that case's own parser: a flag renamed or
removed in a case makes this fail with the page and the line. (The commands run at smoke size
elsewhere: each case's --smoke in tests/test_cases_smoke.py, the examples in
tests/test_examples.py.)"""

import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# The guide and its measured studies (docs/studies/): every page under docs/.
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("**/*.md"))]

_COMMAND = re.compile(r"^(?:\.venv/bin/)?(?:geogrid-dem run (?P<name>[a-z0-9-]+)"
                      r"|(?:\.venv/bin/)?python3? (?:cases/(?P<script>[a-z0-9_]+)\.py"
                      r"|-m geogrid_dem\.cases\.(?P<module>[a-z0-9_]+)))(?P<rest>.*)$")


def _blocks(text: str):
    """(line number, command line) of the shell code blocks, continuations joined."""
    fence, shell, buf, start = False, False, "", 0
    for k, line in enumerate(text.splitlines(), start=1):
        if line.strip().startswith("```"):
            fence = not fence
            shell = fence and line.strip() in ("```", "```bash", "```sh", "```console")
            continue
        if not shell:
            continue
        if not buf:
            start = k
        buf += line.rstrip().removesuffix("\\") + " "
        if not line.rstrip().endswith("\\"):
            yield start, buf.strip()
            buf = ""


def documented_commands():
    from geogrid_dem.cases import CASES

    by_module = {c.module: name for name, c in CASES.items()}
    found = []
    for page in PAGES:
        for k, line in _blocks(page.read_text()):
            line = line.split(" #", 1)[0].strip()
            m = _COMMAND.match(line)
            if not m:
                continue
            name = m["name"] or by_module.get(m["script"] or m["module"])
            if name is None or "..." in line or "<" in line:
                continue
            found.append((f"{page.relative_to(ROOT)}:{k}", name, shlex.split(m["rest"])))
    return found


COMMANDS = documented_commands()


def test_the_docs_show_commands_of_every_case():
    from geogrid_dem.cases import CASES

    assert len(COMMANDS) >= 20
    shown = {name for _, name, _ in COMMANDS}
    assert shown >= set(CASES) - {"deposition"}, set(CASES) - shown


def test_a_renamed_flag_is_caught():
    from geogrid_dem.runs import case_parser

    with pytest.raises(SystemExit):
        case_parser("triaxial").parse_args(["--cell-presure", "1e5"])


@pytest.mark.parametrize("where,name,argv", COMMANDS, ids=[c[0] for c in COMMANDS])
def test_a_documented_command_parses(where, name, argv, capsys):
    from geogrid_dem.runs import case_parser

    if argv and argv[0].endswith(".toml"):
        pytest.skip("a run file")
    if "--help" in argv or "-h" in argv:
        return
    try:
        case_parser(name).parse_args(argv)
    except SystemExit:
        pytest.fail(f"{where}: `{name} {' '.join(argv)}` is refused: "
                    f"{capsys.readouterr().err.strip().splitlines()[-1]}")
