"""The README answers in a screenful and what it shows works: its length, its Python example run as
written, every `swarmpose` command and flag of its shell blocks (and of the docs pages') a real one,
every local link and anchor of those pages one that exists."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from swarmpose.cli.main import build_parser

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
PAGES = (README, *sorted((REPO / "docs").glob("*.md")))
MAX_README_LINES = 300


def blocks(path: Path, language: str) -> list[str]:
    """The fenced code blocks of ``path`` opened with ```language."""
    return re.findall(rf"^```{language}\n(.*?)^```", path.read_text(encoding="utf-8"), flags=re.M | re.S)


def commands_of(block: str) -> list[list[str]]:
    """Each `swarmpose ...` command line of a shell block, continuation lines joined, comments dropped,
    split into words from the word after `swarmpose` on."""
    text = re.sub(r"\\\n", " ", block)
    out = []
    for line in text.splitlines():
        line = re.sub(r"(^|\s)#.*", "", line)
        match = re.search(r"(?:^|[\s/])swarmpose\s+(.*)", line)
        if match:
            out.append(match.group(1).split())
    return out


def subcommands(parser) -> dict:
    return parser._subparsers._group_actions[0].choices


def test_the_readme_fits_a_screenful_or_so():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines; move details into docs/"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_swarmpose_command_and_flag_in_a_shell_block_exists(page):
    commands = subcommands(build_parser())
    found = 0
    for block in blocks(page, "sh"):
        for words in commands_of(block):
            found += 1
            name = words[0]
            assert name in commands, f"{page.name}: `swarmpose {' '.join(words)}`: no command {name!r}"
            parser = commands[name]
            if name == "bench":
                bench = subcommands(parser)
                assert len(words) > 1 and words[1] in bench, f"{page.name}: `swarmpose {' '.join(words)}`: no bench"
                parser = bench[words[1]]
            flags = {s for a in parser._actions for s in a.option_strings}
            for flag in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", " ".join(words)):
                assert flag in flags, f"{page.name}: `swarmpose {' '.join(words)}`: {name} has no {flag}"
    if page == README:
        assert found >= 5, "the README's shell blocks should show the commands"


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.M | re.S)
    return {slug(h) for h in re.findall(r"^#+\s+(.*)$", text, flags=re.M)}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_local_link_and_anchor_exists(page):
    text = re.sub(r"^```.*?^```", "", page.read_text(encoding="utf-8"), flags=re.M | re.S)
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue
        file, _, anchor = target.partition("#")
        path = (page.parent / file).resolve() if file else page
        assert path.exists(), f"{page.name}: link to {target}: no {path}"
        if anchor:
            assert anchor in anchors(path), f"{page.name}: link to {target}: no such heading in {path.name}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_repository_path_named_exists(page):
    text = page.read_text(encoding="utf-8")
    named = re.findall(r"(?<![\w./-])((?:service|cl|tests|scripts|examples|docker|protocol|docs)/[\w.*/-]*)", text)
    missing = sorted({p for p in named if not list(REPO.glob(p.rstrip(".")))})
    assert not missing, f"{page.name} names paths that do not exist: {missing}"


@pytest.mark.slow
def test_the_readme_python_example_runs_as_written(tmp_path):
    """Every ```python block of the README, run in a fresh process on a 3-frame synthetic sequence
    (the block's first argument: it stands for the quick start's /tmp/walk)."""
    examples = blocks(README, "python")
    assert examples, "the README should show the Python API"
    sequence = tmp_path / "wave"
    made = subprocess.run([sys.executable, "-m", "swarmpose", "-q", "synth", "--body", "builtin", "--motion",
                           "builtin:wave", "--frames", "3", "--out", str(sequence)],
                          capture_output=True, text=True, timeout=300)
    assert made.returncode == 0, made.stderr
    for i, code in enumerate(examples):
        script = tmp_path / f"readme_example_{i}.py"
        script.write_text(code, encoding="utf-8")
        run = subprocess.run([sys.executable, str(script), str(sequence)], cwd=tmp_path,
                             capture_output=True, text=True, timeout=900)
        assert run.returncode == 0, f"README python block {i} failed:\n{run.stdout[-2000:]}\n{run.stderr[-4000:]}"
        assert run.stdout.strip(), f"README python block {i} printed nothing"
