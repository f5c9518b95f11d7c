"""The README and the manual stay true.

Every ``groundstation ...`` / ``onboard ...`` subcommand and ``--option`` the pages name (in
fenced blocks and inline code) must exist in the programs' argument parsers, and every command
of every fenced ``sh`` block runs and exits 0, unless the line just before the block's opening
fence is ``<!-- not-run -->`` (docs/architecture.md, "Docs that stay true"). Runnable examples
must therefore be cheap: ``--help``, ``scenarios``, ``onboard gains``, a short ``sortie``.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
NOT_RUN = "<!-- not-run -->"
RUN_LANGS = {"sh", "bash", "shell", "console"}
PROGRAMS = ("groundstation", "onboard")
RUN_TIMEOUT_S = 60
FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*([\w+-]*)")
INLINE = re.compile(r"(`+)(.+?)\1")
# a command starts its line or segment: after a prompt, VAR=value settings or a path to its bin/
INVOCATION = re.compile(
    r"\s*(?:\$\s+)?(?:[A-Z_][A-Z0-9_]*=\S*\s+)*(?:[\w./=-]*/)?"
    r"(groundstation|onboard)((?:[ \t]+\S+)*)"
)
OPTION = re.compile(r"(?<![\w-])(--[a-z0-9][a-z0-9-]*)")
ENV_SETTING = re.compile(r"^[A-Z_][A-Z0-9_]*=\S*$")

# Each program's parser, taken where it is built: ``main`` is run with ``parse_args`` replaced
# by a function that hands the parser back, so however a program builds its parser, its
# subcommands and options are the ones checked. A subprocess with PEREGRINE_JIT=0, so that
# importing the runtime compiles nothing.
_DUMP = """
import argparse, json, sys

class Got(Exception):
    pass

def grab(self, *args, **kwargs):
    raise Got(self)

argparse.ArgumentParser.parse_args = grab

def options(parser):
    subs = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            subs = {name: sorted(p._option_string_actions) for name, p in action.choices.items()}
    return {"": sorted(parser._option_string_actions), "subcommands": subs}

out = {}
for name in ("groundstation", "onboard"):
    module = __import__(name + ".cli", fromlist=["main"])
    try:
        module.main([])
    except Got as got:
        out[name] = options(got.args[0])
print(json.dumps(out))
"""


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    lang: str
    lines: tuple[str, ...]
    run: bool


def _rel(page: Path) -> str:
    return str(page.relative_to(ROOT))


def _scan(page: Path) -> tuple[list[Block], list[tuple[int, str]]]:
    """The page's fenced blocks, and its inline code spans outside them (line, text)."""
    blocks: list[Block] = []
    inline: list[tuple[int, str]] = []
    lines = page.read_text(encoding="utf-8").splitlines()
    paragraph: list[str] = []
    first = 0

    def flush() -> None:  # inline code may wrap, so spans are found paragraph by paragraph
        inline.extend((first, span) for _, span in INLINE.findall(" ".join(paragraph)))
        paragraph.clear()

    i = 0
    previous = ""
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m is None:
            if lines[i].strip():
                if not paragraph:
                    first = i + 1
                paragraph.append(lines[i].strip())
                previous = lines[i].strip()
            else:
                flush()
            i += 1
            continue
        flush()
        indent, fence, lang = m.group(1), m.group(2), m.group(3).lower()
        start = i
        body = []
        i += 1
        while i < len(lines) and not lines[i].strip().startswith(fence[0] * len(fence)):
            body.append(lines[i][len(indent) :] if lines[i].startswith(indent) else lines[i])
            i += 1
        blocks.append(Block(page, start + 1, lang, tuple(body), previous != NOT_RUN))
        previous = ""
        i += 1
    flush()
    return blocks, inline


def _logical_lines(lines: tuple[str, ...]) -> list[str]:
    """Lines with shell continuations (``\\``) joined, and a synopsis's indented ``[--...``
    continuation lines joined to the command they continue."""
    out: list[str] = []
    carry = False
    for raw in lines:
        stripped = raw.strip()
        if out and (carry or (raw[:1].isspace() and stripped[:1] in "[-")):
            out[-1] += " " + stripped.rstrip("\\")
        else:
            out.append(stripped.rstrip("\\"))
        carry = stripped.endswith("\\")
    return out


def _invocations(text: str) -> list[tuple[str, list[str]]]:
    """(program, words) for every groundstation/onboard command a line of code starts (or
    starts after ``&&``, ``;`` or a pipe); the words stop at a comment or the next command."""
    text = re.split(r"\s#\s|\s#$|&&|;|\|\s+(?=[A-Za-z])", text)
    found = []
    for part in text:
        m = INVOCATION.match(part)
        if m is not None:
            found.append((m.group(1), m.group(2).split()))
    return found


def _named() -> list[tuple[str, int, str, list[str]]]:
    """(where, program, words) for every command any page names."""
    out = []
    for page in PAGES:
        blocks, inline = _scan(page)
        for block in blocks:
            if block.lang in ("toml", "json", "python"):
                continue
            for n, line in enumerate(_logical_lines(block.lines)):
                for program, words in _invocations(line):
                    out.append((f"{_rel(page)}:{block.line + n + 1}", program, words))
        for n, span in inline:
            for program, words in _invocations(span):
                out.append((f"{_rel(page)}:{n}", program, words))
    return out


