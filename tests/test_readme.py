"""Every README example runs as written (issue 15): the README's code blocks, run.

The convention
--------------
A fenced code block of ``README.md`` is run when its FIRST line is a marker comment::

    # test: quick                          run in the default suite (`make test`)
    # test: slow                           run only with `-m slow` (`make test-all`)
    # test: skip                           never run (a viewer, a cluster, a long job)
    # test: quick needs runs/demo/x.npz    ... and only when these paths exist (relative
                                           to the repository root, e.g. `make demo` outputs)

The marker is a comment in both shell and Python, so the block stays copy-pasteable.
Blocks fenced as ``python`` (or ``py``) run with this interpreter; every other block
(untagged, ``bash``, ``sh``, ``shell``, ``console``) runs with ``bash -e -o pipefail``,
a leading ``$ `` prompt stripped; blocks tagged otherwise (``text``, ``yaml``, ...) are
not commands and never run (tag a layout tree or printed output ``text``). A command
block without a marker is not run: it is reported as a skipped test ("unmarked"), so
``pytest -rs tests/test_readme.py`` lists what the README does not test. Mark a block
``slow`` when it simulates for more than ~30 s on one core.

Blocks run in a scratch directory that holds a symbolic link to every top-level entry
of the repository (so ``.venv/bin/cnt-sim``, ``docs/...`` and ``runs/demo/...`` resolve,
and new top-level outputs land in the scratch directory), with this interpreter's
``bin`` first on ``PATH`` and ``MPLBACKEND=Agg``.

This file also checks the ``LICENSE`` and ``CITATION.cff`` (issue 15, housekeeping).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAPER_DOI = "10.1021/acs.nanolett.7b04676"

MARKER = re.compile(r"^#\s*test:\s*(?P<kind>quick|slow|skip)\b(?:\s+needs\s+(?P<needs>.+?))?\s*$")
PYTHON = {"python", "py", "python3"}
TIMEOUT_S = {"quick": 300, "slow": 3600}
# Top-level entries of the repository not linked into the scratch directory.
NOT_LINKED = {".git", ".pytest_cache", ".ruff_cache", ".hypothesis"}


@dataclass(frozen=True)
class Block:
    """One fenced code block: where it starts (1-based line of the fence), its language
    (the fence's info word, "" when untagged), its code, and its marker."""

    line: int
    lang: str
    code: str
    kind: str | None  # "quick", "slow", "skip", or None (unmarked)
    needs: tuple[str, ...] = ()

    @property
    def is_python(self) -> bool:
        return self.lang.lower() in PYTHON


def code_blocks(text: str) -> list[Block]:
    """The fenced code blocks of a Markdown text (``` or ~~~ fences, CommonMark style:
    a fence closes with the same character, at least as long, and no info string)."""
    blocks: list[Block] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^ {0,3}(`{3,}|~{3,})\s*([^`\s]*)", lines[i])
        if not m:
            i += 1
            continue
        fence, lang, start = m.group(1), m.group(2), i
        body: list[str] = []
        i += 1
        while i < len(lines) and not re.match(
            rf"^ {{0,3}}{re.escape(fence[0])}{{{len(fence)},}}\s*$", lines[i]
        ):
            body.append(lines[i])
            i += 1
        i += 1  # the closing fence (or the end of the text)
        first = body[0].strip() if body else ""
        marker = MARKER.match(first)
        kind = marker.group("kind") if marker else None
        needs = tuple((marker.group("needs") or "").split()) if marker else ()
        blocks.append(Block(start + 1, lang, "\n".join(body) + "\n", kind, needs))
    return blocks


def runnable(block: Block) -> bool:
    """Shell and Python blocks (not diagrams, tables or YAML)."""
    return block.is_python or block.lang.lower() in {"", "bash", "sh", "shell", "console"}


def shell_code(code: str) -> str:
    return "\n".join(line[2:] if line.startswith("$ ") else line for line in code.splitlines())


def scratch_clone(tmp: Path) -> Path:
    """A directory that links every top-level entry of the repository."""
    work = tmp / "clone"
    work.mkdir()
    for entry in ROOT.iterdir():
        if entry.name not in NOT_LINKED:
            (work / entry.name).symlink_to(entry, target_is_directory=entry.is_dir())
    return work


