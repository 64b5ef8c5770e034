"""The command-line reference, generated from the ``irtps`` command's argument parser.

The directive ``.. irtps-cli::`` writes, for ``irtps`` and each of its commands, the
description, the usage line, every argument and option as a Sphinx ``option`` (so each is
in the site's index and inventory as ``irtps COMMAND --option``) with its help as
``--help`` prints it (ranges and defaults included), and the examples. The parser is built
from `irtps.cli.parser.COMMANDS`, so the reference cannot drift from the command.
"""

from __future__ import annotations

import argparse
import re

from docutils import nodes
from docutils.parsers.rst import Directive
from docutils.statemachine import StringList
from irtps.cli.parser import build_parser
from sphinx.util.nodes import nested_parse_with_titles

#: Characters that reST would read as markup in a plain sentence.
_MARKUP = re.compile(r"([\\*`|_:\[\]<>])")


def plain(text: str) -> str:
    """`text` as reST that shows it verbatim: markup characters escaped, one line."""
    return _MARKUP.sub(r"\\\1", " ".join(text.split()))


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _block(kind: str, text: str) -> list[str]:
    return [f".. code-block:: {kind}", "", *("   " + line for line in text.rstrip().splitlines()), ""]


def _examples(epilog: str | None) -> list[str]:
    """The examples of an epilog (``examples:`` then indented command lines) as a console block."""
    if not epilog or "examples:" not in epilog:
        return []
    lines = epilog.split("examples:", 1)[1].strip("\n").splitlines()
    commands = [line.strip() for line in lines if line.startswith("  ")]
    after = " ".join(line.strip() for line in lines if line.strip() and not line.startswith("  "))
    return [
        "**Examples**",
        "",
        *_block("console", "\n".join(f"$ {command}" for command in commands)),
        *([plain(after), ""] if after else []),
    ]


def _option_lines(parser: argparse.ArgumentParser) -> list[str]:
    """One ``option`` per argument of `parser` (its commands aside), with the help ``--help`` prints."""
    formatter = parser._get_formatter()
    lines = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            continue
        help_text = formatter._expand_help(action) if action.help else ""
        if action.option_strings:
            signature = formatter._format_action_invocation(action)
        else:
            signature = action.dest
            if action.choices:
                help_text += f" (one of: {', '.join(map(str, action.choices))})"
        lines += [f".. option:: {signature}", "", f"   {plain(help_text)}", ""]
    return lines


def command_lines(program: str, parser: argparse.ArgumentParser) -> list[str]:
    """The reST of one command: a section with its texts and one ``option`` per argument."""
    lines = [program, "-" * len(program), "", plain(parser.description or ""), ""]
    lines += _block("text", parser.format_usage())
    lines += [f".. program:: {program}", "", *_option_lines(parser)]
    return lines + _examples(parser.epilog)


def reference_lines(parser: argparse.ArgumentParser) -> list[str]:
    """The reST of the whole reference: ``irtps`` itself, its commands listed, then each one."""
    lines = ["irtps", "-----", "", plain(parser.description or ""), "", *_block("text", parser.format_usage())]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                lines += [f"- :ref:`irtps {choice.dest} <irtps-cli-{choice.dest}>`: {plain(choice.help or '')}"]
            lines.append("")
    lines += [".. program:: irtps", "", *_option_lines(parser), *_examples(parser.epilog)]
    for name, subparser in _subcommands(parser).items():
        lines += [f".. _irtps-cli-{name}:", "", *command_lines(f"irtps {name}", subparser)]
    return lines


class CommandLineReference(Directive):
    """``.. irtps-cli::``: the reference of every command, from `irtps.cli.parser.build_parser`."""

    has_content = False

    def run(self):
        # Read again at every build: what it shows comes from the code, not from this page.
        self.state.document.settings.env.note_reread()
        text = StringList(reference_lines(build_parser()), source="irtps.cli.parser.build_parser")
        node = nodes.section()
        node.document = self.state.document
        nested_parse_with_titles(self.state, text, node)
        return node.children


def setup(app):
    app.add_directive("irtps-cli", CommandLineReference)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
