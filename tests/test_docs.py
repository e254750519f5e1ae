"""The documents stay true to the code: the README is a front door of a few screens, every link
and every path they name exists, and every `sds` command line they show names a subcommand
and options that the command has."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest
from sds_cli.cli import build_parser

REPO = Path(__file__).resolve().parents[1]
DOCUMENTS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")),
             REPO / "bench" / "README.md", *sorted(REPO.glob("config/**/README.md")),
             REPO / "firmware" / "README.md"]
README_LINES = 300
"""The README's length at most: what SDS is, the two commands, a real rig step by step, the
command table, links to docs/ (issue 48)."""


def test_the_readme_is_a_front_door() -> None:
    lines = (REPO / "README.md").read_text().splitlines()
    assert len(lines) <= README_LINES, len(lines)
    assert lines[0].startswith("# SDS") and "make demo" in "\n".join(lines[:15])
    linked = set(re.findall(r"\]\((docs/[^)#]+\.md)", "\n".join(lines)))
    assert linked == {str(p.relative_to(REPO)) for p in (REPO / "docs").glob("*.md")}, \
        "every page of docs/ is linked from the README, and only pages that exist"


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: str(p.relative_to(REPO)))
def test_every_link_and_path_a_document_names_exists(document: Path) -> None:
    text = document.read_text()
    missing = [target for target in re.findall(r"\]\(([^)#\s]+)", text)
               if not target.startswith("http") and not (document.parent / target).exists()]
    for path in set(re.findall(
            r"`((?:src|config|bench|tests|docs|firmware|cmake)/[^`\s*<>{}…]+?)`", text)):
        if not (REPO / path.split(":")[0].rstrip(".,;")).exists():
            missing.append(path)
    assert not missing, missing


def subcommands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ("sds",)
                ) -> dict[tuple[str, ...], set[str]]:
    """Each (sub)command's words → its option strings."""
    found = {path: {o for a in parser._actions for o in a.option_strings}}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found.update(subcommands(sub, (*path, name)))
    return found


def test_every_subcommand_and_argument_has_help_text() -> None:
    """`sds <command> --help` explains each of its words: every subcommand has a summary and
    every argument a help text (issue 48)."""
    silent = []
    parsers = [(("sds",), build_parser())]
    while parsers:
        path, parser = parsers.pop()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                summaries = {a.dest: a.help for a in action._choices_actions}
                for name, sub in action.choices.items():
                    if not summaries.get(name):
                        silent.append(" ".join((*path, name)))
                    parsers.append(((*path, name), sub))
            elif not isinstance(action, argparse._HelpAction) and not action.help:
                silent.append(f"{' '.join(path)} {action.option_strings or action.dest}")
    assert not silent, silent


def command_lines(text: str) -> list[str]:
    """The `sds ...` lines of a document's code blocks, continuation lines joined, comments
    left out."""
    lines: list[str] = []
    for block in re.findall(r"```[a-z]*\n(.*?)```", text, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split("#")[0].strip()
            if line.startswith("sds "):
                lines.append(line)
    return lines


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: str(p.relative_to(REPO)))
def test_every_command_line_shown_is_one_the_command_takes(document: Path) -> None:
    known = subcommands(build_parser())
    wrong = []
    for line in command_lines(document.read_text()):
        words = line.split()
        path = ("sds",)
        while len(words) > len(path) and (*path, words[len(path)]) in known:
            path = (*path, words[len(path)])
        if len(path) == 1:
            wrong.append(f"{line}: no such subcommand")
            continue
        options = {w.split("=")[0] for w in words if w.startswith("--")}
        wrong += [f"{line}: {o}" for o in sorted(options - known[path])]
    assert not wrong, wrong


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a Markdown heading: lower case, punctuation dropped, spaces
    to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_every_anchor_a_document_links_is_one_of_its_headings() -> None:
    """bench/README.md's table of today's figures links each figure to its section: every
    `](#anchor)` of a document is one of its own headings'."""
    for document in (REPO / "README.md", REPO / "bench" / "README.md",
                     *(REPO / "docs").glob("*.md")):
        text = document.read_text()
        anchors = {github_anchor(h) for h in re.findall(r"^#{1,6} (.+)$", text, re.MULTILINE)}
        missing = set(re.findall(r"\]\(#([^)]+)\)", text)) - anchors
        assert not missing, (document, missing)


def todays_figures_rows(text: str) -> list[tuple[str, str]]:
    """(anchor, figure) of each row of bench/README.md's table of today's figures."""
    table = text.split("## Today's figures", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"^\| \[[^]]+\]\(#([^)]+)\) \| (.+?) \| `", table, re.MULTILINE)


def test_todays_figures_are_the_figures_of_their_sections() -> None:
    """No figure in bench/README.md's table of today's figures contradicts its section: every
    number the table states (a decimal, or an integer of two digits or more) is written in
    the section its row links to, so neither can change without the other (issue 48)."""
    text = (REPO / "bench" / "README.md").read_text()
    sections = {github_anchor(heading): body for heading, body in
                re.findall(r"^## (.+)\n((?:(?!^## ).*\n?)*)", text, re.MULTILINE)}
    rows = todays_figures_rows(text)
    assert len(rows) >= 10
    for anchor, figure in rows:
        numbers = re.findall(r"\d+\.\d+|\d{2,}", figure.replace(",", ""))
        missing = [n for n in numbers if n not in sections[anchor].replace(",", "")]
        assert not missing, (anchor, missing)


def test_every_figure_of_a_seeded_run_is_one_bench_records() -> None:
    """A sentence of the README or docs/ that names a run's seeds (`seeds 58101–58120`)
    gives only figures that bench/README.md records for that run: every decimal number in it
    is written in an entry of bench/README.md that names the same seeds (from that entry's
    bold start or heading to the next), so a page cannot keep a figure the run did not give
    or the benchmarks have replaced (issue 48)."""
    bench = (REPO / "bench" / "README.md").read_text().replace(",", "")
    # A run's record: from where bench/README.md names its seeds to the next entry (a bold
    # paragraph start) or heading.
    entries = re.split(r"^(?=\*\*|#)", bench, flags=re.MULTILINE)
    checked = 0
    for document in (REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))):
        text = document.read_text().replace(",", "")
        for paragraph in re.split(r"\n\s*\n|\n- |\.\s+(?=[A-Z])", text):
            runs = re.findall(r"seeds (\d{4,5}[–-]\d{4,5})", paragraph)
            if not runs:
                continue
            recorded = "".join(entry for entry in entries if any(run in entry for run in runs))
            assert recorded, (document.name, runs)
            missing = [n for n in re.findall(r"\d+\.\d+", paragraph) if n not in recorded]
            assert not missing, (document.name, runs, missing)
            checked += 1
    assert checked >= 3