def run_block(block: Block, tmp: Path) -> subprocess.CompletedProcess[str]:
    work = scratch_clone(tmp)
    env = dict(os.environ, MPLBACKEND="Agg")
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    if block.is_python:
        script = tmp / f"readme_{block.line}.py"
        script.write_text(block.code)
        argv = [sys.executable, str(script)]
    else:
        argv = ["bash", "-e", "-o", "pipefail", "-c", shell_code(block.code)]
    return subprocess.run(argv, cwd=work, env=env, capture_output=True, text=True,
                          timeout=TIMEOUT_S[block.kind or "quick"])  # fmt: skip


def _params() -> list:
    if not README.exists():
        return [pytest.param(None, marks=pytest.mark.skip(reason="no README.md"), id="none")]
    params = []
    for block in filter(runnable, code_blocks(README.read_text(encoding="utf-8"))):
        marks: list = []
        if block.kind is None:
            marks.append(pytest.mark.skip(reason="unmarked: add '# test: quick|slow|skip'"))
        elif block.kind == "skip":
            marks.append(pytest.mark.skip(reason="marked '# test: skip'"))
        elif block.kind == "slow":
            marks.append(pytest.mark.slow)
        params.append(pytest.param(block, marks=marks, id=f"README.md:{block.line}"))
    return params or [pytest.param(None, marks=pytest.mark.skip(reason="no blocks"), id="none")]


@pytest.mark.parametrize("block", _params())
def test_readme_block_runs(block: Block, tmp_path: Path) -> None:
    missing = [p for p in block.needs if not (ROOT / p).exists()]
    if missing:
        pytest.skip(f"needs {', '.join(missing)} (e.g. from `make demo`)")
    done = run_block(block, tmp_path)
    assert done.returncode == 0, (
        f"README.md line {block.line} exits {done.returncode}:\n{block.code}\n"
        f"--- stdout\n{done.stdout[-3000:]}\n--- stderr\n{done.stderr[-3000:]}"
    )


# ---- the convention itself ----------------------------------------------------------------

SAMPLE = """\
Intro.

```
# test: quick
echo one
```

~~~python
# test: slow needs runs/a.npz runs/b.npz
print("two")
~~~

````
# test: skip
```
nested fence text
````

```yaml
# test: quick
key: value
```

```bash
$ echo unmarked
```
"""


def test_code_blocks_and_markers() -> None:
    blocks = code_blocks(SAMPLE)
    assert [(b.line, b.lang, b.kind) for b in blocks] == [
        (3, "", "quick"), (8, "python", "slow"), (13, "", "skip"), (19, "yaml", "quick"),
        (24, "bash", None),
    ]  # fmt: skip
    assert blocks[0].code == "# test: quick\necho one\n"
    assert blocks[1].needs == ("runs/a.npz", "runs/b.npz") and blocks[1].is_python
    assert "nested fence text" in blocks[2].code  # a longer fence holds a shorter one
    assert [runnable(b) for b in blocks] == [True, True, True, False, True]
    assert shell_code(blocks[4].code).strip() == "echo unmarked"


def test_a_marked_block_runs_in_a_scratch_clone(tmp_path: Path) -> None:
    shell = Block(1, "", "# test: quick\n$ test -f pyproject.toml && touch made_here\n", "quick")
    (tmp_path / "a").mkdir()
    done = run_block(shell, tmp_path / "a")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "a" / "clone" / "made_here").exists()
    assert not (ROOT / "made_here").exists()
    (tmp_path / "b").mkdir()
    python = Block(1, "python", "# test: quick\nimport cnt_env\nraise SystemExit(3)\n", "quick")
    assert run_block(python, tmp_path / "b").returncode == 3
    failing = Block(1, "", "# test: quick\nfalse | cat\necho not reached\n", "quick")
    (tmp_path / "c").mkdir()
    assert run_block(failing, tmp_path / "c").returncode != 0  # pipefail


# ---- LICENSE and CITATION.cff ----------------------------------------------------------


def test_license_is_mit() -> None:
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "WITHOUT WARRANTY OF ANY KIND" in text


def test_citation_cites_the_software_and_the_paper() -> None:
    import yaml

    import cnt_env

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    assert cff["title"] and cff["authors"] and cff["message"]
    assert cff["license"] == "MIT" and str(cff["version"]) == cnt_env.__version__
    (paper,) = [r for r in cff["references"] if r.get("doi") == PAPER_DOI]
    assert paper["type"] == "article" and paper["journal"] == "Nano Letters"
    assert paper["year"] == 2018 and paper["volume"] == 18
    names = [a["family-names"] for a in paper["authors"]]
    assert names == ["Jawed", "Hadjiconstantinou", "Parks", "Reis"]
    assert "flow-directed deposition" in paper["title"]