@pytest.fixture(scope="module")
def parsers() -> dict:
    env = dict(os.environ, PEREGRINE_JIT="0")
    out = subprocess.run(
        [sys.executable, "-c", _DUMP], capture_output=True, text=True, env=env, timeout=120
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_the_pages_are_found_and_name_commands():
    names = [p.name for p in PAGES]
    assert "README.md" in names and len(names) > 3
    assert len(_named()) > 50


def _problems(named: list[tuple[str, str, list[str]]], parsers: dict) -> list[str]:
    problems = []
    for where, program, words in named:
        tree = parsers[program]
        sub = next((w for w in words if not w.startswith(("-", "[", "<"))), None)
        allowed = set(tree[""])
        if sub is not None and re.fullmatch(r"[a-z][a-z-]*", sub) and tree["subcommands"]:
            if sub not in tree["subcommands"]:
                problems.append(f"{where}: `{program} {sub}`: no such subcommand")
                continue
            allowed |= set(tree["subcommands"][sub])
        for option in OPTION.findall(" ".join(words)):
            if option not in allowed:
                shown = f"{program} {sub}" if sub else program
                problems.append(f"{where}: `{shown}` has no option {option}")
    return problems


def test_every_subcommand_and_option_named_exists(parsers):
    problems = _problems(_named(), parsers)
    assert not problems, "\n".join(problems)


def test_the_check_finds_what_does_not_exist(parsers):
    named = [
        ("a", *found)
        for line in (
            "groundstation sortie cv-top-to-bottom --lawz png",
            "PEREGRINE_JIT=0 groundstation fly now",
            "x && /opt/venv/bin/onboard run --camera 0 --no-such-thing  # --comment-only",
            "groundstation campaign static --laws png --n 3 --set gains.k_v=5",
        )
        for found in _invocations(line)
    ]
    assert _problems(named, parsers) == [
        "a: `groundstation sortie` has no option --lawz",
        "a: `groundstation fly`: no such subcommand",
        "a: `onboard run` has no option --no-such-thing",
    ]


def _runnable() -> list[tuple[str, str]]:
    """(where, command) for every command of the runnable blocks, each distinct command
    once (``where`` lists every place it appears)."""
    places: dict[str, list[str]] = {}
    for page in PAGES:
        blocks, _ = _scan(page)
        for block in blocks:
            if block.lang not in RUN_LANGS or not block.run:
                continue
            for n, line in enumerate(_logical_lines(block.lines)):
                line = line.removeprefix("$ ")  # a prompt
                if line and not line.startswith("#"):
                    places.setdefault(line, []).append(f"{_rel(page)}:{block.line + n + 1}")
    return [(",".join(where), line) for line, where in places.items()]


def test_runnable_blocks_hold_only_the_programs_commands():
    problems = []
    for where, line in _runnable():
        words = shlex.split(line, comments=True)
        while words and ENV_SETTING.match(words[0]):
            words.pop(0)
        if not words or words[0] not in PROGRAMS:
            problems.append(
                f"{where}: `{line}` is not a groundstation/onboard command: mark "
                f"its block {NOT_RUN}"
            )
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize(("where", "line"), _runnable(), ids=[w for w, _ in _runnable()])
def test_runnable_command_exits_0(where, line, tmp_path):
    words = shlex.split(line, comments=True)
    env = dict(os.environ, PEREGRINE_JIT="0")
    while words and ENV_SETTING.match(words[0]):
        key, value = words.pop(0).split("=", 1)
        env[key] = value
    if not words or words[0] not in PROGRAMS:
        pytest.fail(f"{where}: not a groundstation/onboard command (mark it {NOT_RUN})")
    out = subprocess.run(
        [sys.executable, "-m", words[0], *words[1:]],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
    )
    assert out.returncode == 0, f"{where}: `{line}` exited {out.returncode}\n{out.stderr[-2000:]}"


def test_the_benchmark_page_gives_each_figure_its_command():
    from groundstation.bench.docs_table import page

    core = {
        "rtf_projected": 251.4,
        "rtf_projected_min": 199.6,
        "rtf_rendered": 22.25,
        "rtf_rendered_min": 20.0,
        "tick_median_ms": 0.0361,
        "tick_p99_ms": 0.09,
        "tick_median_with_fusion_ms": 0.05,
        "detector_median_ms": 1.234,
        "detector_p99_ms": 2.5,
        "render_median_ms": 3.0,
        "peak_rss_mb": 312.4,
        "load_average_1min_before_after": [1.5, 2.25],
    }
    text = page({"core": core}, 2, "a test machine", "compiled", "2026-01-02")
    rows = [ln for ln in text.splitlines() if ln.startswith("| ") and "---" not in ln]
    assert rows[0] == "| figure | measured | command |"
    assert rows[1] == (
        "| simulator real-time factor, projected camera, one core (median) | 251x (slowest 200x)"
        " | `groundstation bench --repeat 2` |"
    )
    assert "| control tick (the loop's work per tick), median / p99 | 0.036 / 0.090 ms |" in text
    assert len(rows) == 1 + 7  # the core rows only: the other kinds did not run
    assert "2026-01-02 (UTC) on a test machine" in text and "core 1.5 -> 2.2" in text
