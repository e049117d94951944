"""Every command in README.md, docs/*.md and patches/**/README.md works as written on
a fresh clone (issue 29). It found, when written: docs/naoqi.md's and docs/ros2.md's
`pip install 'sonibus[...]'` (sonibus is on no package index), the README's
`pd -jack` without `-nojackconnect` (tests/test_docs_jack.py) and a listing line of
design.md whose command ran into its description.

What is a command: a line of a shell block (```sh, ```bash, ```console or a bare
```), a line of an indented code block, or an inline code span, that starts with
``sonibus``, ``make``, ``pip``/``python3 -m pip``, ``pd`` (or a path ending in
one of them: ``~/venv/bin/sonibus``). Output lines (``sonibus: error: ...``),
prose and other languages (```toml, ```python) are not commands.

What is checked of each, with no robot and no sound card:

- ``sonibus ...``: parsed by sonibus's own parser (every flag must exist for that
  subcommand, every positional be there; ``send``'s words go through the
  command's own checks; ``run FILE --only NODE``'s file must exist and hold
  NODE); and those that need no hardware run for real (``adapters``,
  ``--help``, ``--version``, ``info``/``export``/``plot`` of a recording made
  here, ``run`` of an example of simulated parts only, until it is running).
- ``make TARGET``: TARGET is a target of the Makefile.
- ``pip install``: sonibus is not on the package index, so ``sonibus[extra]``
  without a path is a lie; every extra named must be one of pyproject.toml's.
- ``pd ...``: every flag must be one ``pd -help`` lists.

A usage line (a word in ``[...]``), a listing line (a command, two spaces or
more, what it does) and an inline span in prose are taken as synopses: only
their flags are checked. To keep a block out altogether (output that starts
with ``sonibus``, a line of several commands in one: ``sonibus record | replay``),
put ``<!-- not a command -->`` on the line just before the block (or before the
paragraph holding the span). A command that needs a robot or hardware needs no
mark: only the commands listed above run, the others are only parsed.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import logging
import re
import shlex
import subprocess
import threading
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

from sonibus.bus.cli import Environment, Exit, app
from sonibus.bus.cli.send import command_args

from .conftest import Network, wait_for
from .recorder.conftest import record_sim

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "patches").glob("**/README.md"))]
SKIP_MARK = "<!-- not a command -->"
SHELL_FENCES = {"", "sh", "bash", "shell", "console"}
PROGRAMS = {"sonibus", "make", "pip", "pip3", "pd"}


@dataclass(frozen=True)
class Example:
    """One command as a doc writes it, and where."""

    doc: str
    line: int
    text: str
    synopsis: bool = False  # a code span in prose, a usage line or a listing: only its flags are checked

    @property
    def words(self) -> list[str]:
        try:
            return shlex.split(self.text, comments=True)
        except ValueError:  # (an apostrophe in a span of prose: "sonibus send pepper say I'm")
            return self.text.split()

    def __str__(self) -> str:
        return f"{self.doc}:{self.line}: {self.text}"


def _program(word: str) -> str:
    return word.rsplit("/", 1)[-1]


def _is_command(text: str) -> bool:
    """Whether a line of a code block or a code span is a command (not output, not prose)."""
    text = text.removeprefix("$ ").strip()
    if not text or text.startswith(("#", "sonibus:")):
        return False
    first = text.split()[0]
    if first in ("python3", "python") and " -m pip " in f" {text} ":
        return True
    return _program(first) in PROGRAMS and (len(text.split()) > 1 or first == "sonibus")


def _commands(line_text: str) -> list[str]:
    """The commands of one shell line: split at ``&&``, ``;``, ``|``, a trailing ``&``;
    the part before a ``#`` comment; with ``cd DIR &&`` and ``sudo`` left out."""
    text = re.sub(r"\s#\s.*$", "", line_text.removeprefix("$ ")).strip()
    parts = [p.strip() for p in re.split(r"&&|;|\|\|?|&\s*$", text) if p.strip()]
    return [p.removeprefix("sudo ").strip() for p in parts if not p.startswith("cd ")]


