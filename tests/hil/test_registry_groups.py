"""The console script builds only the group of the command it runs (hil.cli.root.GROUPS):
that group's parsers must be the whole registry's, word for word, and every command of the
registry must belong to a group (or be ``bench``, for which the whole registry is built)."""

from __future__ import annotations

import argparse

import pytest

from hil.cli import root
from hil.cli.args import walk


def _commands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


@pytest.fixture(scope="module")
def whole() -> dict[str, argparse.ArgumentParser]:
    return _commands(root.build_parser())


def test_every_command_but_bench_is_in_one_group(whole):
    grouped = [w for words, _ in root.GROUPS for w in words]
    assert len(grouped) == len(set(grouped)), grouped
    assert sorted(grouped) == sorted(set(whole) - {"bench"})


@pytest.mark.parametrize("word", [w for words, _ in root.GROUPS for w in words])
def test_a_group_alone_parses_and_helps_as_the_whole_registry(word, whole):
    alone = _commands(root.build_parser(word))
    assert word in alone
    mine = walk(alone[word])
    theirs = walk(whole[word])
    assert [p.prog for p in mine] == [p.prog for p in theirs]
    for a, b in zip(mine, theirs, strict=True):
        assert a.format_help() == b.format_help(), a.prog
        assert a.get_default("run") == b.get_default("run"), a.prog


@pytest.mark.parametrize(("argv", "word"), [
    (["bus", "run", "--seconds", "1"], "bus"),
    (["identify-check", "--rows"], "identify-check"),
    (["bench", "bus"], None),  # bench's targets come from every group
    (["--help"], None),
    (["--version", "bus"], None),
    (["buss", "run"], None),  # a typo gets the whole registry's "invalid choice" line
    ([], None),
])
def test_the_command_word_is_the_first_argument_only(argv, word):
    assert root.command_word(argv) == word