def examples(path: Path) -> list[Example]:
    """The commands of one markdown file (see the module's docstring)."""
    doc = str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else path.name
    found: list[Example] = []
    lines = path.read_text(encoding="utf-8").splitlines()
    fence: str | None = None   # the info string of the fenced block we are in
    indented = False           # in an indented code block
    marked = skipping = False  # a mark was seen / the block it marks is being read
    paragraph: list[tuple[int, str]] = []

    def add(number: int, text: str) -> None:
        text = re.sub(r"\s#\s.*$", "", text).strip()  # (a comment, often aligned with spaces)
        command, gap, _ = re.split(r"(\s{2,})", text, maxsplit=1) if "  " in text else (text, "", "")
        for part in _commands(command):  # (after a gap of spaces: what a listing says of the command)
            if _is_command(part):
                found.append(Example(doc, number, part, synopsis=bool(gap) or re.search(r"(^|\s)\[", part) is not None))

    def end_paragraph() -> None:  # its inline code spans (one may cross a line break)
        joined = "\n".join(t for _, t in paragraph)
        for match in re.finditer(r"(?<!`)`([^`]+)`(?!`)", joined) if not skipping else ():
            number = paragraph[joined.count("\n", 0, match.start())][0]
            for text in _commands(" ".join(match[1].split())):
                if _is_command(text):
                    found.append(Example(doc, number, text, synopsis=True))
        paragraph.clear()

    def begin() -> bool:  # a block begins: is it the one a mark is for?
        nonlocal marked
        was, marked = marked, False
        return was

    for number, line in enumerate(lines, 1):
        stripped = line.strip()
        if fence is not None:
            if stripped.startswith("```"):
                fence = None
            elif fence in SHELL_FENCES and not skipping:
                add(number, stripped)
            continue
        if stripped == SKIP_MARK:
            end_paragraph()
            marked = True
        elif stripped.startswith("```"):
            end_paragraph()
            fence, skipping, indented = stripped[3:].strip(), begin(), False
        elif not stripped:
            end_paragraph()
            indented = False
        elif line.startswith("    ") and not paragraph and (indented or not lines[number - 2].strip()):
            if not indented:
                indented, skipping = True, begin()
            if not skipping:
                add(number, stripped)
        else:
            if not paragraph:
                skipping = begin()
            indented = False
            paragraph.append((number, line))
    end_paragraph()
    return found


def every_example() -> list[Example]:
    return [example for path in DOCS for example in examples(path)]


# -- checking one command ----------------------------------------------------------


@functools.cache
def _parser() -> argparse.ArgumentParser:
    with contextlib.redirect_stderr(io.StringIO()):  # (the test plug-in's broken command is named there)
        logging.disable(logging.WARNING)
        try:
            return app.parser(app.commands())
        finally:
            logging.disable(logging.NOTSET)


def _subparser(name: str):
    top = _parser()
    actions = [a for a in top._actions if a.dest == "command"]  # (argparse keeps subparsers there)
    return actions[0].choices.get(name)


def check_sonibus(example: Example) -> str:
    """What is wrong with a ``sonibus`` command ("" if nothing)."""
    words = example.words[1:]
    if not words:
        return ""
    if example.synopsis:
        sub = _subparser(words[0])
        if sub is None:  # (prose may name a part of a word: TAB completes `sonibus re`)
            return ""
        known = {s for a in sub._actions for s in a.option_strings}
        flags = [w.split("=")[0].strip("[]") for w in words[1:] if w.lstrip("[").startswith("-")]
        wrong = [f for f in flags if f not in known]
        return f"sonibus {words[0]} has no {', '.join(wrong)}" if wrong else ""
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            args = _parser().parse_args(words)
    except SystemExit as exc:
        return "" if exc.code == 0 else err.getvalue().strip().splitlines()[-1]
    return _check_args(args)


def _check_args(args) -> str:
    """The checks a command makes of its arguments beyond argparse, where a doc can get them wrong."""
    if args.command == "send" and args.verb and not any("<" in w for w in args.args):
        try:
            command_args(args.verb, args.args)
        except Exception as exc:  # (ConfigError: what `sonibus send` would say)
            return str(exc)
    if args.command == "run" and not args.config.startswith(("~", "/", "$")) and "/" in args.config:
        path = ROOT / args.config
        if not path.exists():
            return f"{args.config} is not in the clone"
        nodes = tomllib.loads(path.read_text(encoding="utf-8")).get("nodes", {})
        missing = [n for n in args.only or () if n not in nodes]
        if missing:
            return f"{args.config} has no node {', '.join(missing)} (nodes: {', '.join(nodes)})"
    return ""


def _extras() -> set[str]:
    return set(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"])


def check_pip(example: Example) -> str:
    """``pip install``: sonibus from a path (it is on no index), with extras that exist."""
    for word in example.words:
        found = re.fullmatch(r"(.*?)\[([\w,-]+)\]", word)
        if not found:
            continue
        place, extras = found[1], found[2].split(",")
        if place == "sonibus":
            return f"'{word}': sonibus is not on the package index — install from the clone: pip install '.[...]'"
        unknown = [e for e in extras if e not in _extras()]
        if unknown:
            return f"no extra {', '.join(unknown)} (pyproject.toml has {', '.join(sorted(_extras()))})"
    return ""


def _make_targets() -> set[str]:
    text = (ROOT / "Makefile").read_text()
    return set(re.findall(r"^([\w-]+):", text, re.MULTILINE))


def check_make(example: Example) -> str:
    wrong = [w for w in example.words[1:] if not w.startswith("-") and "=" not in w and w not in _make_targets()]
    return f"no make target {', '.join(wrong)}" if wrong else ""


@functools.cache
def _pd_flags() -> set[str]:
    result = subprocess.run(["pd", "-help"], capture_output=True, text=True, timeout=30)
    return set(re.findall(r"(?<![\w-])(-[a-z][\w-]*)", result.stdout + result.stderr))  # ("-nosound is synonym")


def check_pd(example: Example) -> str:
    flags = _pd_flags()
    wrong = [w for w in example.words[1:] if w.startswith("-") and w not in flags]
    return f"pd -help lists no {', '.join(wrong)}" if wrong else ""


CHECKS = {"sonibus": check_sonibus, "pip": check_pip, "pip3": check_pip, "make": check_make, "pd": check_pd}


def check(example: Example) -> str:
    words = example.words
    program = "pip" if words[:3] in (["python3", "-m", "pip"], ["python", "-m", "pip"]) else _program(words[0])
    return CHECKS[program](example)


REPO_DIRS = ("examples", "patches", "docs", "scripts", "adapters", "bus", "schemas", "tests", "bench")


def check_paths(example: Example) -> str:
    """Files of the clone a command names (``examples/jack.toml``) must be there."""
    missing = [w for w in example.words if w.split("/")[0] in REPO_DIRS and "/" in w and not (ROOT / w).exists()]
    return f"{', '.join(missing)}: not in the clone" if missing else ""


def problems(example: Example) -> str:
    return check_paths(example) or check(example)


# -- the tests ----------------------------------------------------------------------


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_command_of_the_doc_is_one_sonibus_make_pip_and_pd_take(path):
    """Issue 29, items 7 and 9: docs/naoqi.md told users to `pip install 'sonibus[naoqi]'`
    (sonibus is on no package index); flags a command does not have."""
    wrong = [f"{example}\n    → {problem}" for example in examples(path) if (problem := problems(example))]
    assert not wrong, f"{len(wrong)} command(s) of {path.name} do not work as written:\n" + "\n".join(wrong)


def test_the_extraction_finds_the_commands_and_only_them(tmp_path):
    """Commands of shell blocks, indented blocks and code spans, not output, prose or
    other languages; a marked block is left out."""
    doc = tmp_path / "doc.md"
    doc.write_text("\n".join([
        "Run `sonibus nodes --timeout 2` or `make test`; `sonibus:` is not one.", "",
        "    sonibus demo --robot nao   # a comment", "        simulated NAO → OSC", "", "```sh",
        "pip install -e '.[jack]' && pd -jack -nojackconnect &", "```", "", "```toml", 'sonibus = "not a command"',
        "```", "", SKIP_MARK, "```", "sonibus top [--every S] | what", "```", "", "    sonibus record a.mcap",
        "    sonibus: error: output", ""]))
    found = [(e.line, e.text, e.synopsis) for e in examples(doc)]
    assert found == [(1, "sonibus nodes --timeout 2", True), (1, "make test", True),
                     (3, "sonibus demo --robot nao", False),
                     (7, "pip install -e '.[jack]'", False), (7, "pd -jack -nojackconnect", False),
                     (19, "sonibus record a.mcap", False)]
    assert len(examples(ROOT / "README.md")) > 30, "the extraction found few commands in the README: is it broken?"


# -- running those that need no robot ----------------------------------------------------

RUN_NOW = {"adapters", "info", "export", "plot"}    # run to their end
RUN_UNTIL_RUNNING = {"run", "demo"}                 # run until they say so, then Ctrl-C
SIMULATED = {"sim", "osc", "features", "console"}   # what an example `run` may hold to be run here
ISOLATED = ["--no-multicast", "--listen", "tcp/127.0.0.1:0"]  # (its own bus: never another test's)


def _runnable(example: Example) -> bool:
    words = example.words
    if example.synopsis or _program(words[0]) != "sonibus" or any(w.startswith(("<", "~", "$")) for w in words[1:]):
        return False
    if "--help" in words or words[1:] == ["--version"]:
        return True
    command = words[1] if len(words) > 1 else ""
    if command == "run":
        if not (ROOT / words[2]).is_file():  # (a file of the reader's: foxglove.toml, show.toml)
            return False
        nodes = tomllib.loads((ROOT / words[2]).read_text(encoding="utf-8")).get("nodes", {})
        only = words[words.index("--only") + 1:] if "--only" in words else list(nodes)
        return all(nodes[n].get("adapter") in SIMULATED for n in only)
    return command in RUN_NOW | RUN_UNTIL_RUNNING


def _until_running(words: list[str], env: Environment, what: str) -> list[int]:
    """Run ``sonibus WORDS`` on a bus of its own until it says it runs, then stop it; its status."""
    status: list[int] = []
    thread = threading.Thread(target=lambda: status.append(app.main([*words, *ISOLATED], env)))
    thread.start()
    try:
        wait_for(lambda: not thread.is_alive() or "sonibus: running " in env.stdout.getvalue(),
                 timeout=30, what=f"{what} to say it runs")
    finally:
        env.stop.set()
        thread.join(10)
    return status


def test_the_commands_that_need_no_robot_run_as_written(tmp_path, monkeypatch):
    """`sonibus adapters`, `--version`, `--help`, `info`/`export`/`plot` of a recording
    made here (under the name the doc gives it), `run` of an example of simulated parts
    and `demo` (until they say they run, on a bus of their own), exactly as the docs
    write them, from the clone's folder (in this process: `main` is the command line)."""
    chosen = list({e.text: e for e in every_example() if _runnable(e)}.values())
    recordings = {w for e in chosen for w in e.words if w.endswith(".mcap")}
    net = Network()
    try:
        record_sim(net, tmp_path / "made.mcap", frames=30)
    finally:
        net.close()
    for name in recordings:
        (tmp_path / name).write_bytes((tmp_path / "made.mcap").read_bytes())
    failed = []
    for example in chosen:
        words = example.words[1:]
        monkeypatch.chdir(tmp_path if set(words) & recordings else ROOT)
        env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
        if words[0] in RUN_UNTIL_RUNNING and "--help" not in words:
            status = _until_running(words, env, str(example))
            ok = status in ([Exit.OK], [Exit.INTERRUPTED])
        else:
            status = [app.main(words, env)]
            ok = status == [Exit.OK]
        if not ok:
            failed.append(f"{example}\n    → exit {status}: {env.stderr.getvalue().strip()[-500:]}")
    assert not failed, "\n".join(failed)
    assert {"adapters", "info", "run", "demo"} <= {e.words[1] for e in chosen if len(e.words) > 1}
